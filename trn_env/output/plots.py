"""The plots a navigation engineer looks at first, drawn with matplotlib's Agg backend.

- track.png: true and estimated tracks over a hillshade of the true terrain, a scale bar, and the estimate
  with its error magnified (true position + k x error) so that a 10 m error is visible at map scale;
- errors.png: north, east, horizontal and vertical navigation error against time with the filter's
  +-3 sigma bounds (horizontal: 3 hypot(sigma_N, sigma_E)), GNSS outages shaded.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    return plt


def hillshade(heights_m: np.ndarray, dx_m: float, dy_m: float) -> np.ndarray:
    """Grey hillshade (0..1) of a south-up grid (row 0 = south), sun from the north-west at 45 deg."""
    from matplotlib.colors import LightSource
    h = np.where(np.isfinite(heights_m), heights_m, np.nanmin(heights_m))
    ls = LightSource(azdeg=315, altdeg=45)
    # LightSource assumes row 0 is the top (north): flip, shade, flip back.
    return ls.hillshade(h[::-1], vert_exag=2.0, dx=dx_m, dy=dy_m)[::-1]


def _dem_extent_deg(dem) -> tuple[float, float, float, float]:
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    return (math.degrees(lon_min), math.degrees(lon_max), math.degrees(lat_min), math.degrees(lat_max))


def plot_track(path: Path, dem, arrays: dict[str, np.ndarray], title: str = "",
               waypoints_deg: list[tuple[float, float]] | None = None) -> None:
    """True and estimated tracks over the hillshade of `dem` (any object with heights_m and bounds)."""
    plt = _pyplot()
    lon0, lon1, lat0, lat1 = _dem_extent_deg(dem)
    lat_mid = math.radians(0.5 * (lat0 + lat1))
    heights = np.asarray(dem.heights_m, float)
    ny, nx = heights.shape
    dy_m = math.radians(lat1 - lat0) * 6.371e6 / max(ny - 1, 1)
    dx_m = math.radians(lon1 - lon0) * 6.371e6 * math.cos(lat_mid) / max(nx - 1, 1)
    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    ax.imshow(hillshade(heights, dx_m, dy_m), cmap="gray", origin="lower", extent=(lon0, lon1, lat0, lat1),
              vmin=0, vmax=1)
    im = ax.imshow(heights, cmap="terrain", origin="lower", extent=(lon0, lon1, lat0, lat1), alpha=0.35)
    fig.colorbar(im, ax=ax, shrink=0.7, label="terrain height (m MSL)")
    ax.plot(np.degrees(arrays["true_lon_rad"]), np.degrees(arrays["true_lat_rad"]), "-", color="black",
            lw=1.6, label="true track")
    ax.plot(np.degrees(arrays["est_lon_rad"]), np.degrees(arrays["est_lat_rad"]), "--", color="red",
            lw=1.2, label="estimated track")
    # at map scale the two tracks overlap: draw the estimate again with its error magnified k times
    e_n = np.asarray(arrays["err_ned_m"][:, 0], float)
    e_e = np.asarray(arrays["err_ned_m"][:, 1], float)
    e_max = float(np.nanmax(np.hypot(e_n, e_e))) if e_n.size and np.isfinite(e_n).any() else 0.0
    extent_m = math.radians(lat1 - lat0) * 6.371e6
    if e_max > 0.0:
        k = _nice(0.05 * extent_m / e_max)
        if k > 1.5:
            lat_t = np.asarray(arrays["true_lat_rad"], float)
            lon_t = np.asarray(arrays["true_lon_rad"], float)
            lat_m = lat_t + k * e_n / 6.371e6
            lon_m = lon_t + k * e_e / (6.371e6 * np.cos(lat_t))
            ax.plot(np.degrees(lon_m), np.degrees(lat_m), "-", color="magenta", lw=0.9,
                    label=f"estimate with its error x{k:g} (max {e_max:.0f} m)")
    _scale_bar(ax, lon0, lon1, lat0, lat1, lat_mid)
    if waypoints_deg:
        wl = np.array(waypoints_deg)
        ax.plot(wl[:, 1], wl[:, 0], "o:", color="blue", ms=5, lw=0.8, label="route")
    ax.plot(np.degrees(arrays["true_lon_rad"][:1]), np.degrees(arrays["true_lat_rad"][:1]), "k^", ms=8,
            label="start")
    ax.set_aspect(1.0 / math.cos(lat_mid))
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_title(title or "true and estimated tracks")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 x 10^n not above x (x > 0)."""
    p = 10.0 ** math.floor(math.log10(x))
    return max(m * p for m in (1.0, 2.0, 5.0) if m * p <= x)


