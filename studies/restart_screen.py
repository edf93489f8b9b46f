"""A cheap screen for the particle estimators' restart test: the start's own solutions refined on the data so far.

The particle estimators test themselves for a restart (online
re-initiation, :mod:`fgdoppler.estimators.restart`) only at the checkpoints
where the data since the last one surprise them.  On the random 3-D layouts
that misses a wrong basin the data leave slowly (``filters_3d.py``; draw 9:
the particles restart at 37.5 s though the truth's basin was e^17 more
probable at 25 s).  Testing at every checkpoint finds those runs but makes
the check's grid and Levenberg–Marquardt fits at every one, which on the
paper's recordings costs more than goal 2's time budget allows.

This study prototypes the screen aimed at the mistake itself, outside the
library: at each checkpoint where the data do not surprise the estimator,
the initiation's own solutions (its estimate, alternatives and grid
candidates) and the running estimate, carried back to the window's start,
are each refined on every measurement so far (the constant-velocity data
cost, SciPy's Levenberg–Marquardt with the vectorised model's Jacobian: no
grid, no factor graph); where one of the start's solutions costs less than
the running estimate's basin by the trackers' mode margin
(:data:`~fgdoppler.estimators.restart.MODE_MARGIN`, 13.8), the full test is
made there.  The registry's ``surprise_check`` is replaced for the screened
runs (a measurement, not an option of the library).

Printed: on ``--draws`` random 3-D draws (60 s), paired against the
default for ``particle`` and ``map``, the RMS over draws and the median of
each run's position RMS error over t >= 10 s, the median final error, the
draws closer and farther by more than a metre, the restarts, the screens
and how many fired, the median CPU time and NEES; then on the accuracy
benchmark's recordings (``--paper-runs`` per scenario, ``--seed``) whether
every track is the default's to the bit, the screens fired, and the
median CPU time and its paired ratio.

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
from scipy.optimize import least_squares

import fgdoppler as fd
import fgdoppler.estimators.registry as registry
import fgdoppler.estimators.restart as restart
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.particle_posterior import _along_jacobian
from fgdoppler.models.tracking import as_tracking_model

#: The variants: the registry's test, and the screened one.
VARIANTS = ("default", "screen")


def refined_cost(model: fd.TrackingModel, x0: np.ndarray, t: np.ndarray, pair: np.ndarray, z: np.ndarray,
                 sigma: np.ndarray) -> float:
    """Least data cost sum(((z - h(F(t) x)) / sigma)^2) in the basin of ``x0`` (LM; inf where the track
    meets a sensor)."""
    last: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def along(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # SciPy asks for the residual and then the Jacobian at the same point: one model call for both
        key = x.tobytes()
        if key not in last:
            last.clear()
            last[key] = _along_jacobian(model, x, t, pair)
        return last[key]

    def residual(x: np.ndarray) -> np.ndarray:
        return (z - along(x)[0]) / sigma

    def jacobian(x: np.ndarray) -> np.ndarray:
        return -along(x)[1] / sigma[:, None]

    try:
        return float(2.0 * least_squares(residual, x0, jac=jacobian, method="lm", max_nfev=60, x_scale="jac").cost)
    except ValueError:
        return float("inf")


class Screen:
    """The screened ``surprise_check`` for one recording, counting its screens and the ones that fired."""

    def __init__(self, measurements: fd.Measurements, model: Any, init: fd.Initiation) -> None:
        self.m, self.model, self.init = measurements, as_tracking_model(model), init
        self.screens = self.fired = 0

    def fires(self, result: fd.TrackResult, tc: float) -> bool:
        state = restart._state_at(result, tc)
        if state is None:
            return False
        sel = self.m.time <= tc + 1e-9
        t, pair = self.m.time[sel] - self.init.t_start, self.m.pair[sel].astype(np.intp)
        z, sigma = self.m.doppler[sel], self.m.sigma[sel]
        own = refined_cost(self.model, self.model.motion.F(self.init.t_start - tc) @ state[0], t, pair, z, sigma)
        starts = [self.init.x_start, *(a.state for a in self.init.alternatives),
                  *(c.state for c in self.init.candidates)]
        best = min(refined_cost(self.model, x, t, pair, z, sigma) for x in starts)
        fired = best < own - restart.MODE_MARGIN
        self.screens += 1
        self.fired += fired
        return fired

    def check(self, t_start: float, max_span: float) -> Callable[[fd.TrackResult, float, float], bool]:
        def test(result: fd.TrackResult, t_last: float, tc: float) -> bool:
            return tc - t_start <= max_span and (restart.surprised(result, t_last, tc) or self.fires(result, tc))
        return test


def run(name: str, measurements: fd.Measurements, model: Any, init: fd.Initiation, reference: fd.TrackResult,
        variant: str) -> tuple[fd.TrackResult, dict[str, float]]:
    """Run ``name`` with the registry's test or the screened one; its CPU time, screens and screens fired."""
    screen = Screen(measurements, model, init)
    registry.surprise_check = screen.check if variant == "screen" else restart.surprise_check  # type: ignore[assignment]
    try:
        cpu = time.process_time()
        res = fd.run_estimator(name, measurements, model, init, reference=reference)
        return res, {"cpu": time.process_time() - cpu, "screens": screen.screens, "fired": screen.fired}
    finally:
        registry.surprise_check = restart.surprise_check


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
        draws = [r for r in pool.map(one_draw, range(a.draws)) if "map default" in r]
        paper = list(pool.map(one_paper_run, [(s, r, a.seed) for s in range(6) for r in range(a.paper_runs)],
                              chunksize=3))
    lines = [f"{len(draws)} random 3-D draws (60 s), default → screened:", "", *draws_table(draws), "",
             f"The accuracy benchmark's recordings, {a.paper_runs} runs per scenario, seed {a.seed}:", "",
             *paper_table(paper)]
    _common.save_table(a.out, "restart_screen", "\n".join(lines) + "\n", {"draws": draws})


if __name__ == "__main__":
    main()
