"""The particle estimator on 600 s recordings: with its process-noise re-anchoring and with a rigid track.

The particles are samples of the state at an anchor time carried along a
constant-velocity track; the estimators' model adds process noise
(``q = 1e-3`` m²/s³), which that track leaves out until the anchor moves on.
``ParticleSettings.max_noise_share`` (default 0.1) moves it on once the
noise left out is a tenth of the posterior's variance in some direction and
costs more than a Gaussian summary would lose
(:mod:`fgdoppler.estimators.particle`, "Re-anchoring"); ``math.inf`` keeps
a rigid track for ``max_span`` (300 s), as before the rule.

Recordings: the paper's pairs (case a, case b with its staggered pair), a
target from (20 km, 3 km) at (30, -40) m/s for 600 s, its truth at constant
velocity (``--truth-q 0``, the default) or with the estimators' own process
noise (``--truth-q 1e-3``: the model is then exactly right).  Per case, over
``--recordings`` recordings (seeds 0, 1, ...): position RMSE over t >= 300 s
and at the last scan, run-averaged NEES over t >= 300 s (4 state
dimensions: 4 if consistent), and how many verdicts are not ``ok`` (the
check against the offline smoother, :func:`fgdoppler.run_estimator`), for
the offline smoother and the particle estimator with and without the rule.

Run: ``python studies/long_particles.py [--recordings 12] [--truth-q 0]``
(about 2 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np

import fgdoppler as fd
from fgdoppler.analysis.metrics import errors, nees
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.simulation import PAPER_CASE_B_OFFSET

CASES = ("a", "b")
VARIANTS = {"smoother": None, "particle (rule)": 0.1, "particle (rigid)": math.inf}


def scenario(case: str, truth_q: float) -> fd.Scenario:
    """The 600 s recording of one of the paper's geometries, its truth with process noise ``truth_q`` (0: none)."""
    offsets = (0.0, PAPER_CASE_B_OFFSET) if case == "b" else (0.0, 0.0)
    return fd.Scenario(geometry=fd.paper_geometry(case), x0=(20e3, 3e3, 30.0, -40.0), duration=600.0,
                       time_offsets=offsets, name=f"case {case}, 600 s",
                       process_noise=fd.ConstantVelocity(q=truth_q) if truth_q > 0 else None)


def recording(case: str, truth_q: float, seed: int
              ) -> tuple[fd.Simulation, fd.Measurements, fd.TrackingModel, fd.Initiation, fd.TrackResult]:
    """One recording of :func:`scenario` (seed ``seed``): simulation, measurements, model, initiation from the
    first 10 measurements per pair, and the offline smoother's result."""
    scen = scenario(case, truth_q)
    sim = fd.simulate(scen, np.random.default_rng(seed))
    m = sim.measurements
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(m.first_per_pair(10), model)
    return sim, m, model, init, fd.run_estimator("smoother", m, model, init)


def run_recordings(one: Callable[..., Any], doc: str) -> tuple[argparse.Namespace, list[Any]]:
    """``one`` over ``--recordings`` seeds with ``--truth-q`` (``_common.each_count``), the header printed."""
    args, rows = _common.each_count(one, doc.splitlines()[0], "recordings", 12, options={"truth_q": 0.0})
    print(f"{args.recordings} recordings per case, truth process noise q = {args.truth_q:g} m^2/s^3")
    return args, rows


def by_variant(rows: list[Any], names: Iterable[str]) -> Iterator[tuple[str, str, list[Any]]]:
    """``(case, name, that variant's result of every recording)`` for each case and each of ``names``."""
    for case in CASES:
        for name in names:
            yield case, name, [r[case][name] for r in rows]


def save(out: Path, name: str, summary: dict[str, Any]) -> None:
    """``summary`` as JSON in ``out/name``."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    path.write_text(json.dumps(summary, indent=1))
    print(f"wrote {path}")


@one_blas_thread
def one(seed: int, truth_q: float) -> dict[str, dict[str, list[float | str]]]:
    out: dict[str, dict[str, list[float | str]]] = {}
    for case in CASES:
        sim, m, model, init, smoother = recording(case, truth_q, seed)
        for name, share in VARIANTS.items():
            result = smoother if share is None else fd.run_estimator(
                "particle", m, model, init, fd.ParticleSettings(max_noise_share=share), reference=smoother)
            e = result.primary
            truth = sim.truth.at(e.times)
            squared = errors(e.states, truth)[0]
            consistency = nees(e.states, e.covariances, truth)
            late = e.times >= 300.0
            out.setdefault(case, {})[name] = [float(np.mean(squared[late])), float(squared[-1]),
                                              float(np.mean(consistency[late])), str(result.status)]
    return out


def main() -> None:
    args, rows = run_recordings(one, __doc__)
    summary = {}
    for case, name, runs in by_variant(rows, VARIANTS):
        late, last, nees = (np.array([float(v[i]) for v in runs]) for i in range(3))
        flagged = sum(v[3] != "ok" for v in runs)
        summary[f"{case} {name}"] = {"rmse_late": float(np.sqrt(late.mean())), "rmse_last": float(np.sqrt(last.mean())),
                                     "nees_late": float(nees.mean()), "not_ok": flagged}
        print(f"case {case} {name:17s} RMSE t >= 300 s {np.sqrt(late.mean()):6.0f} m, last {np.sqrt(last.mean()):6.0f} m, "
              f"NEES {nees.mean():6.2f}, not ok {flagged} of {len(runs)}")
    save(args.out, f"long_particles_q{args.truth_q:g}.json", summary)


if __name__ == "__main__":
    main()
