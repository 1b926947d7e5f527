"""The run folder's plots: the error panels' scale."""

from __future__ import annotations

import numpy as np

from trn_env.output import plots


def test_error_panels_scale_to_the_flight_not_the_prior(tmp_path):
    """A prior 100x the converged bound no longer flattens the flight (its reach is written in the panel);
    a late divergence stays in view; a panel without finite values keeps matplotlib's limits."""
    plt = plots._pyplot()
    t = np.arange(200.0)
    e = np.full(200, 3.0)
    e[0] = 900.0                                   # the prior's error at the start
    s3 = np.full(200, 10.0)
    s3[:2] = 1500.0
    e[190] = 60.0                                  # a late peak
    fig, ax = plt.subplots()
    plots._error_ylim(ax, t, e, s3, symmetric=True)
    lo, hi = ax.get_ylim()
    assert hi == -lo and 60.0 < hi < 100.0
    assert [x.get_text() for x in ax.texts] == ["first 10 s reach 1500 m (off scale)"]
    fig2, ax2 = plt.subplots()
    before = ax2.get_ylim()
    plots._error_ylim(ax2, t, np.full(200, np.nan), np.full(200, np.nan), symmetric=False)
    assert ax2.get_ylim() == before and not ax2.texts
    plt.close("all")
    arrays = {"t_s": t, "err_ned_m": np.c_[e, e, e], "gnss_available": t < 10.0,
              "est_cov_diag": np.tile((s3 / 3.0)[:, None] ** 2, (1, 9))}
    plots.plot_errors(tmp_path / "errors.png", arrays, "test")
    assert (tmp_path / "errors.png").stat().st_size > 10_000
