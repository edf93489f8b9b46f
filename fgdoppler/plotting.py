"""Matplotlib figures.  Every function takes ``ax=None`` (a new figure) and returns the axes.

Nothing here calls ``plt.show()``; use :func:`save` to write a figure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from fgdoppler.geometry import Geometry, bistatic_range

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from fgdoppler.analysis.observability import ObservabilityMap, ObservabilityReport, SpeedTable

__all__ = [
    "covariance_ellipse",
    "ellipse_points",
    "figure_bytes",
    "figure_formats",
    "plot_geometry",
    "plot_lag_sweep",
    "plot_landscape",
    "plot_nees",
    "plot_observability_map",
    "plot_observability_slice",
    "plot_report_std",
    "plot_rmse",
    "plot_speed_table",
    "plot_track",
    "save",
]


def _axes(ax: Axes | None, figsize: tuple[float, float] = (6.4, 4.2)) -> Axes:
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, new = plt.subplots(figsize=figsize, layout="constrained")
    return new


def save(ax: Axes, path: str | Path, *, dpi: int = 120) -> Path:
    """Write the axes' figure to ``path`` (folders created) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = ax.get_figure(root=True)
    assert fig is not None
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def figure_bytes(ax: Axes, fmt: str, *, dpi: int = 120) -> bytes:
    """The axes' figure rendered in format ``fmt`` (``"png"``, ``"svg"``, ...), and closed; nothing is written."""
    import io

    import matplotlib.pyplot as plt

    fig = ax.get_figure(root=True)
    assert fig is not None
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


def figure_formats() -> set[str]:
    """File suffixes (without the dot) matplotlib can write."""
    from matplotlib.figure import Figure

    return set(Figure().canvas.get_supported_filetypes())


def ellipse_points(geometry: Geometry, pair: int, point: ArrayLike, n: int = 361) -> np.ndarray:
    """Points ``(n, 2)`` of the bistatic ellipse of ``pair`` through ``point``.

    Foci at Tx and Rx; semi-major axis ``a = (r_T + r_R) / 2``, focal half
    distance ``c = L / 2``, semi-minor ``b = sqrt(a^2 - c^2)``.
    """
    tx, rx = geometry.tx[pair], geometry.rx[pair]
    R = float(bistatic_range(np.asarray(point, dtype=float), geometry)[pair])
    a = R / 2
    c = np.linalg.norm(rx - tx) / 2
    b = float(np.sqrt(max(float(a * a - c * c), 0.0)))
    th = np.linspace(0, 2 * np.pi, n)
    ang = float(np.arctan2(rx[1] - tx[1], rx[0] - tx[0]))
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    pts = np.stack([a * np.cos(th), b * np.sin(th)], axis=1) @ rot.T
    return pts + (tx + rx) / 2


