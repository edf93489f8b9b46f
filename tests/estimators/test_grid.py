"""Grid search: chunking invariance, agreement of kernels, distinct optima, the speed bound."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fgdoppler as fd
from fgdoppler.estimators.grid import (
    GridSpec,
    HalfPlane,
    grid_costs,
    grid_search,
    speed_lower_bound,
)
from tests.conftest import random_geometry, random_states


def _window(case: str = "a", x: float = 45e3, seed: int = 1):
    sim = fd.simulate(fd.paper_scenario(case, x), np.random.default_rng(seed))
    w = sim.measurements.first_per_pair(10)
    o = w.stacked_order()
    return sim, fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0]), w.doppler[o], w.sigma[o]


PAPER_ZONE = fd.paper_geometry("a").default_zone()
SMALL_ZONE = fd.Zone(along=(40e3, 48e3), across=(0.0, 4e3), speed_max=150.0)
KM = GridSpec(position_step=1e3)


def test_chunked_and_unchunked_costs_identical() -> None:
    sim, bt, z, s = _window("b", 5e3)
    zone = fd.Zone(along=(2e3, 12e3), across=(-2e3, 3e3))
    a = grid_search(sim.scenario.geometry, bt, z, s, zone, KM, k_best=20, chunk=37)
    b = grid_search(sim.scenario.geometry, bt, z, s, zone, KM, k_best=20, chunk=10**8)
    np.testing.assert_array_equal(a.costs, b.costs)
    np.testing.assert_array_equal(a.states, b.states)
    # the generic per-state evaluation, chunked or not, agrees with the product kernel
    c1 = grid_costs(sim.scenario.geometry, bt, z, s, a.states, chunk=1)
    c2 = grid_costs(sim.scenario.geometry, bt, z, s, a.states, chunk=10**6)
    np.testing.assert_array_equal(c1, c2)
    np.testing.assert_allclose(c1, a.costs, rtol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_shared_sensor_terms_change_no_cost(monkeypatch: pytest.MonkeyPatch, dim: int) -> None:
    """One transmitter seen by three receivers at the same instants, one receiver shared with a second
    transmitter, on the ground (2-D) or at heights (3-D, the grid's altitude levels): the product kernel
    computes each (sensor, time) term once and reuses it; the costs are those it gives computing every term
    afresh for each measurement, to the bit, and the per-state kernel's to rounding."""
    import dataclasses

    import fgdoppler.estimators.grid as grid

    z = (0.0, 100.0, 50.0) if dim == 3 else ()
    rxs = [(12e3, 3e3), (-9e3, 6e3), (5e3, -4e3)]
    geo = fd.Geometry(pairs=(*(fd.BistaticPair(tx=(0.0, 0.0, *z[1:2]), rx=(*r, *z[2:3])) for r in rxs),
                             fd.BistaticPair(tx=(30e3, 0.0, *z[:1]), rx=(*rxs[0], *z[2:3]))))
    sc = dataclasses.replace(fd.paper_scenario("a", 25e3, altitude=2e3 if dim == 3 else None), geometry=geo,
                             time_offsets=(0.0,) * 4)
    w = fd.simulate(sc, np.random.default_rng(3)).measurements.spread(6)
    o = w.stacked_order()
    bt = fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0])
    zone = geo.zone if dim == 3 else fd.Zone(along=(15e3, 35e3), across=(2e3, 12e3), speed_max=300.0)
    spec = GridSpec(position_step=2e3) if dim == 3 else KM
    results = []
    for share in (True, False):
        monkeypatch.setattr(grid, "SHARE_TERMS", share)
        results.append(grid_search(geo, bt, w.doppler[o], w.sigma[o], zone, spec, k_best=10, chunk=500))
    assert results[0].states.shape[1] == 2 * dim
    for r in results[1:]:
        np.testing.assert_array_equal(r.costs, results[0].costs)
        np.testing.assert_array_equal(r.states, results[0].states)
    np.testing.assert_allclose(grid_costs(geo, bt, w.doppler[o], w.sigma[o], results[0].states), results[0].costs,
                               rtol=1e-12)


