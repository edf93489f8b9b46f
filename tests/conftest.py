"""Shared fixtures: geometries and random states away from the sensors."""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

import fgdoppler as fd


def pytest_configure(config: pytest.Config) -> None:
    """One BLAS thread in each pytest-xdist worker (and the commands the tests start from it).

    numpy's OpenBLAS starts a thread per core in every process, and with two
    workers on two cores those threads only spin against each other
    (docs/concepts.md, "Running many tracks at once").
    """
    if os.environ.get("PYTEST_XDIST_WORKER"):
        os.environ["OPENBLAS_NUM_THREADS"] = "1"
        threadpool_limits(1)


def random_geometry(rng: np.random.Generator, n_pairs: int | None = None) -> fd.Geometry:
    """A random geometry of 1–4 pairs with sensors in a 60 km box."""
    n = int(rng.integers(1, 5)) if n_pairs is None else n_pairs
    pairs: list[fd.BistaticPair] = []
    while len(pairs) < n:
        tx, rx = rng.uniform(-30e3, 30e3, 2), rng.uniform(-30e3, 30e3, 2)
        if np.linalg.norm(tx - rx) > 1e3:
            pairs.append(fd.BistaticPair(tx=tx, rx=rx))
    return fd.Geometry(pairs=tuple(pairs))


def random_states(rng: np.random.Generator, geometry: fd.Geometry, n: int, min_dist: float = 500.0) -> np.ndarray:
    """``n`` states with positions at least ``min_dist`` from every sensor."""
    out = np.empty((0, 4))
    sensors = geometry.sensors()
    while out.shape[0] < n:
        pos = rng.uniform([-40e3, -40e3], [70e3, 40e3], size=(4 * n, 2))
        d = np.linalg.norm(pos[:, None, :] - sensors[None], axis=-1).min(axis=1)
        pos = pos[d > min_dist]
        vel = rng.uniform(-300, 300, size=(pos.shape[0], 2))
        out = np.vstack([out, np.hstack([pos, vel])])
    return out[:n]


@pytest.fixture(params=["a", "b"])
def paper_geom(request: pytest.FixtureRequest) -> fd.Geometry:
    return fd.paper_geometry(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20260621)


def benchmark_recording(scenario: int, run: int, seed: int = 2026) -> tuple[fd.Simulation, fd.TrackingModel]:
    """Run ``run`` of paper scenario ``scenario`` as ``python -m benchmarks.bench_accuracy --seed seed`` records it."""
    scen = fd.paper_scenarios()[scenario]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, scenario, run])))
    return sim, fd.TrackingModel.of(scen.geometry)


def benchmark_run(scenario: int, run: int, seed: int = 2026) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation]:
    """:func:`benchmark_recording` and the benchmark's start: the initiation on each pair's first 10 measurements
    (the benchmark's own :func:`benchmarks.bench_accuracy.recording`)."""
    from benchmarks.bench_accuracy import recording

    return recording(scenario, run, seed)


def with_jumps(m: fd.Measurements, jumps: dict[int, float]) -> fd.Measurements:
    """``m`` with measurement ``i`` moved by ``jumps[i]`` of its sigma."""
    bad = np.zeros(len(m))
    bad[list(jumps)] = list(jumps.values())
    return fd.Measurements(time=m.time, pair=m.pair, doppler=m.doppler + bad * m.sigma, sigma=m.sigma)


def assert_names_the_jumps(message: str, m: fd.Measurements, jumps: dict[int, float]) -> None:
    """An ``outliers`` finding's ``message`` names exactly the measurements of ``m`` that ``jumps`` moved (pair and
    time), each with its residual within 4 sigma of its jump."""
    named = re.findall(r"pair (\d) at t = ([\d.]+) s: ([+-][\d.]+) sigma", message)
    assert sorted((int(p), float(t)) for p, t, _ in named) == sorted(
        (int(m.pair[i]), float(m.time[i])) for i in jumps)
    for p, t, sigmas in named:
        [i] = [i for i in jumps if (m.pair[i], m.time[i]) == (int(p), float(t))]
        assert abs(float(sigmas) - jumps[i]) < 4.0
