"""The particle estimators' basin screen (:mod:`fgdoppler.estimators.basin_screen`), measured against its absence.

The particle estimators test themselves for a restart (online
re-initiation, :mod:`fgdoppler.estimators.restart`) at the checkpoints
where the data since the last one surprise them, and, since the screen,
where one of the initiation's solutions refined on all the data so far
fits them better than the running estimate's basin by the trackers' mode
margin.  On the random 3-D layouts surprise alone misses a wrong basin the
data leave slowly (``filters_3d.py``; draw 9: the particles restart at
37.5 s though the truth's basin was e^17 more probable at 25 s).

This study runs ``particle`` and ``map`` with the library's screen and
with the registry's screen removed (surprise alone), paired.

Printed: on ``--draws`` random 3-D draws (60 s), unscreened → screened,
the RMS over draws and the median of each run's position RMS error over
t >= 10 s, the median final error, the draws closer and farther by more
than a metre, the restarts, the screens and how many fired, the median CPU
time and NEES; then on the accuracy benchmark's recordings
(``--paper-runs`` per scenario, ``--seed``) whether every track is the
unscreened one to the bit, the screens fired, and the median CPU time and
its paired ratio.

Run: python studies/restart_screen.py [--draws 40] [--paper-runs 30] [--seed 2026] [--out DIR]
(about 20 min on 2 cores)
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from filters_3d import measures
from random_layouts import recorded
from random_layouts_3d import draw

import fgdoppler as fd
import fgdoppler.estimators.registry as registry
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.basin_screen import basin_screen

#: The variants: the registry's test on surprise alone, and with the library's basin screen (its default).
VARIANTS = ("unscreened", "screened")


class Counted:
    """The registry's ``basin_screen`` for one run: none (``unscreened``), or the library's, counting its screens
    and the ones that fired."""

    def __init__(self, variant: str) -> None:
        self.variant = variant
        self.screens = self.fired = 0

    def __call__(self, measurements: fd.Measurements, model: Any, init: fd.Initiation, margin: float
                 ) -> Callable[[np.ndarray, float], bool] | None:
        fires = None if self.variant == "unscreened" else basin_screen(measurements, model, init, margin)
        if fires is None:
            return None
        screen = fires

        def counted(state: np.ndarray, tc: float) -> bool:
            out = screen(state, tc)
            self.screens += 1
            self.fired += out
            return out
        return counted


def run(name: str, measurements: fd.Measurements, model: Any, init: fd.Initiation, reference: fd.TrackResult,
        variant: str) -> tuple[fd.TrackResult, dict[str, float]]:
    """Run ``name`` with or without the screen; its CPU time, screens and screens fired."""
    counted = Counted(variant)
    registry.basin_screen = counted
    try:
        cpu = time.process_time()
        res = fd.run_estimator(name, measurements, model, init, reference=reference)
        return res, {"cpu": time.process_time() - cpu, "screens": counted.screens, "fired": counted.fired}
    finally:
        registry.basin_screen = basin_screen


@one_blas_thread
def one_draw(k: int) -> dict[str, Any]:
    out, sim, init = recorded(k, *draw(k), duration=60.0)
    if init is None:
        return out
    g = sim.scenario.geometry
    reference = fd.run_estimator("smoother", sim.measurements, g, init)
    for name in ("particle", "map"):
        for variant in VARIANTS:
            res, extra = run(name, sim.measurements, g, init, reference, variant)
            out[f"{name} {variant}"] = {**measures(res, sim.truth), **extra}
    return out


@one_blas_thread
def one_paper_run(task: tuple[int, int, int]) -> dict[str, Any]:
    s, r, seed = task
    sim, model, init = _common.paper_run(s, r, seed)
    reference = fd.run_estimator("smoother", sim.measurements, model, init)
    out: dict[str, Any] = {"s": s, "r": r}
    for name in ("particle", "map"):
        for variant in VARIANTS if r % 2 else VARIANTS[::-1]:  # alternate the order: paired CPU times
            res, extra = run(name, sim.measurements, model, init, reference, variant)
            e = res.primary
            out[f"{name} {variant}"] = {"states": e.states.tolist(), **extra}
    return out


def draws_table(rows: list[dict[str, Any]]) -> list[str]:
    lines = ["| estimator | RMS over draws (m) | median (m) | median final (m) | closer / farther | final closer / "
             "farther | restarts | screens fired | median CPU (s) | median NEES |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name in ("particle", "map"):
        b, x = ([r[f"{name} {v}"] for r in rows] for v in VARIANTS)
        rb, rx = np.array([y["rmse"] for y in b]), np.array([y["rmse"] for y in x])
        fb, fx = np.array([y["final"] for y in b]), np.array([y["final"] for y in x])
        lines.append(
            f"| {name} | {np.sqrt(np.mean(rb ** 2)):,.0f} → {np.sqrt(np.mean(rx ** 2)):,.0f} | {np.median(rb):,.0f} → "
            f"{np.median(rx):,.0f} | {np.median(fb):,.0f} → {np.median(fx):,.0f} | {int(np.sum(rx < rb - 1))} / "
            f"{int(np.sum(rx > rb + 1))} | {int(np.sum(fx < fb - 1))} / {int(np.sum(fx > fb + 1))} | "
            f"{sum(y['restarts'] for y in b)} → {sum(y['restarts'] for y in x)} | {sum(y['fired'] for y in x)} of "
            f"{sum(y['screens'] for y in x)} | {np.median([y['cpu'] for y in b]):.2f} → "
            f"{np.median([y['cpu'] for y in x]):.2f} | {np.median([y['nees'] for y in b]):.1f} → "
            f"{np.median([y['nees'] for y in x]):.1f} |")
    return lines


def paper_table(rows: list[dict[str, Any]]) -> list[str]:
    lines = ["| scenario | estimator | tracks the same | screens fired | median CPU (s) | paired CPU ratio |",
             "|---|---|---|---|---|---|"]
    for s, scen in enumerate(fd.paper_scenarios()):
        rs = [x for x in rows if x["s"] == s]
        for name in ("particle", "map"):
            b, x = ([r[f"{name} {v}"] for r in rs] for v in VARIANTS)
            same = sum(u["states"] == v["states"] for u, v in zip(b, x, strict=True))
            lines.append(f"| {scen.name} | {name} | {same} of {len(rs)} | {sum(y['fired'] for y in x)} of "
                         f"{sum(y['screens'] for y in x)} | {np.median([y['cpu'] for y in b]):.3f} → "
                         f"{np.median([y['cpu'] for y in x]):.3f} | "
                         f"{np.median([v['cpu'] / u['cpu'] for u, v in zip(b, x, strict=True)]):.3f} |")
    return lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=40)
    p.add_argument("--paper-runs", type=int, default=30)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    with ProcessPoolExecutor(2) as pool:
        draws = [r for r in pool.map(one_draw, range(a.draws)) if "map screened" in r]
        paper = list(pool.map(one_paper_run, [(s, r, a.seed) for s in range(6) for r in range(a.paper_runs)],
                              chunksize=3))
    lines = [f"{len(draws)} random 3-D draws (60 s), unscreened → screened:", "", *draws_table(draws), "",
             f"The accuracy benchmark's recordings, {a.paper_runs} runs per scenario, seed {a.seed}:", "",
             *paper_table(paper)]
    _common.save_table(a.out, "restart_screen", "\n".join(lines) + "\n", {"draws": draws})


if __name__ == "__main__":
    main()