def plot_geometry(
    geometry: Geometry,
    ax: Axes | None = None,
    *,
    groups: Mapping[str, ArrayLike] | None = None,
    ellipse_through: ArrayLike | None = None,
    trajectories: Sequence[ArrayLike] = (),
    km: bool = True,
) -> Axes:
    """Sensors, baselines, optional evaluation points, ellipses through a point, trajectories.

    Parameters
    ----------
    groups
        Label -> points ``(n, 2)`` drawn as markers (paper Fig. 3).
    ellipse_through
        A point; each pair's bistatic ellipse through it is drawn (Fig. 7a).
    trajectories
        Position sequences ``(n, >=2)`` drawn as lines (Fig. 9).
    """
    ax = _axes(ax)
    s = 1e-3 if km else 1.0
    unit = "km" if km else "m"
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:purple"]
    for i, p in enumerate(geometry.pairs):
        c = colours[i % len(colours)]
        ax.plot([p.tx[0] * s, p.rx[0] * s], [p.tx[1] * s, p.rx[1] * s], "-", color=c, lw=1, alpha=0.6,
                label=f"pair {geometry.pair_label(i)}")
        if ellipse_through is not None:
            e = ellipse_points(geometry, i, ellipse_through) * s
            ax.plot(e[:, 0], e[:, 1], "--", color=c, lw=1, label=f"ellipse of pair {geometry.pair_label(i)}")
    tx = np.unique(geometry.tx, axis=0) * s
    rx = np.unique(geometry.rx, axis=0) * s
    ax.plot(tx[:, 0], tx[:, 1], "^", color="k", ms=9, label="Tx")
    ax.plot(rx[:, 0], rx[:, 1], "s", color="k", mfc="w", ms=8, label="Rx")
    markers = ["o", "^", "x", "d"]
    for j, (label, pts) in enumerate((groups or {}).items()):
        q = np.asarray(pts, dtype=float) * s
        ax.plot(q[:, 0], q[:, 1], markers[j % len(markers)], ms=3, label=label)
    for j, tr in enumerate(trajectories):
        q = np.asarray(tr, dtype=float)[:, :2] * s
        ax.plot(q[:, 0], q[:, 1], "-", lw=1.5, label=f"trajectory {j + 1}")
        ax.plot(q[0, 0], q[0, 1], "o", color=ax.lines[-1].get_color(), ms=4)
    if ellipse_through is not None:
        pt = np.asarray(ellipse_through, dtype=float) * s
        ax.plot(pt[0], pt[1], "*", color="r", ms=12, label="point")
    east = geometry.geodetic_origin is not None  # sites by latitude and longitude: metres east and north
    ax.set_xlabel(f"x, east ({unit})" if east else f"x ({unit})")
    ax.set_ylabel(f"y, north ({unit})" if east else f"y ({unit})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", loc="best")
    return ax


