"""Random layouts off the paper's recipe: truths with process noise, high rates, dropped measurements.

The verdicts were tuned on recordings of targets at exactly constant
velocity, two scans a second, 30 s, nothing missing.  This study runs every
estimator (``fd.run_estimators``: one reference smoother, default settings)
on the draws of ``random_layouts.py`` and ``random_layouts_3d.py`` recorded
the way a user's data may come instead:

* ``2-D noisy``: 5 scans/s for 120 s, the truth moving with the model's own
  process noise (white acceleration, q = 1e-3 m²/s³);
* ``2-D gaps``: 2 scans/s for 60 s at constant velocity, 30 % of the
  measurements after the initiation's window dropped at random and one pair
  (drawn) silent from 25 to 35 s;
* ``3-D noisy``: ground sensors, 2 scans/s for 60 s, the truth with the same
  process noise;
* ``3-D``: the same recordings' constant-velocity control.

Per cell and estimator: the median over draws of the run-averaged NEES over
t ≥ 10 s (position and velocity), how many draws exceed the χ² 99.9 %
quantile of the state's dimension, how many of those the verdict called
``ok`` (the count that must be zero), and how many draws were ``ok`` at all;
then every draw where some estimator exceeds it, with its verdicts, NEES and
final position errors (m).

Run: ``python studies/noisy_truth_layouts.py [--cells 2-D-noisy 2-D-gaps 3-D-noisy 3-D] [--workers 2]
[--out DIR]`` (22 minutes on 2 cores beside the test suite, 2026-12-02; every draw's record goes to
``DIR/noisy_truth_layouts.json``, default ``output/studies``).  Results: docs/concepts.md, "Recorded off
the recipe".
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import _common  # noqa: F401  (the repository root on the path)
import numpy as np
import random_layouts
import random_layouts_3d
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.metrics import nees
from fgdoppler.analysis.workers import one_blas_thread

#: Start of the time averages (s).
T_AVERAGE = 10.0
#: Process noise of the noisy truths (m²/s³): the model's own.
Q_TRUTH = 1e-3
#: Share of the measurements after the initiation's window dropped in the ``gaps`` cell.
DROPPED = 0.3
#: When the drawn pair is silent in the ``gaps`` cell (s).
SILENT = (25.0, 35.0)


@dataclass(frozen=True, kw_only=True)
class Cell:
    """One way of recording the draws: dimension, rate, length, noise in the truth, gaps, and which draws."""

    dim: int
    dt: float
    duration: float
    q: float
    gaps: bool
    draws: int


CELLS = {
    "2-D-noisy": Cell(dim=2, dt=0.2, duration=120.0, q=Q_TRUTH, gaps=False, draws=20),
    "2-D-gaps": Cell(dim=2, dt=0.5, duration=60.0, q=0.0, gaps=True, draws=30),
    "3-D-noisy": Cell(dim=3, dt=0.5, duration=60.0, q=Q_TRUTH, gaps=False, draws=16),
    "3-D": Cell(dim=3, dt=0.5, duration=60.0, q=0.0, gaps=False, draws=16),
}


def recording(cell: Cell, i: int) -> tuple[fd.Simulation, fd.Measurements]:
    """Draw ``i``'s simulation and the measurements the estimators get (with the cell's gaps)."""
    g, x0, rng = (random_layouts if cell.dim == 2 else random_layouts_3d).draw(i)
    noise = fd.ConstantVelocity(q=cell.q) if cell.q > 0 else None
    sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=cell.duration, dt=cell.dt, process_noise=noise), rng)
    m = sim.measurements
    if not cell.gaps:
        return sim, m
    keep = rng.random(len(m)) > DROPPED
    keep[: 10 * len(g.pairs)] = True  # the initiation's window whole
    silent = int(rng.integers(len(g.pairs)))
    keep &= ~((m.pair == silent) & (m.time > SILENT[0]) & (m.time < SILENT[1]))
    return sim, m.subset(keep)


#: What a study measures on one draw: ``(cell, simulation, measurements, initiation)`` to the draw's record.
Measure = Callable[[Cell, fd.Simulation, fd.Measurements, fd.Initiation], dict[str, Any]]


@one_blas_thread
def _draw(measure: Measure, task: tuple[str, int]) -> dict[str, Any]:
    """Draw ``task = (cell, i)`` recorded, initiated and measured; a refusal of the initiation is recorded."""
    name, i = task
    cell = CELLS[name]
    sim, m = recording(cell, i)
    g = sim.scenario.geometry
    out: dict[str, Any] = {"cell": name, "draw": i, "pairs": len(g.pairs)}
    try:
        init = fd.initiate(m.first_per_pair(10), g)
    except ValueError as exc:  # a target faster than the zone's bound
        return {**out, "refused": str(exc)}
    return {**out, **measure(cell, sim, m, init)}


def one(cell: Cell, sim: fd.Simulation, m: fd.Measurements, init: fd.Initiation) -> dict[str, Any]:
    """Every estimator's verdict, run-averaged NEES over t >= T_AVERAGE and final position error."""
    out: dict[str, Any] = {}
    for est, r in fd.run_estimators(list(fd.ESTIMATORS), m, sim.scenario.geometry, init).items():
        e = r.primary
        late = (e.times >= T_AVERAGE) & e.cov_ok
        truth = sim.truth.at(e.times[late])
        end = sim.truth.at(e.times[-1:])[0]
        out[est] = {"status": str(r.status), "nees": float(np.mean(nees(truth, e.covariances[late], e.states[late]))),
                    "end_error": float(np.linalg.norm(e.states[-1, :cell.dim] - end[:cell.dim])),
                    "reasons": [x.code for x in r.reasons]}
    return out


