"""Campaign stage: many closed-loop runs over seeds, navigators and sweeps; Parquet rows; baselines; reports.

spec          campaign files: format, validation (every problem by field path), the runs they expand to
runs          one run: its task and the worker function that flies it into a row
episodes      env episodes of a policy over goals and seeds as campaign runs (one row per episode)
rows          the output folder: manifest, one Parquet row file per run (atomic), logs
local         the local backend (a process pool over the machine's cores)
ray_backend   the Ray backend (a local instance or a cluster; Ray imported only there)
driver        run a campaign on a backend, with progress, into its folder (`--resume`)
stats         per-group statistics: the summary table
baseline      the regression gate (`--check`, `--write-baseline`)
report        `trn-env report DIR`: the summary table and plots, PNGs and one self-contained HTML page
"""

from trn_env.campaign.driver import make_backend, run_campaign
from trn_env.campaign.spec import Campaign, CampaignError, load_campaign

__all__ = ["Campaign", "CampaignError", "load_campaign", "make_backend", "run_campaign"]