def _numpy_costs(geo: fd.Geometry, bt: fd.StackedTimes, z: np.ndarray, w: np.ndarray, pos: np.ndarray,
                 vel: np.ndarray, huber_k: float | None) -> np.ndarray:
    """The grid's cost of every (position, velocity) in numpy's array operations, the kernel's order of operations:
    offsets and dot products coordinate by coordinate, each measurement's transmitter term then receiver term."""
    from fgdoppler.models.robust import huber_rho

    d = pos.shape[1]
    tx, rx = (np.array([getattr(p, end)[:d] for p in geo.pairs], dtype=float) for end in ("tx", "rx"))
    s2 = vel[:, 0] * vel[:, 0] + vel[:, 1] * vel[:, 1]
    s2 = s2 + vel[:, 2] * vel[:, 2] if d == 3 else s2
    out = np.zeros((pos.shape[0], vel.shape[0]))

    def rate(sensor: np.ndarray, t: float) -> np.ndarray:
        a = [pos[:, k] - sensor[k] for k in range(d)]
        c = a[0] * a[0] + a[1] * a[1]
        c = c + a[2] * a[2] if d == 3 else c
        U = a[0][:, None] * vel[None, :, 0] + a[1][:, None] * vel[None, :, 1]
        U = U + a[2][:, None] * vel[None, :, 2] if d == 3 else U
        ts2 = t * s2
        d2 = U * (2.0 * t) + c[:, None] + t * ts2
        return (U + ts2) / np.sqrt(d2)

    for j in range(bt.size):
        h = 0.0 + rate(tx[bt.pair[j]], bt.t[j]) + rate(rx[bt.pair[j]], bt.t[j])
        out += huber_rho((z[j] - h) * w[j], huber_k)
    return out


