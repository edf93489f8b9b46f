"""The smoother's split test of the motion model: what it costs per run on the paper's recordings.

Each of the six paper scenarios, ``RUNS`` recordings simulated as the
accuracy benchmark does (seed ``SEED``); the process time of
``run_estimator("smoother", ...)`` from the same initiation with the test
(``SmootherSettings()``, the default) and without it
(``motion_check=False``), one after the other per recording so that load
affects both alike.  The two tracks and covariances must be the same (the
test only adds a finding); how many recordings it flags is counted (their
truth moves at constant velocity: every flag is a false alarm).

Run alone: ``python -m benchmarks --only motion`` (about a minute).
"""

from __future__ import annotations

import time

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row

RUNS = 5
SEED = 2026


def run() -> list[Row]:
    cells, ratios = [], []
    differ = flagged = 0
    for s, scen in enumerate(fd.paper_scenarios()):
        model = fd.TrackingModel.of(scen.geometry)
        on = off = 0.0
        for r in range(RUNS):
            m = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([SEED, s, r]))).measurements
            init = fd.initiate(m.first_per_pair(10), model)
            t = time.process_time()
            a = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(motion_check=False))
            off += time.process_time() - t
            t = time.process_time()
            b = fd.run_estimator("smoother", m, model, init)
            on += time.process_time() - t
            differ += int(not (np.array_equal(a.primary.states, b.primary.states)
                               and np.array_equal(a.primary.covariances, b.primary.covariances, equal_nan=True)))
            flagged += int(any(x.code == "manoeuvre" for x in b.reasons))
        ratios.append(on / off)
        cells.append(f"{scen.name}: {on / RUNS:.3f} vs {off / RUNS:.3f} s")
    return [Row(name=f"smoother per 30 s recording with the split test of the motion model vs without, paper "
                     f"scenarios, {RUNS} runs each; tracks differing: {differ}; flagged (false alarms): {flagged}",
                value="; ".join(cells), ratio=max(ratios),
                target="— (cost of the test, largest ratio with / without)", met=None if differ == 0 else False)]
