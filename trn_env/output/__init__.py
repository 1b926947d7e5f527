"""Output stage: run folders written atomically, logs, plots.

run_folder  `write_run` (summary.json, log/, log.npz, timeline.csv, events.csv, plots; all or nothing)
plots       track over the terrain, errors against time with the filter's bounds
"""

from trn_env.output.run_folder import default_out_dir, write_run

__all__ = ["default_out_dir", "write_run"]
