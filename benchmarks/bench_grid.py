"""Grid search over the paper grid versus one NumPy ``a*b+c`` pass over as many elements."""

from __future__ import annotations

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row, median_time
from fgdoppler.estimators.grid import grid_search


def run() -> list[Row]:
    sim = fd.simulate(fd.paper_scenario("a", 25e3), np.random.default_rng(1))
    w = sim.measurements.first_per_pair(10)
    o = w.stacked_order()
    bt = fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0])
    zone = sim.scenario.geometry.default_zone()
    res = grid_search(sim.scenario.geometry, bt, w.doppler[o], w.sigma[o], zone)
    n = res.n_candidates * bt.size  # candidate x measurement evaluations
    t_grid = median_time(lambda: grid_search(sim.scenario.geometry, bt, w.doppler[o], w.sigma[o], zone), repeat=15)
    a, b, c = (np.random.default_rng(0).random(n) for _ in range(3))
    t_fma = median_time(lambda: a * b + c, repeat=15)
    ratio = t_grid / t_fma
    return [Row(name=f"grid search, paper grid ({res.n_candidates} candidates x {bt.size} measurements)",
                value=f"{t_grid * 1e3:.1f} ms (a*b+c over {n:.2e} elements: {t_fma * 1e3:.2f} ms)",
                ratio=ratio, target="<= 8x", met=ratio <= 8.0)]
