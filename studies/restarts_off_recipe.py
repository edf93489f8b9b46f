"""What the trackers' online re-initiation buys off the paper's recipe: the same recordings with and without it.

The restart rules (:mod:`fgdoppler.estimators.restart`) were measured on
the paper's scenarios, where they change no track by a resolved amount,
and on a slow target along a long valley.  Off the recipe the trackers
restart far more often: the recordings of ``noisy_truth_layouts.py`` —
random two- to four-pair layouts in 2-D and 3-D, truths with process
noise, high rates, dropped measurements — restart the EKF, iSAM2 and the
fixed-lag smoother several times each.  This study runs those three on
every draw twice from the same initiation, with the default settings and
with ``restarts=False``, and compares the position RMSE over t ≥ 10 s
(the study's averaging start) draw by draw: per cell and tracker the
median and mean over draws, how many draws the restarts bring more than
10 % closer and how many they put more than 10 % further off, and the
two-sided Wilcoxon signed-rank p-value of the paired log ratios.

Run: ``python studies/restarts_off_recipe.py [--cells ...] [--workers 2] [--out DIR]`` (16 minutes
on 2 cores, 2026-12-02; every draw's RMSEs go to ``DIR/restarts_off_recipe.json``, default
``output/studies``).  Results: docs/concepts.md, "What the restarts buy off the recipe".
"""

from __future__ import annotations

from typing import Any

import _common  # noqa: F401  (the repository root on the path)
import numpy as np
from noisy_truth_layouts import CELLS, T_AVERAGE, Cell, run_draws
from scipy.stats import wilcoxon

import fgdoppler as fd
from fgdoppler.estimators.settings import EKFSettings, FixedLagSettings, ISAM2Settings

#: The trackers that restart, with their settings classes.
TRACKERS = {"ekf": EKFSettings, "isam2": ISAM2Settings, "fixed-lag": FixedLagSettings}
#: A draw counts as closer (further off) with the restarts where its RMSE is below (above) the other's by this ratio.
RESOLVED = 1.1


def one(cell: Cell, sim: fd.Simulation, m: fd.Measurements, init: fd.Initiation) -> dict[str, Any]:
    """One draw: each tracker's RMSE over t >= T_AVERAGE with and without restarts, and its restart count."""
    out: dict[str, Any] = {}
    for restarts in (True, False):
        settings = {est: cls(restarts=restarts) for est, cls in TRACKERS.items()}
        for est, r in fd.run_estimators(list(TRACKERS), m, sim.scenario.geometry, init, settings,
                                        verify=False).items():
            e = r.primary
            late = e.times >= T_AVERAGE
            err = np.linalg.norm(e.states[late, :cell.dim] - sim.truth.at(e.times[late])[:, :cell.dim], axis=1)
            key = "on" if restarts else "off"
            out[f"{est}/{key}"] = float(np.sqrt(np.mean(err**2)))
            if restarts:
                out[f"{est}/restarts"] = sum("re-initiation" in ev.message for ev in r.events)
    return out


def report(rows: list[dict[str, Any]]) -> None:
    """The paired comparison per cell and tracker."""
    print(f"| cell | tracker | restarts per draw | median RMSE on / off (m) | mean on / off (m) | "
          f"closer / further (>{RESOLVED - 1:.0%}) | Wilcoxon p | draws |")
    print("|---|---|---|---|---|---|---|---|")
    for name in CELLS:
        ran = [r for r in rows if r["cell"] == name and "refused" not in r]
        if not ran:
            continue
        for est in TRACKERS:
            on = np.array([r[f"{est}/on"] for r in ran])
            off = np.array([r[f"{est}/off"] for r in ran])
            count = np.mean([r[f"{est}/restarts"] for r in ran])
            ratio = np.log(on / off)
            p = wilcoxon(ratio[ratio != 0]).pvalue if np.any(ratio != 0) else 1.0
            print(f"| {name} | {est} | {count:.1f} | {np.median(on):,.0f} / {np.median(off):,.0f} | "
                  f"{np.mean(on):,.0f} / {np.mean(off):,.0f} | {int(np.sum(on * RESOLVED < off))} / "
                  f"{int(np.sum(on > off * RESOLVED))} | {p:.2g} | {len(ran)} |")


def main() -> None:
    report(run_draws("restarts_off_recipe", __doc__.splitlines()[0], one))


if __name__ == "__main__":
    main()
