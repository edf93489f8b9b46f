"""The smoother's whole-recording mode search: what it costs per run on the paper's recordings.

Each of the six paper scenarios, ``RUNS`` recordings simulated as the
accuracy benchmark does (seed ``SEED``); the process time of
``run_estimator("smoother", ...)`` from the same initiation with the search
off (``SmootherSettings(mode_search=False)``), with 5 grid candidates refined
(``mode_candidates=5``, the initiation's default) and with the default 20,
in one process, one after the other per recording so that load affects the
three alike.  The tracks with 5 and with 20 candidates are compared too.

Run alone: ``python -m benchmarks --only modes`` (about a minute).
"""

from __future__ import annotations

import time

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row

RUNS = 5
SEED = 2026
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


def run() -> list[Row]:
    cells, ratios, differ = [], [], 0
    for s, scen in enumerate(fd.paper_scenarios()):
        t, d = _times(scen, s)
        differ += d
        ratios.append(t["20"] / t["off"])
        cells.append(f"{scen.name}: {t['off']:.3f} / {t['5']:.3f} / {t['20']:.3f} s")
    return [Row(name=f"smoother per 30 s recording without the mode search / 5 candidates / 20 (default), "
                     f"paper scenarios, {RUNS} runs each; tracks differing between 5 and 20: {differ}",
                value="; ".join(cells), ratio=max(ratios), target="— (cost of the search, largest ratio 20 / off)")]