@pytest.mark.parametrize(("dim", "huber_k"), [(2, None), (3, 1.345)])
def test_the_compiled_costs_are_numpys_to_the_bit(dim: int, huber_k: float | None) -> None:
    """The compiled loop forms the offsets, the dot products, the terms and the sum itself; every cost is the one
    numpy's array operations give in the same order, to the bit, for every position against every velocity and
    for positions each with its own velocity (a pruned search's survivors), chunked or not."""
    import fgdoppler.estimators.grid as grid

    rng = np.random.default_rng(11)
    geo = random_geometry(rng, 3)
    if dim == 3:
        geo = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=(*p.tx, rng.uniform(0, 300)), rx=(*p.rx, rng.uniform(0, 300)))
                                      for p in geo.pairs))
    t = np.repeat(np.arange(8) * 0.5, 3)
    bt = fd.StackedTimes(pair=np.tile(np.arange(3), 8), t=t)
    z, w = rng.normal(0.0, 50.0, t.size), 1.0 / rng.uniform(0.5, 2.0, t.size)
    pos, vel = rng.uniform(-40e3, 40e3, (70, dim)), rng.uniform(-250.0, 250.0, (90, dim))
    expected = _numpy_costs(geo, bt, z, w, pos, vel, huber_k)
    for chunk in (1, 500, 10**6):
        np.testing.assert_array_equal(grid._product_costs(geo, bt, z, w, pos, vel, chunk, huber_k), expected)
    every = np.arange(pos.shape[0] * vel.shape[0])[::37]
    pairs = grid._pair_costs(geo, bt, z, w, pos[every // vel.shape[0]], vel[every % vel.shape[0]], 13, huber_k)
    np.testing.assert_array_equal(pairs, expected.reshape(-1)[every])


@pytest.mark.parametrize("shape", [(7,), (5, 6), (4, 3, 5, 6), (3, 4, 2, 3, 5), (3, 1, 2)])
@pytest.mark.parametrize("wrap_last", [False, True])
def test_local_minima_among_candidates_are_the_filters(shape: tuple[int, ...], wrap_last: bool) -> None:
    """The neighbour test on some candidates agrees with scipy's minimum filter over the whole grid: integer costs
    (many ties), infinite patches (unscored candidates), edges clamped or wrapped."""
    from scipy.ndimage import minimum_filter

    from fgdoppler.estimators.grid_kernels import minima_among

    rng = np.random.default_rng(len(shape) + 10 * wrap_last)
    for _ in range(20):
        cost = rng.integers(0, 4, size=int(np.prod(shape))).astype(float)
        cost[rng.random(cost.size) < 0.3] = np.inf
        modes = ["nearest"] * (len(shape) - 1) + ["wrap" if wrap_last else "nearest"]
        cube = cost.reshape(shape)
        expected = np.flatnonzero((cube == minimum_filter(cube, size=3, mode=modes)) & np.isfinite(cube))
        finite = np.flatnonzero(np.isfinite(cost))
        np.testing.assert_array_equal(finite[minima_among(cost, shape, wrap_last, finite)], expected)
        some = rng.permutation(finite)[: finite.size // 2]  # any order, any subset: each judged on its own
        np.testing.assert_array_equal(np.sort(some[minima_among(cost, shape, wrap_last, some)]),
                                      np.intersect1d(some, expected))


def test_candidates_are_distinct_local_minima() -> None:
    sim, bt, z, s = _window("a", 25e3)
    r = grid_search(sim.scenario.geometry, bt, z, s, PAPER_ZONE, k_best=8)
    assert np.all(np.diff(r.costs) >= 0)
    xs, ys, speeds, heads = GridSpec().axes(PAPER_ZONE, 50e3, r.speed_min)
    # each returned candidate is no worse than every one of its 80 grid neighbours
    for st_, c in zip(r.states, r.costs, strict=True):
        sp = np.hypot(st_[2], st_[3])
        hd = np.arctan2(st_[2], st_[3]) % (2 * np.pi)
        i = np.argmin(abs(xs - st_[0]))
        j = np.argmin(abs(ys - st_[1]))
        k = np.argmin(abs(speeds - sp))
        m = np.argmin(abs((heads - hd + np.pi) % (2 * np.pi) - np.pi))
        nb = []
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                for dk in (-1, 0, 1):
                    for dm in (-1, 0, 1):
                        ii, jj, kk = np.clip([i + di, j + dj, k + dk], 0, [xs.size - 1, ys.size - 1, speeds.size - 1])
                        h = heads[(m + dm) % heads.size]
                        nb.append([xs[ii], ys[jj], speeds[kk] * np.sin(h), speeds[kk] * np.cos(h)])
        costs = grid_costs(sim.scenario.geometry, bt, z, s, np.array(nb))
        assert c <= costs.min() + 1e-9
    # and no two are grid neighbours of each other: they are separated optima
    steps = np.array([1e3, 1e3])
    for a in range(len(r.states)):
        for b in range(a + 1, len(r.states)):
            same_pos = np.all(np.abs(r.states[a, :2] - r.states[b, :2]) <= steps)
            same_vel = np.linalg.norm(r.states[a, 2:] - r.states[b, 2:]) < 1e-6
            assert not (same_pos and same_vel)


def test_truth_is_near_the_best_candidate_noise_free() -> None:
    sc = fd.paper_scenario("a", 45e3)
    sim = fd.simulate(sc, np.random.default_rng(0))
    w = sim.measurements.first_per_pair(10)
    o = w.stacked_order()
    bt = fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0])
    clean = fd.cv_doppler(np.array(sc.x0), sc.geometry, bt)
    r = grid_search(sc.geometry, bt, clean, 1.0, SMALL_ZONE, KM, k_best=3)
    assert np.linalg.norm(r.best[:2] - np.array(sc.x0[:2])) <= 1.5e3


def test_half_plane_excludes_candidates() -> None:
    sim, bt, z, s = _window("a", 45e3)
    hp = HalfPlane(point=(0.0, 0.0), normal=(0.0, -1.0))  # south of the baseline only
    r = grid_search(sim.scenario.geometry, bt, z, s, PAPER_ZONE, k_best=5, half_plane=hp)
    assert np.all(r.states[:, 1] <= 0)


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_speed_bound_never_excludes_the_truth(seed: int) -> None:
    rng = np.random.default_rng(seed)
    g = random_geometry(rng)
    x = random_states(rng, g, 1, min_dist=10.0)[0]
    h = fd.bistatic_doppler(x, g)
    speed = np.hypot(x[2], x[3])
    assert speed_lower_bound(h, 1.0, n_sigma=0.0) <= speed * (1 + 1e-12)
    # noise up to n_sigma standard deviations cannot push the bound above the truth
    sigma = rng.uniform(0.1, 5.0, h.shape)
    noise = rng.uniform(-1, 1, h.shape) * 5.0 * sigma
    assert speed_lower_bound(h + noise, sigma, n_sigma=5.0) <= speed * (1 + 1e-12)


def test_speed_bound_is_attained_beyond_the_sensors() -> None:
    # On the baseline extension both unit vectors align, |h| = 2 |v|: the bound is tight.
    g = fd.paper_geometry("a")
    x = np.array([-5e3, 0.0, -80.0, 0.0])
    h = fd.bistatic_doppler(x, g)
    assert abs(h[0]) == np.float64(160.0) or abs(abs(h[0]) - 160.0) < 1e-9
    assert speed_lower_bound(h, 1.0, n_sigma=0.0) == np.max(np.abs(h)) / 2
    # the paper's bound (max |Z|) would exclude the true speed 80 m/s here
    assert np.max(np.abs(h)) > 80.0


def test_resolution_rule_gives_the_paper_grid_and_scales_with_the_zone() -> None:
    # The paper's grid: 1 km steps over x 2-48 km, y -5..5 km; 10 m/s up to 200 m/s; 20 deg headings.
    us, vs, speeds, heads = GridSpec().axes(PAPER_ZONE, 50e3, 0.0)
    np.testing.assert_array_equal(us, np.arange(2e3, 48e3 + 1, 1e3))
    np.testing.assert_array_equal(vs, np.arange(-5e3, 5e3 + 1, 1e3))
    np.testing.assert_array_equal(speeds, np.arange(0.0, 201.0, 10.0))
    np.testing.assert_allclose(np.rad2deg(heads), np.arange(0.0, 341.0, 20.0))
    # a zone 20x the paper's area is coarsened to the node budget, never finer than D/50
    big = fd.Zone(along=(0.0, 200e3), across=(-50e3, 50e3), speed_max=400.0)
    spec = GridSpec()
    step = spec.step(big, 50e3)
    assert step == np.sqrt(big.area / spec.max_positions)
    us, vs, speeds, _ = spec.axes(big, 50e3, 0.0)
    assert us.size * vs.size <= spec.max_positions * 1.1
    assert speeds[1] - speeds[0] == 20.0  # speed_max / 20
    # a small zone gets at least 5 nodes a side
    small = fd.Zone(along=(0.0, 2e3), across=(0.0, 1e3))
    assert GridSpec().step(small, 50e3) == 250.0


def test_speed_bound_above_the_zone_names_the_option() -> None:
    import pytest

    with pytest.raises(ValueError, match="--speed-max"):
        GridSpec().axes(PAPER_ZONE, 50e3, 250.0)


@pytest.mark.parametrize(("case", "k_best", "first_share", "options"), [
    ("a", 5, None, {}),
    ("b", 40, 1e-5, {"huber_k": 1.5}),  # a first batch of a few candidates: the batches must double, often
    ("a", 12, 1e-4, {"half_plane": HalfPlane(normal=(0.0, -1.0))}),
    ("3d", 8, 1e-4, {}),
    # gross outliers under the Huber loss: the first part's bound is weak, the bounds must be tightened part by
    # part (and a tightened bound is still a bound)
    ("outliers", 5, None, {"huber_k": 1.345}),
    ("outliers", 30, 1e-4, {"huber_k": 1.345}),
])
def test_pruned_search_is_the_exhaustive_search(monkeypatch: pytest.MonkeyPatch, case: str, k_best: int,
                                                first_share: float | None, options: dict) -> None:
    """The grid scores every candidate on a quarter of the data and only the promising ones on all of it; the
    K best local minima and their costs must be those of scoring the whole grid on every measurement, to the bit
    (forced by a stride longer than the window)."""
    import fgdoppler.estimators.grid as grid

    if case == "3d":
        sc = fd.paper_scenario("a", 25e3, altitude=3e3)
        sim = fd.simulate(sc, np.random.default_rng(4))
        w = sim.measurements.spread(8)
        zone, spec = sc.geometry.zone, GridSpec(position_step=2e3)
    else:
        sim = fd.simulate(fd.paper_scenario("a" if case == "outliers" else case, 5e3 if case == "b" else 25e3),
                          np.random.default_rng(2))
        w = sim.measurements.spread(16)
        zone, spec = PAPER_ZONE, GridSpec()
        if case == "outliers":  # one measurement in eight off by 100 sigma, spread over the parts
            z = w.doppler.copy()
            z[3::8] += 100.0 * w.sigma[3::8] * np.where(np.arange(z.size)[3::8] % 16 == 3, 1.0, -1.0)
            w = fd.Measurements(time=w.time, pair=w.pair, doppler=z, sigma=w.sigma)
    o = w.stacked_order()
    bt = fd.StackedTimes(pair=w.pair[o], t=w.time[o] - w.time[0])
    geo = sim.scenario.geometry
    if first_share is not None:
        monkeypatch.setattr(grid, "PRUNE_FIRST_SHARE", first_share)
    tightened: list[bool] = []
    tighten = grid._tighten

    def counted(*args: object) -> bool:
        tightened.append(tighten(*args))  # type: ignore[arg-type]
        return tightened[-1]

    monkeypatch.setattr(grid, "_tighten", counted)
    pruned = grid_search(geo, bt, w.doppler[o], w.sigma[o], zone, spec, k_best=k_best, **options)
    assert any(tightened) or case != "outliers"
    monkeypatch.setattr(grid, "PRUNE_STRIDE", 10**9)
    whole = grid_search(geo, bt, w.doppler[o], w.sigma[o], zone, spec, k_best=k_best, **options)
    assert pruned.costs.size == k_best
    np.testing.assert_array_equal(pruned.costs, whole.costs)
    np.testing.assert_array_equal(pruned.states, whole.states)
