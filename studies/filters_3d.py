"""Every online estimator on random 3-D layouts, and the particle estimators with their restart test made the other way.

On the random 3-D layouts of ``random_layouts_3d.py`` (its draws, recorded
for ``--duration`` seconds) the particle estimators end kilometres from the
truth where the offline smoother is close (``particle_anchor_3d.py``).  Is
that the particles, or is every filter there as far off?  Each draw is
tracked by every estimator with its defaults, against one shared reference
smoother; and ``particle`` and ``map`` once more with the online
re-initiation's test made the other way (``check_every``,
:class:`fgdoppler.MapSettings`): ``particle`` at *every* checkpoint of the
first ``max_span`` seconds, ``map`` only where the data since the last
checkpoint surprise it, a rescue armed it or the basin screen fires (each
one's default in space is the other).

Printed per estimator and variant, over the draws: the RMS and the median of
each run's position RMS error over t >= 10 s, the median of its horizontal
part and of that part's ratio to the Cramér–Rao bound of the draw
(:func:`horizontal_bounds`: filtering for the filters, smoothing for the
smoother), the median final error, the
median NEES averaged over t >= 10 s, the runs whose NEES exceeds the
chi-square 99.9 % quantile of the averaged statistic (6 dimensions), the
``ok`` runs and of them those beyond that quantile, the restarts, the
median wall time; for those variants also the draws whose error over
t >= 10 s and whose final error fell or rose by more than a metre, paired
against the default.

Run: python studies/filters_3d.py [--draws 40] [--duration 60] [--out DIR]
(about 20 min on 2 cores)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from random_layouts import recorded
from random_layouts_3d import draw
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.bounds import crlb_deterministic
from fgdoppler.analysis.metrics import errors, nees
from fgdoppler.analysis.workers import one_blas_thread

#: Times from which a run's NEES and error are averaged (s), as in the accuracy benchmark.
T_LATE = 10.0
#: The estimators, in the table's order (the smoother last: it is the reference).
NAMES = ("ekf", "isam2", "fixed-lag", "particle", "map", "smoother")
#: The particle estimators run again with their restart test made the other way: ``check_every``, and the label.
VARIANTS = {"particle": (True, "every checkpoint"), "map": (False, "surprise only")}


def measures(res: fd.TrackResult, truth: fd.Trajectory) -> dict[str, Any]:
    """A run's errors (over t >= :data:`T_LATE`, and at the end; the position's and its horizontal part's), NEES,
    verdict, restarts and wall time."""
    e = res.primary
    x_true = truth.at(e.times)
    se = errors(e.states, x_true)[0]
    late = e.times >= T_LATE
    horizontal = np.sum((e.states[late, :2] - x_true[late, :2]) ** 2, axis=1)
    return {"rmse": float(np.sqrt(np.mean(se[late]))), "final": float(np.sqrt(se[-1])),
            "horizontal": float(np.sqrt(np.mean(horizontal))),
            "nees": float(np.mean(nees(e.states, e.covariances, x_true)[late])), "status": str(res.status),
            "wall": float(res.wall_time),
            "restarts": sum("online re-initiation" in ev.message for ev in res.events)}


def changes(runs: list[dict[str, Any]], base: list[dict[str, Any]]) -> str:
    """The draws whose error over t >= :data:`T_LATE` fell / rose by more than a metre against ``base`` (the same
    draws' :func:`measures`), and those whose final error did: ``"fell / rose, final fell / rose"``."""
    a, b = (np.array([x["rmse"] for x in r]) for r in (runs, base))
    fa, fb = (np.array([x["final"] for x in r]) for r in (runs, base))
    return (f"{int(np.sum(a < b - 1))} / {int(np.sum(a > b + 1))}, "
            f"{int(np.sum(fa < fb - 1))} / {int(np.sum(fa > fb + 1))}")


def horizontal_bounds(sim: fd.Simulation) -> dict[str, float]:
    r"""The Cramér–Rao bounds on the horizontal position error of draw ``sim``, RMS over the scans at t >= :data:`T_LATE`.

    For a constant-velocity truth the information on the start state from the
    measurements up to :math:`t` is :math:`\mathbf J_0(t)`
    (:func:`~fgdoppler.analysis.bounds.crlb_deterministic`, evaluated on the
    truth); the estimators also hold the zone's weak prior
    :math:`N(\mathbf m, \mathbf P_w)` on the start, so the bound here is
    :math:`\mathbf F(t)(\mathbf J_0(t) + \mathbf P_w^{-1})^{-1}\mathbf F(t)'`, with the data up to
    :math:`t` (filtering) or all of them (smoothing), and
    :math:`\sqrt{\overline{\operatorname{tr}\mathbf B_{xy}(t)}}` over those scans its horizontal
    RMS.  The height is left out: ground sensors see it only through
    :math:`z/r`, there the prior's Gaussian spans the altitude band, and the
    estimators' hard walls (not in the bound) hold it.  It is a yardstick evaluated at the
    truth, not a bound on every estimator: a biased one (the walls) can fall below it.
    """
    g, m = sim.scenario.geometry, sim.measurements
    prior = fd.TrackingModel.of(g).prior()
    assert prior is not None
    t = np.unique(m.time)
    t = t[t >= T_LATE]
    out = {}
    for label, smoothing in (("filtering", False), ("smoothing", True)):
        b = crlb_deterministic(g, sim.truth.states[0], m, t, t0=float(sim.truth.times[0]), smoothing=smoothing,
                               prior_information=np.linalg.inv(prior[1]))
        out[label] = float(np.sqrt(np.mean(np.trace(b[:, :2, :2], axis1=1, axis2=2))))
    return out


@one_blas_thread
def one(k: int, duration: float = 60.0) -> dict[str, Any]:
    out, sim, init = recorded(k, *draw(k), duration=duration)
    if init is None:
        return out
    g = sim.scenario.geometry
    out["bound"] = horizontal_bounds(sim)
    reference = fd.run_estimator("smoother", sim.measurements, g, init)
    for name in NAMES:
        res = reference if name == "smoother" else fd.run_estimator(name, sim.measurements, g, init,
                                                                     reference=reference)
        out[name] = measures(res, sim.truth)
    for name, (every, label) in VARIANTS.items():
        settings_of: Callable[..., fd.TrackerSettings] = fd.ESTIMATORS[name].settings
        settings = settings_of(check_every=every)
        res = fd.run_estimator(name, sim.measurements, g, init, settings, reference=reference)
        out[f"{name}, {label}"] = measures(res, sim.truth)
    return out


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 40, {"duration": 60.0})
    rows = [r for r in all_rows if "smoother" in r]
    limit = float(chi2.ppf(0.999, 6))
    lines = [f"{len(rows)} draws of random_layouts_3d.py, {a.duration:g} s each ({len(all_rows) - len(rows)} refused); "
             f"errors and NEES over t >= {T_LATE:g} s (NEES: 6 dimensions, chi-square 99.9 % {limit:.1f})", "",
             "| estimator | RMS over draws (m) | median (m) | median horizontal (m) | horizontal / bound, median "
             "| median final (m) | NEES median | NEES > 99.9 % | ok "
             "| ok and > 99.9 % | restarts | median wall (s) | paired: fell / rose, final fell / rose |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    variants = [f"{name}, {label}" for name, (_, label) in VARIANTS.items()]
    for key in [*NAMES, *variants]:
        v = [r[key] for r in rows]
        rmse = np.array([x["rmse"] for x in v])
        horizontal = np.array([x["horizontal"] for x in v])
        bound = np.array([r["bound"]["smoothing" if key == "smoother" else "filtering"] for r in rows])
        final = np.array([x["final"] for x in v])
        paired = changes(v, [r[key.split(",")[0]] for r in rows]) if key in variants else ""
        lines.append(f"| {key} | {math.sqrt(np.mean(rmse ** 2)):,.0f} | {np.median(rmse):,.0f} | "
                     f"{np.median(horizontal):,.0f} | {np.median(horizontal / bound):.2f} | "
                     f"{np.median(final):,.0f} | {np.median([x['nees'] for x in v]):.1f} | "
                     f"{sum(x['nees'] > limit for x in v)} | {sum(x['status'] == 'ok' for x in v)} | "
                     f"{sum(x['status'] == 'ok' and x['nees'] > limit for x in v)} | "
                     f"{sum(x['restarts'] for x in v)} | {np.median([x['wall'] for x in v]):.2f} | {paired} |")
    for label in ("filtering", "smoothing"):
        b = np.array([r["bound"][label] for r in rows])
        lines.append(f"\nHorizontal {label} bound with the weak prior (horizontal_bounds): median {np.median(b):,.0f} m, "
                     f"RMS over draws {math.sqrt(np.mean(b ** 2)):,.0f} m")
    _common.save_table(a.out, f"filters_3d_{a.duration:g}s", "\n".join(lines) + "\n", all_rows)


if __name__ == "__main__":
    main()