def _scale_bar(ax, lon0, lon1, lat0, lat1, lat_mid) -> None:
    """A scale bar of a round length (about a fifth of the map's width) at the lower left."""
    width_m = math.radians(lon1 - lon0) * 6.371e6 * math.cos(lat_mid)
    length_m = _nice(0.2 * width_m)
    dlon = math.degrees(length_m / (6.371e6 * math.cos(lat_mid)))
    x0 = lon0 + 0.05 * (lon1 - lon0)
    y0 = lat0 + 0.05 * (lat1 - lat0)
    ax.plot([x0, x0 + dlon], [y0, y0], "-", color="black", lw=3, solid_capstyle="butt")
    label = f"{length_m / 1000:g} km" if length_m >= 1000 else f"{length_m:g} m"
    ax.text(x0 + 0.5 * dlon, y0 + 0.012 * (lat1 - lat0), label, ha="center", va="bottom", fontsize=8)


def _shade_outages(ax, t: np.ndarray, available: np.ndarray) -> None:
    if t.size == 0:
        return
    off = ~available.astype(bool)
    edges = np.flatnonzero(np.diff(np.r_[0, off.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[a], t[min(b, t.size) - 1], color="0.9", zorder=0)


def _finite_max(*parts: np.ndarray) -> float:
    vals = np.concatenate([np.abs(p[np.isfinite(p)]) for p in parts])
    return float(np.max(vals)) if vals.size else math.nan


def _error_ylim(ax, t: np.ndarray, e: np.ndarray, s3: np.ndarray, symmetric: bool) -> None:
    """Y limits that show the flight, not the prior: scaled to the error and bound after the first 5 % of
    the samples (a start tens of times wider than the converged bound flattened the rest to a line); what
    the start reaches beyond them is written in the panel. A late peak or divergence stays in view."""
    skip = t.size // 20
    rest = _finite_max(e[skip:], s3[skip:])
    if not math.isfinite(rest):
        return
    lim = 1.15 * min(rest, 1e5) + 1.0
    ax.set_ylim(-lim if symmetric else 0.0, lim)
    start = _finite_max(e[:skip], s3[:skip]) if skip else math.nan
    if math.isfinite(start) and start > lim:
        ax.text(0.01, 0.96, f"first {t[skip] - t[0]:.0f} s reach {start:.0f} m (off scale)",
                transform=ax.transAxes, va="top", fontsize=7, color="0.35")


def plot_errors(path: Path, arrays: dict[str, np.ndarray], title: str = "") -> None:
    """Navigation error against time with +-3 sigma bounds of the navigator's covariance."""
    plt = _pyplot()
    t = arrays["t_s"]
    err = arrays["err_ned_m"]
    sig = np.sqrt(np.clip(arrays["est_cov_diag"][:, :3], 0.0, None))
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), dpi=110, sharex=True)
    panels = [
        ("north error (m)", err[:, 0], 3 * sig[:, 0], True, "+-3 sigma_N"),
        ("east error (m)", err[:, 1], 3 * sig[:, 1], True, "+-3 sigma_E"),
        ("horizontal error (m)", np.hypot(err[:, 0], err[:, 1]), 3 * np.hypot(sig[:, 0], sig[:, 1]), False,
         "3 hypot(sigma_N, sigma_E)"),
        ("vertical error, est - true (m)", -err[:, 2], 3 * sig[:, 2], True, "+-3 sigma_D"),
    ]
    for ax, (label, e, s3, symmetric, bound) in zip(axes, panels, strict=True):
        _shade_outages(ax, t, arrays["gnss_available"])
        ax.plot(t, e, color="C0", lw=1.0, label="error")
        ax.plot(t, s3, color="C3", lw=0.8, ls="--", label=bound)
        if symmetric:
            ax.plot(t, -s3, color="C3", lw=0.8, ls="--")
        ax.legend(loc="upper right", fontsize=7)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        _error_ylim(ax, t, e, s3, symmetric)
    axes[-1].set_xlabel("time (s); grey = GNSS not used")
    fig.suptitle(title or "navigation error")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def render_tracks_rgb(dem, true_track, est_track, goal_rad, cache=None, size_px: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 image of the map hillshade with the true (black) and estimated (red) tracks.

    `cache` (any object) keeps the rendered hillshade between calls in its `_background` attribute.
    """
    plt = _pyplot()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    lon0, lon1, lat0, lat1 = _dem_extent_deg(dem)
    lat_mid = math.radians(0.5 * (lat0 + lat1))
    bg = getattr(cache, "_background", None) if cache is not None else None
    if bg is None:
        heights = np.asarray(dem.heights_m, float)
        ny, nx = heights.shape
        dy_m = math.radians(lat1 - lat0) * 6.371e6 / max(ny - 1, 1)
        dx_m = math.radians(lon1 - lon0) * 6.371e6 * math.cos(lat_mid) / max(nx - 1, 1)
        bg = hillshade(heights, dx_m, dy_m)
        if cache is not None:
            cache._background = bg
    fig = plt.figure(figsize=(size_px / 100, size_px / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(bg, cmap="gray", origin="lower", extent=(lon0, lon1, lat0, lat1), vmin=0, vmax=1)
    tt = np.degrees(np.asarray(true_track, float).reshape(-1, 2))
    et = np.degrees(np.asarray(est_track, float).reshape(-1, 2))
    ax.plot(tt[:, 1], tt[:, 0], "-", color="black", lw=2)
    ax.plot(et[:, 1], et[:, 0], "--", color="red", lw=1.5)
    ax.plot(math.degrees(goal_rad[1]), math.degrees(goal_rad[0]), "*", color="gold", ms=14, mec="black")
    ax.set_xlim(lon0, lon1)
    ax.set_ylim(lat0, lat1)
    ax.set_aspect(1.0 / math.cos(lat_mid))
    ax.axis("off")
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
    plt.close(fig)
    return img


def plot_integrity(path: Path, arrays: dict[str, np.ndarray], name: str = "dem_integrity",
                   title: str = "") -> None:
    """A monitor's test statistic against its threshold over time (as seed 003's Figs 3-4), alarms shaded,
    and the absolute disparities it sums (coloured by height source: GNSS or the navigator)."""
    plt = _pyplot()
    k = f"monitor_{name}_"
    t = arrays[k + "t_s"]
    stat, thr, alarm = arrays[k + "statistic"], arrays[k + "threshold"], arrays[k + "alarm"].astype(bool)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), dpi=110, sharex=True)
    ax = axes[0]
    ax.plot(t, stat, color="C0", lw=1.1, label="test statistic T")
    ax.plot(t, thr, color="C3", lw=1.0, ls="--", label="threshold")
    if alarm.any():
        edges = np.flatnonzero(np.diff(np.r_[0, alarm.astype(int), 0]))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            ax.axvspan(t[a], t[b - 1], color="C3", alpha=0.12, zorder=0)
    ax.set_ylabel("T (eq 4/5)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[1]
    src = arrays[k + "source"]
    for code, label, color in ((0, "GNSS height", "C0"), (1, "navigator height", "C1")):
        m = src == code
        if m.any():
            ax.plot(t[m], arrays[k + "disparity_m"][m], ".", ms=2.5, color=color, label=f"disparity, {label}")
    sig = arrays[k + "sigma_m"]
    ax.plot(t, sig, color="0.4", lw=0.8, ls=":", label="+-sigma")
    ax.plot(t, -sig, color="0.4", lw=0.8, ls=":")
    ax.set_ylabel("absolute disparity p (m)")
    ax.set_xlabel("time (s); red = integrity alarm")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.suptitle(title or f"{name}: test statistic against its threshold")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