def report(rows: list[dict[str, Any]]) -> None:
    """The table and the draws beyond the quantile, per cell."""
    print("| cell | estimator | median NEES | beyond 99.9 % | ok and beyond | ok | draws |")
    print("|---|---|---|---|---|---|---|")
    beyond_rows = []
    for name, cell in CELLS.items():
        ran = [r for r in rows if r["cell"] == name and "refused" not in r]
        if not ran:
            continue
        limit = float(chi2.ppf(0.999, 2 * cell.dim))
        for est in fd.ESTIMATORS:
            ne = np.array([r[est]["nees"] for r in ran])
            ok = np.array([r[est]["status"] == "ok" for r in ran])
            print(f"| {name} | {est} | {np.median(ne):.2f} | {int(np.sum(ne > limit))} | "
                  f"{int(np.sum(ok & (ne > limit)))} | {int(np.sum(ok))} | {len(ran)} |")
        for r in ran:
            bad = {est: r[est] for est in fd.ESTIMATORS if r[est]["nees"] > limit}
            if bad:
                beyond_rows.append(f"{name} draw {r['draw']} ({r['pairs']} pairs): " + "; ".join(
                    f"{est} {v['status']} NEES {v['nees']:.3g} off {v['end_error']:,.0f} m" for est, v in bad.items()))
    print()
    print("\n".join(beyond_rows))


def run_draws(name: str, description: str, measure: Measure) -> list[dict[str, Any]]:
    """The command line of a study over the cells' draws: ``measure`` on each, the records in ``DIR/name.json``.

    Options ``--cells``, ``--workers`` and ``--out``; every draw is recorded
    and initiated by default (:func:`recording`, :func:`fgdoppler.initiate`
    on its first 10 scans per pair), its record the cell, draw, pair count
    and what ``measure`` (a module-level function, for the process pool)
    returns.  Prints how many draws ran and how many the initiation refused.
    """
    p = argparse.ArgumentParser(prog=f"{name}.py", description=description)
    p.add_argument("--cells", nargs="+", choices=list(CELLS), default=list(CELLS))
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("output/studies"))
    args = p.parse_args()
    tasks = [(cell, i) for cell in args.cells for i in range(CELLS[cell].draws)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(partial(_draw, measure), tasks))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{name}.json").write_text(json.dumps(rows, indent=1))
    refused = sum("refused" in r for r in rows)
    print(f"{len(rows)} draws, {refused} refused (a target faster than the zone's bound); "
          f"averages over t >= {T_AVERAGE:g} s")
    return rows


def main() -> None:
    report(run_draws("noisy_truth_layouts", __doc__.splitlines()[0], one))


if __name__ == "__main__":
    main()
