"""Every estimator on one recording: :func:`fgdoppler.run_estimators` against one ``run_estimator`` call each.

Each of the six paper scenarios, ``RUNS`` recordings simulated as the
accuracy benchmark does (seed ``SEED``), one initiation; the process time
of ``fd.run_estimators(fd.ESTIMATORS, ...)`` (the filters' verdicts share one
reference smoother, their restart checks their fits of the data so far,
:class:`~fgdoppler.estimators.restart.FreshFits`) and of
``fd.run_estimator(name, ...)`` for every name (each filter runs its own
smoother and its own fits), one after the other per recording so that load
affects both alike; and whether every status, finding and estimate is the
same.

Run alone: ``python -m benchmarks --only shared`` (about two minutes).
"""

from __future__ import annotations

import time

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row

RUNS = 2
SEED = 2026


def _same(a: fd.TrackResult, b: fd.TrackResult) -> bool:
    return a.status == b.status and a.reasons == b.reasons and len(a.estimates) == len(b.estimates) and all(
        np.array_equal(x.states, y.states) and np.array_equal(x.covariances, y.covariances, equal_nan=True)
        for x, y in zip(a.estimates, b.estimates, strict=True))


def run() -> list[Row]:
    shared = each = 0.0
    count = differ = 0
    for s, scen in enumerate(fd.paper_scenarios()):
        model = fd.TrackingModel.of(scen.geometry)
        for r in range(RUNS):
            m = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([SEED, s, r]))).measurements
            init = fd.initiate(m.first_per_pair(10), model)
            t = time.process_time()
            together = fd.run_estimators(fd.ESTIMATORS, m, model, init)
            shared += time.process_time() - t
            t = time.process_time()
            alone = {n: fd.run_estimator(n, m, model, init) for n in fd.ESTIMATORS}
            each += time.process_time() - t
            count += 1
            differ += sum(not _same(together[n], alone[n]) for n in fd.ESTIMATORS)
    return [Row(name=f"every estimator ({len(fd.ESTIMATORS)}) on one recording with its verdict: fd.run_estimators "
                     f"(one reference smoother, the restart checks' fits shared) vs run_estimator per name; paper scenarios, {RUNS} runs each; "
                     f"answers differing in anything: {differ} of {count * len(fd.ESTIMATORS)}",
                value=f"{shared:.1f} s vs {each:.1f} s CPU", ratio=shared / each,
                target="< 1 (the same answers)", met=shared < each and differ == 0)]
