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
    bt, z, sigma = _window(sim.measurements.first_per_pair(10))
    zone = sim.scenario.geometry.default_zone()
    res = grid_search(sim.scenario.geometry, bt, z, sigma, zone)
    n = res.n_candidates * bt.size  # candidate x measurement evaluations
    t_grid = median_time(lambda: grid_search(sim.scenario.geometry, bt, z, sigma, zone), repeat=15)
    a, b, c = (np.random.default_rng(0).random(n) for _ in range(3))
    t_fma = median_time(lambda: a * b + c, repeat=15)
    ratio = t_grid / t_fma
    return Row(name=f"grid search, paper grid ({res.n_candidates} candidates x {bt.size} measurements)",
               value=f"{t_grid * 1e3:.1f} ms (a*b+c over {n:.2e} elements: {t_fma * 1e3:.2f} ms)",
               ratio=ratio, target="<= 8x", met=ratio <= 8.0)


def _window(w: fd.Measurements) -> tuple[fd.StackedTimes, np.ndarray, np.ndarray]:
    o = w.stacked_order()
    return fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0]), w.doppler[o], w.sigma[o]


def _alternate(geo: fd.Geometry, w: fd.Measurements, setting: str, values: tuple[object, ...], repeat: int,
               huber_k: float | None = None) -> tuple[tuple[float, ...], bool, int, int]:
    """Median CPU times of ``grid_search`` with the module attribute ``setting`` at each of ``values``.

    They are timed alternately in one process, so that none inherits a heap another grew.  Also returns
    whether all found the same candidates with the same costs, the grid's size and the window's.
    """
    bt, z, sigma = _window(w)
    zone = geo.default_zone()
    saved = getattr(grid, setting)
    times: list[list[float]] = [[] for _ in values]
    results: list[grid.GridResult] = []
    try:
        for _ in range(repeat):
            results = []
            for i, v in enumerate(values):
                setattr(grid, setting, v)
                t = time.process_time()
                results.append(grid_search(geo, bt, z, sigma, zone, huber_k=huber_k))
                times[i].append(time.process_time() - t)
    finally:
        setattr(grid, setting, saved)
    a = results[0]
    same = all(np.array_equal(a.costs, b.costs) and np.array_equal(a.states, b.states) for b in results[1:])
    return tuple(float(np.median(ts)) for ts in times), same, a.n_candidates, bt.size


def _shared_row(repeat: int = 7) -> Row:
    """One transmitter, four receivers measuring at the same instants: each term once vs every term computed."""
    geo = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=(0.0, 0.0), rx=r)
                                  for r in [(20e3, 5e3), (-15e3, 10e3), (5e3, -20e3), (-10e3, -15e3)]))
    sc = dataclasses.replace(fd.paper_scenario("a", 5e3), geometry=geo, time_offsets=(0.0,) * 4)
    w = fd.simulate(sc, np.random.default_rng(1)).measurements.spread(16)
    (shared, afresh), same, n, m = _alternate(geo, w, "SHARE_TERMS", (True, False), repeat)
    return _paired_row(f"grid search, 1 Tx + 4 synchronous Rx ({n} candidates x {m} measurements): each sensor "
                       "term once vs every term computed", shared, afresh, "identical costs" if same else
                       "COSTS DIFFER", same, 0.8)


def _paired_row(name: str, now: float, before: float, verdict: str, same: bool, target: float) -> Row:
    ratio = now / before
    return Row(name=name, value=f"{now * 1e3:.1f} ms vs {before * 1e3:.1f} ms CPU; {verdict}", ratio=ratio,
               target=f"<= {target:g}x, identical", met=same and ratio <= target)


def _pruned_row(repeat: int = 7) -> Row:
    """A restart check's grid (case b 25 km, 16 measurements per pair over 30 s): pruned vs exhaustive.

    The exhaustive search is the pruned one with a stride longer than the window (every candidate scored on every
    measurement).
    """
    sim = fd.simulate(fd.paper_scenario("b", 25e3), np.random.default_rng(1))
    (pruned, whole), same, n, m = _alternate(sim.scenario.geometry, sim.measurements.spread(16), "PRUNE_STRIDE",
                                             (grid.PRUNE_STRIDE, 10**9), repeat)
    return _paired_row(f"grid search, a restart check's window ({n} candidates x {m} measurements): pruned by a "
                       "lower bound vs every candidate on every measurement", pruned, whole,
                       "identical minima" if same else "MINIMA DIFFER", same, 0.6)


def _outlier_row(repeat: int = 7) -> Row:
    """A restart check's window with 5 % outliers of +-100 sigma under the Huber loss (case a 45 km, 16
    measurements per pair): the pruned search with its bounds tightened part by part, against the same without
    tightening (the first part's bound only) and against every candidate on every measurement."""
    sim = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(3))
    w = sim.measurements.spread(16)
    rng = np.random.default_rng(3)
    z = w.doppler.copy()
    idx = rng.choice(len(w), round(0.05 * len(w)), replace=False)
    z[idx] += rng.choice([-100.0, 100.0], idx.size) * w.sigma[idx]
    w = fd.Measurements(time=w.time, pair=w.pair, doppler=z, sigma=w.sigma)
    (tight, loose), same, n, m = _alternate(sim.scenario.geometry, w, "_tighten", (grid._tighten, _no_tightening),
                                            repeat, huber_k=1.345)
    (whole,), _, _, _ = _alternate(sim.scenario.geometry, w, "PRUNE_STRIDE", (10**9,), repeat, huber_k=1.345)
    bt, z, sigma = _window(w)
    pruned = grid_search(sim.scenario.geometry, bt, z, sigma, sim.scenario.geometry.default_zone(), huber_k=1.345)
    grid.PRUNE_STRIDE, saved = 10**9, grid.PRUNE_STRIDE
    try:
        every = grid_search(sim.scenario.geometry, bt, z, sigma, sim.scenario.geometry.default_zone(), huber_k=1.345)
    finally:
        grid.PRUNE_STRIDE = saved
    same = same and np.array_equal(pruned.costs, every.costs) and np.array_equal(pruned.states, every.states)
    return _paired_row(f"grid search, a restart check's window with 5 % outliers, Huber loss ({n} candidates x {m} "
                       f"measurements): bounds tightened part by part vs the first part's bound only (every "
                       f"candidate on every measurement: {whole * 1e3:.1f} ms)", tight, loose,
                       "identical minima" if same else "MINIMA DIFFER", same, 0.8)


def _no_tightening(*args: object) -> bool:
    return False


def run() -> list[Row]:
    return [_paper_row(), _shared_row(), _pruned_row(), _outlier_row()]
