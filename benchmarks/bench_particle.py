"""The particle estimator's hot path: the Doppler of every particle's track at every measurement.

Each Metropolis move of :mod:`fgdoppler.estimators.particle` evaluates the
likelihood of all its tracks against all the data so far (4,096 tracks ×
up to 120 measurements on the paper's recordings).  Measured side by side
in one run on the same inputs: the per-state model's ``(n, m, d)`` layout
(:func:`fgdoppler.models.doppler._terms`, what ``predict_along`` used
before) against :func:`fgdoppler.models.doppler._along` (coordinate by
coordinate, in cache-sized blocks), which must give the same numbers to the
bit; and a whole particle run in case a 25 km as it is against the same run
with the earlier evaluation (the ``(n, m, d)`` layout, the likelihood in one
block of 2^20 entries), the same track to the bit.
"""

from __future__ import annotations

import numpy as np

import fgdoppler as fd
import fgdoppler.estimators.particle as particle
import fgdoppler.models.observation as observation
from benchmarks._common import Row, median_time
from fgdoppler.models.doppler import _along, _terms


def _strided_along(x: np.ndarray, t: np.ndarray, tx: np.ndarray, rx: np.ndarray, *, singular: str = "raise"
                   ) -> tuple[np.ndarray, np.ndarray | None]:
    """The earlier evaluation: the per-state model on ``(n, m, d)`` arrays."""
    d = x.shape[-1] // 2
    vel = x[:, None, d:]
    h, _, _, mask = _terms(x[:, None, :d] + t[None, :, None] * vel, vel, tx[None], rx[None], jacobian=False,
                           singular=singular)
    return h, mask


def _kernel_row() -> Row:
    g = fd.paper_geometry("a")
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4096, 4)) * [5e3, 3e3, 100.0, 100.0] + [25e3, 0.0, 0.0, 0.0]
    t = np.sort(rng.uniform(0.0, 30.0, 120))
    c = rng.integers(0, 2, 120)
    tx, rx = g.tx[c], g.rx[c]

    def strided() -> np.ndarray:
        return _strided_along(x, t, tx, rx, singular="mask")[0]

    def blocked() -> np.ndarray:
        return _along(x, t, tx, rx, singular="mask")[0]

    if not np.array_equal(strided(), blocked()):
        raise AssertionError("the blocked Doppler differs from the per-state model")
    t_old = median_time(strided, repeat=15)
    t_new = median_time(blocked, repeat=15)
    ratio = t_new / t_old
    return Row(name="Doppler of 4,096 tracks x 120 measurements: blocked, per coordinate vs (n, m, d) layout",
               value=f"{t_new * 1e3:.1f} ms vs {t_old * 1e3:.1f} ms, identical", ratio=ratio, target="<= 0.5x",
               met=ratio <= 0.5)


def _particle_row() -> Row:
    scen = fd.paper_scenario("a", 25e3)
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([7, 1, 3])))
    model = fd.TrackingModel.of(scen.geometry)
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), model)
    chunk, along = particle.CHUNK_ROWS, observation._along
    tracks, times = [], []
    for rows, fn in ((1 << 20, _strided_along), (chunk, along)):
        particle.CHUNK_ROWS, observation._along = rows, fn
        try:
            tracks.append(fd.run_estimator("particle", m, model, init).primary.states)
            times.append(median_time(lambda: fd.run_estimator("particle", m, model, init), repeat=5))
        finally:
            particle.CHUNK_ROWS, observation._along = chunk, along
    if not np.array_equal(tracks[0], tracks[1]):
        raise AssertionError("the particle track depends on how its likelihood is evaluated")
    ratio = times[1] / times[0]
    return Row(name="particle run, case a 25 km: blocked likelihood vs the earlier (n, m, d) layout in one block",
               value=f"{times[1]:.2f} s vs {times[0]:.2f} s, identical tracks", ratio=ratio, target="<= 0.8x",
               met=ratio <= 0.8)


def run() -> list[Row]:
    return [_kernel_row(), _particle_row()]
