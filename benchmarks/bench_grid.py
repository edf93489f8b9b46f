"""Grid search over the paper grid versus one NumPy ``a*b+c`` pass over as many elements; shared sensor terms;
the pruned search against scoring every candidate on every measurement."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

import fgdoppler as fd
import fgdoppler.estimators.grid as grid
from benchmarks._common import Row, median_time
from fgdoppler.estimators.grid import grid_search


def _paper_row() -> Row:
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
    return Row(name=f"grid search, paper grid ({res.n_candidates} candidates x {bt.size} measurements)",
               value=f"{t_grid * 1e3:.1f} ms (a*b+c over {n:.2e} elements: {t_fma * 1e3:.2f} ms)",
               ratio=ratio, target="<= 8x", met=ratio <= 8.0)


def _shared_row(repeat: int = 7) -> Row:
    """One transmitter, four receivers measuring at the same instants: each term once vs every term computed.

    The two are timed alternately in one process (CPU time), so that neither inherits a heap the other grew.
    """
    geo = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=(0.0, 0.0), rx=r)
                                  for r in [(20e3, 5e3), (-15e3, 10e3), (5e3, -20e3), (-10e3, -15e3)]))
    sc = dataclasses.replace(fd.paper_scenario("a", 5e3), geometry=geo, time_offsets=(0.0,) * 4)
    w = fd.simulate(sc, np.random.default_rng(1)).measurements.spread(16)
    o = w.stacked_order()
    bt = fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0])
    zone = geo.default_zone()
    cap = grid.MAX_SHARED_TERMS
    times: dict[int, list[float]] = {cap: [], 0: []}
    results = {}
    try:
        for _ in range(repeat):
            for c in (cap, 0):
                grid.MAX_SHARED_TERMS = c
                t = time.process_time()
                results[c] = grid_search(geo, bt, w.doppler[o], w.sigma[o], zone)
                times[c].append(time.process_time() - t)
    finally:
        grid.MAX_SHARED_TERMS = cap
    same = bool(np.array_equal(results[cap].costs, results[0].costs)
                and np.array_equal(results[cap].states, results[0].states))
    shared, afresh = float(np.median(times[cap])), float(np.median(times[0]))
    ratio = shared / afresh
    return Row(name=f"grid search, 1 Tx + 4 synchronous Rx ({results[cap].n_candidates} candidates x {bt.size} "
                    "measurements): each sensor term once vs every term computed",
               value=f"{shared * 1e3:.0f} ms vs {afresh * 1e3:.0f} ms CPU; "
                     + ("identical costs" if same else "COSTS DIFFER"),
               ratio=ratio, target="<= 0.8x, identical", met=same and ratio <= 0.8)


def _pruned_row(repeat: int = 7) -> Row:
    """A restart check's grid (case b 25 km, 16 measurements per pair over 30 s): pruned vs exhaustive.

    The exhaustive search is the pruned one with a stride longer than the window (every candidate scored on every
    measurement); the two are timed alternately in one process (CPU time).
    """
    sim = fd.simulate(fd.paper_scenario("b", 25e3), np.random.default_rng(1))
    w = sim.measurements.spread(16)
    o = w.stacked_order()
    bt = fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0])
    geo = sim.scenario.geometry
    zone = geo.default_zone()
    stride = grid.PRUNE_STRIDE
    times: dict[int, list[float]] = {stride: [], 0: []}
    results = {}
    try:
        for _ in range(repeat):
            for s in (stride, 0):
                grid.PRUNE_STRIDE = s or 10**9
                t = time.process_time()
                results[s] = grid_search(geo, bt, w.doppler[o], w.sigma[o], zone)
                times[s].append(time.process_time() - t)
    finally:
        grid.PRUNE_STRIDE = stride
    same = bool(np.array_equal(results[stride].costs, results[0].costs)
                and np.array_equal(results[stride].states, results[0].states))
    pruned, whole = float(np.median(times[stride])), float(np.median(times[0]))
    ratio = pruned / whole
    return Row(name=f"grid search, a restart check's window ({results[0].n_candidates} candidates x {bt.size} "
                    "measurements): pruned by a lower bound vs every candidate on every measurement",
               value=f"{pruned * 1e3:.1f} ms vs {whole * 1e3:.1f} ms CPU; "
                     + ("identical minima" if same else "MINIMA DIFFER"),
               ratio=ratio, target="<= 0.6x, identical", met=same and ratio <= 0.6)


def run() -> list[Row]:
    return [_paper_row(), _shared_row(), _pruned_row()]