def plot_observability_map(m: ObservabilityMap, ax: Axes | None = None, *, title: str | None = None) -> Axes:
    """Heat map of O over initial x × heading; the −40 floor is drawn black and labelled."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from fgdoppler.analysis.observability import O_FLOOR

    ax = _axes(ax)
    O = np.ma.masked_less_equal(m.O, O_FLOOR)
    cmap = plt.get_cmap("viridis").with_extremes(bad="black")
    mesh = ax.pcolormesh(m.x * 1e-3, m.heading_deg, O.T, cmap=cmap, shading="nearest")
    ax.figure.colorbar(mesh, ax=ax, label="O = log10 det(J'J)")
    if np.any(m.unobservable):
        ax.legend(handles=[Patch(color="black", label="O = -40 (unobservable)")], loc="upper right",
                  fontsize="small")
    ax.set_xlabel("initial x (km)")
    ax.set_ylabel("heading (deg, clockwise from +y)")
    ax.set_title(title or f"y = {m.y / 1e3:g} km, speed {m.speed:g} m/s; {m.sampling.describe()}", fontsize="small")
    return ax


def plot_observability_slice(
    curves: Mapping[str, tuple[ArrayLike, ArrayLike]], ax: Axes | None = None, *, heading_deg: float | None = None
) -> Axes:
    """O versus initial x (paper Fig. 8): ``curves`` maps a label to ``(x, O)``."""
    ax = _axes(ax)
    for label, (x, O) in curves.items():
        ax.plot(np.asarray(x) * 1e-3, O, "-o", ms=2, label=label)
    ax.set_xlabel("initial x (km)")
    ax.set_ylabel("O = log10 det(J'J)")
    if heading_deg is not None:
        ax.set_title(f"heading {heading_deg:g} deg", fontsize="small")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return ax


def plot_report_std(report: ObservabilityReport, ax: Axes | None = None) -> Axes:
    """Position standard deviations over time from an observability report."""
    ax = _axes(ax)
    if report.pos_std is None or report.weakest_std is None:
        ax.text(0.5, 0.5, f"indeterminate: {report.message}", ha="center", va="center", transform=ax.transAxes,
                wrap=True)
        return ax
    ax.semilogy(report.times, report.pos_std[:, 0], label="σx")
    ax.semilogy(report.times, report.pos_std[:, 1], label="σy")
    ax.semilogy(report.times, report.weakest_std, "k--", label="weakest direction")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("standard deviation (m)")
    ax.set_title(f"O(x0) = {report.O_x0:.2f}, cond(J'J) = {report.cond_JtJ:.2g}", fontsize="small")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    return ax


def plot_landscape(
    x: ArrayLike,
    heading_deg: ArrayLike,
    cost: ArrayLike,
    ax: Axes | None = None,
    *,
    best: ArrayLike | None = None,
    others: Sequence[ArrayLike] = (),
    truth: ArrayLike | None = None,
) -> Axes:
    """Residual landscape over initial x × heading (paper Fig. 2) with optima and truth marked.

    ``best``, ``others`` and ``truth`` are states ``[x, y, vx, vy]``; their
    heading is ``atan2(vx, vy)``.
    """
    import matplotlib.colors as mcolors

    ax = _axes(ax)
    c = np.asarray(cost, dtype=float)
    finite = c[np.isfinite(c)]
    norm = mcolors.LogNorm(vmin=max(finite.min(), 1e-3), vmax=finite.max()) if finite.size else None
    mesh = ax.pcolormesh(np.asarray(x) * 1e-3, heading_deg, c.T, shading="nearest", norm=norm, cmap="magma_r")
    ax.figure.colorbar(mesh, ax=ax, label="weighted residual")

    def hd(s: ArrayLike) -> tuple[float, float]:
        s = np.asarray(s, dtype=float)
        return s[0] * 1e-3, float(np.rad2deg(np.arctan2(s[2], s[3])) % 360)

    for i, o in enumerate(others):
        ax.plot(*hd(o), "o", color="tab:blue", ms=7, label="local optima" if i == 0 else None)
    if best is not None:
        ax.plot(*hd(best), "o", color="red", ms=9, label="global optimum")
    if truth is not None:
        ax.plot(*hd(truth), "x", color="lime", ms=10, mew=2, label="truth")
    ax.set_xlabel("initial x (km)")
    ax.set_ylabel("heading (deg)")
    ax.legend(fontsize="small", loc="upper right")
    return ax


def covariance_ellipse(mean: ArrayLike, cov: ArrayLike, n_sigma: float = 2.0, n: int = 64) -> np.ndarray:
    """Points ``(n, 2)`` of the ``n_sigma`` ellipse of a 2-D Gaussian."""
    w, V = np.linalg.eigh(np.asarray(cov, dtype=float)[:2, :2])
    th = np.linspace(0, 2 * np.pi, n)
    circle = np.stack([np.cos(th), np.sin(th)], axis=1)
    return np.asarray(mean, dtype=float)[:2] + n_sigma * (circle * np.sqrt(np.clip(w, 0, None))) @ V.T


def plot_track(
    times: ArrayLike,
    states: ArrayLike,
    geometry: Geometry,
    ax: Axes | None = None,
    *,
    covariances: ArrayLike | None = None,
    cov_ok: ArrayLike | None = None,
    truth: ArrayLike | None = None,
    label: str = "estimate",
    n_ellipses: int = 12,
) -> Axes:
    """Estimated track with 2σ position ellipses, the truth (if given) and the sensors (km); 3-D tracks in plan view (x, y)."""
    ax = plot_geometry(geometry, ax)
    x = np.asarray(states, dtype=float)
    ax.plot(x[:, 0] * 1e-3, x[:, 1] * 1e-3, "-", color="tab:red", lw=1.5, label=label)
    if truth is not None:
        tr = np.asarray(truth, dtype=float)
        ax.plot(tr[:, 0] * 1e-3, tr[:, 1] * 1e-3, "--", color="k", lw=1, label="truth")
    if covariances is not None and len(x):
        P = np.asarray(covariances, dtype=float)
        ok = np.ones(len(x), dtype=bool) if cov_ok is None else np.asarray(cov_ok, dtype=bool)
        for i, k in enumerate(np.unique(np.linspace(0, len(x) - 1, n_ellipses).astype(int))):
            if ok[k]:
                e = covariance_ellipse(x[k], P[k]) * 1e-3
                ax.plot(e[:, 0], e[:, 1], "-", color="tab:red", lw=0.7, alpha=0.7, label="2σ" if i == 0 else None)
    pts = [x[:, :2]] + ([np.asarray(truth, dtype=float)[:, :2]] if truth is not None else [])
    allp = np.vstack(pts) * 1e-3
    pad = max(1.0, 0.15 * float(np.ptp(allp, axis=0).max()))
    ax.set_xlim(allp[:, 0].min() - pad, allp[:, 0].max() + pad)
    ax.set_ylim(allp[:, 1].min() - pad, allp[:, 1].max() + pad)
    ax.set_aspect("auto")
    ax.legend(fontsize="small", loc="best")
    return ax


def plot_rmse(
    times: ArrayLike,
    curves: Mapping[str, ArrayLike],
    ax: Axes | None = None,
    *,
    bounds: Mapping[str, ArrayLike] | None = None,
    ylabel: str = "position RMSE (m)",
    title: str | None = None,
    legend: bool = True,
    dotted: Sequence[str] = (),
) -> Axes:
    """RMSE versus time per estimator (log scale), with bounds (e.g. CRLB) dashed.

    Curves named in ``dotted`` (e.g. extrapolated initiation estimates) are drawn thin and
    dotted; ``legend=False`` leaves the legend to the caller (one per figure).
    """
    ax = _axes(ax)
    t = np.asarray(times, dtype=float)
    for label, y in curves.items():
        style = {"ls": ":", "lw": 1.0} if label in dotted else {"lw": 1.4}
        ax.semilogy(t, np.asarray(y, dtype=float), label=label, **style)
    for label, y in (bounds or {}).items():
        ax.semilogy(t, np.asarray(y, dtype=float), "k--", lw=1, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title, fontsize="medium")
    ax.grid(True, which="both", alpha=0.3)
    if legend:
        ax.legend(fontsize="small", ncol=2)
    return ax


def plot_nees(
    times: ArrayLike, curves: Mapping[str, ArrayLike], band: tuple[float, float], ax: Axes | None = None,
    *, title: str | None = None,
) -> Axes:
    """Run-averaged NEES versus time with the 95 % χ² band shaded."""
    ax = _axes(ax)
    t = np.asarray(times, dtype=float)
    ax.axhspan(band[0], band[1], color="tab:green", alpha=0.2, label="95 % band")
    for label, y in curves.items():
        ax.semilogy(t, np.asarray(y, dtype=float), label=label, lw=1.3)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("average NEES")
    if title:
        ax.set_title(title, fontsize="small")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="x-small")
    return ax


def plot_lag_sweep(lags: Sequence[float], rmse: Sequence[float], ax: Axes | None = None, *,
                   references: Mapping[str, float] | None = None) -> Axes:
    """Time-averaged position RMSE of the fixed-lag smoother versus its lag, with horizontal references."""
    ax = _axes(ax)
    ax.semilogx(lags, rmse, "-o", label="fixed-lag")
    for (label, value), style in zip((references or {}).items(), (("tab:red", "--"), ("k", ":"), ("tab:green", "-.")),
                                     strict=False):
        ax.axhline(value, color=style[0], ls=style[1], label=label)
    ax.set_xlabel("lag (s)")
    ax.set_ylabel("position RMSE, time average (m)")
    ax.legend(fontsize="small")
    return ax


def plot_speed_table(table: SpeedTable, ax: Axes | None = None) -> Axes:
    """Max and min of the observability measure per group versus speed (the paper's Table 2 as a figure)."""
    ax = _axes(ax)
    for g in table.groups:
        ax.plot(table.speeds, [table.values[g][s][0] for s in table.speeds], "-o", label=f"group {g} max")
        ax.plot(table.speeds, [table.values[g][s][1] for s in table.speeds], "--o", label=f"group {g} min")
    ax.set_xlabel("speed (m/s)")
    ax.set_ylabel("O")
    ax.legend(fontsize="small")
    return ax
