"""The smoother's whole-recording mode search: what it costs per run on the paper's recordings.

Each of the six paper scenarios, ``RUNS`` recordings simulated as the
accuracy benchmark does (seed ``SEED``); the process time of
``run_estimator("smoother", ...)`` from the same initiation with the search
off (``SmootherSettings(mode_search=False)``), with 5 grid candidates refined
(``mode_candidates=5``, the initiation's default) and with the default 20,
in one process, one after the other per recording so that load affects the
three alike.  The tracks with 5 and with 20 candidates are compared too.

A second row: where the initiation is ambiguous (among runs 0 to
``AMBIGUOUS_SCAN - 1`` of each scenario), the smoother runs once per
hypothesis; through ``run_estimator`` the hypotheses share their
whole-recording searches (:class:`~fgdoppler.estimators.search_memo.SearchMemo`)
and only the one of lowest cost is finished — its final findings and
reported covariances (:func:`~fgdoppler.estimators.ambiguity.resolve_staged`);
resolved by :func:`~fgdoppler.estimators.ambiguity.resolve` each runs whole
and repeats the searches.  Process time of the two, one after the other
per recording, and whether every track, covariance, cost and finding is
the same (it may not be where a hypothesis that lost held its track at the
zone's wall: only the staged run tests the reported track against that one
released, :meth:`~fgdoppler.estimators.smoother.SmootherDraft.joined`).

Run alone: ``python -m benchmarks --only modes`` (about two minutes).
"""

from __future__ import annotations

import time

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row

RUNS = 5
SEED = 2026
#: Runs per scenario searched for ambiguous initiations (the second row).
AMBIGUOUS_SCAN = 40
VARIANTS = {"off": fd.SmootherSettings(mode_search=False), "5": fd.SmootherSettings(mode_candidates=5),
            "20": fd.SmootherSettings()}


def _times(scen: fd.Scenario, s: int) -> tuple[dict[str, float], int]:
    """Mean process time per variant over the runs, and how many runs' tracks differ between 5 and 20."""
    total = dict.fromkeys(VARIANTS, 0.0)
    differ = 0
    for r in range(RUNS):
        sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([SEED, s, r])))
        m = sim.measurements
        model = fd.TrackingModel.of(scen.geometry)
        init = fd.initiate(m.first_per_pair(10), model)
        tracks = {}
        for name, settings in VARIANTS.items():
            t = time.process_time()
            tracks[name] = fd.run_estimator("smoother", m, model, init, settings).primary.states
            total[name] += time.process_time() - t
        differ += int(not np.array_equal(tracks["5"], tracks["20"]))
    return {k: v / RUNS for k, v in total.items()}, differ


def same_findings(judged: fd.TrackResult, alone: fd.TrackResult) -> bool:
    """Whether ``run_estimator``'s result carries ``alone``'s findings where the smoother puts them: after the
    initiation's (put first), before the verdict's (appended by the judge)."""
    own = [r.message for r in judged.reasons if not r.code.startswith("initiation-")]
    return own[:len(alone.reasons)] == [r.message for r in alone.reasons]


def _shared_and_alone() -> tuple[float, float, int, int]:
    """Process time of the smoothers of every ambiguous recording with the shared searches and without,
    how many recordings, and how many of them differ in anything between the two."""
    from fgdoppler.estimators.ambiguity import resolve
    from fgdoppler.estimators.registry import ESTIMATORS, hypotheses_of

    shared = alone = 0.0
    count = differ = 0
    settings = fd.SmootherSettings()
    for s, scen in enumerate(fd.paper_scenarios()):
        model = fd.TrackingModel.of(scen.geometry)
        for r in range(AMBIGUOUS_SCAN):
            m = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([SEED, s, r]))).measurements
            init = fd.initiate(m.first_per_pair(10), model)
            if not init.ambiguous:
                continue
            hyps, weights = hypotheses_of("smoother", m, model, init, settings)
            t = time.process_time()
            a = fd.run_estimator("smoother", m, model, init, settings, verify=False)
            shared += time.process_time() - t
            t = time.process_time()
            b = resolve(ESTIMATORS["smoother"].run, "cost", m, model, hyps, settings, None, weights)
            alone += time.process_time() - t
            count += 1
            same = (np.array_equal(a.primary.states, b.primary.states)
                    and np.array_equal(a.primary.covariances, b.primary.covariances, equal_nan=True)
                    and a.cost == b.cost and [e.message for e in a.events] == [e.message for e in b.events]
                    and same_findings(a, b))
            differ += int(not same)
    return shared, alone, count, differ


def run() -> list[Row]:
    shared, alone, count, differ_shared = _shared_and_alone()
    cells, ratios, differ = [], [], 0
    for s, scen in enumerate(fd.paper_scenarios()):
        t, d = _times(scen, s)
        differ += d
        ratios.append(t["20"] / t["off"])
        cells.append(f"{scen.name}: {t['off']:.3f} / {t['5']:.3f} / {t['20']:.3f} s")
    return [Row(name=f"smoother per 30 s recording without the mode search / 5 candidates / 20 (default), "
                     f"paper scenarios, {RUNS} runs each; tracks differing between 5 and 20: {differ}",
                value="; ".join(cells), ratio=max(ratios), target="— (cost of the search, largest ratio 20 / off)"),
            Row(name=f"smoothers of an ambiguous initiation's hypotheses, whole-recording searches shared and only "
                     f"the lowest cost finished vs each run whole: the {count} ambiguous recordings among runs 0-{AMBIGUOUS_SCAN - 1} of each paper "
                     f"scenario; differing in anything: {differ_shared}",
                value=f"{shared:.1f} s vs {alone:.1f} s CPU", ratio=shared / alone,
                target="< 1 (the same results)", met=shared < alone and differ_shared == 0)]
