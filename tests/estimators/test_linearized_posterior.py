"""The posterior of the data so far linearised about a reference track (fgdoppler.estimators.linearized_posterior)."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.linearized import linearize_rows
from fgdoppler.estimators.linearized_posterior import linearized_filter, mean_square_errors


def _recording(seed: int = 3) -> tuple[fd.Simulation, fd.TrackingModel]:
    """6 s of the paper's case b pairs from (8 km, 2 km) at (30, -40) m/s."""
    scen = fd.Scenario(geometry=fd.paper_geometry("b"), x0=(8e3, 2e3, 30.0, -40.0), duration=6.0)
    return fd.simulate(scen, np.random.default_rng(seed)), fd.TrackingModel.of(scen.geometry)


def _reference(sim: fd.Simulation, times: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A reference track near the truth but not on it (the offline smoother's stands there in use)."""
    return sim.truth.at(times) + rng.normal(0.0, [300.0, 300.0, 3.0, 3.0], size=(times.size, 4))


def _batch(model: fd.TrackingModel, m: fd.Measurements, ref_t: np.ndarray, ref_x: np.ndarray, t_start: float,
           x: np.ndarray, P: np.ndarray, at: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the state at ``at`` (default: the last scan) of the same linear-Gaussian model,
    solved as one batch.

    States at ``t_start``, at every scan after it and at ``at``; a prior ``(x, P)`` on the first, the motion
    rows ``x_k - F x_{k-1} ~ N(0, Q)``, and each measurement's whitened row ``A x_k ~ N(b + A xbar_k, 1)``: all
    whitened and stacked into one least-squares system ``J y = r``, solved by QR (``J = QR``: the mean
    ``R^-1 Q'r``, the covariance ``R^-1 R^-T``), whose block at ``at`` is returned.
    """
    later = m.subset(m.time > t_start)
    times = np.unique(np.concatenate([[t_start], later.time, [] if at is None else [at]]))
    n, d = times.size, model.n
    blocks: list[np.ndarray] = []
    rhs: list[np.ndarray] = []
    W = np.linalg.inv(np.linalg.cholesky(P))  # whitening: W P W' = I
    prior = np.zeros((d, n * d))
    prior[:, :d] = W
    blocks.append(prior)
    rhs.append(W @ x)
    for k in range(1, n):
        dt = times[k] - times[k - 1]
        Wq = np.linalg.inv(np.linalg.cholesky(model.motion.Q(dt)))
        G = np.zeros((d, n * d))
        G[:, (k - 1) * d:k * d], G[:, k * d:(k + 1) * d] = -Wq @ model.motion.F(dt), Wq
        blocks.append(G)
        rhs.append(np.zeros(d))
    lin = model.motion.along(ref_t, ref_x, later.time)
    rows = linearize_rows(model.observation, lin, later.pair, later.doppler, later.sigma)
    k_of = np.searchsorted(times, later.time)
    for i in range(len(later)):
        a = np.zeros((1, n * d))
        a[0, k_of[i] * d:(k_of[i] + 1) * d] = rows.A[i]
        blocks.append(a)
        rhs.append(np.array([rows.b[i] + rows.A[i] @ lin[i]]))
    q, r = np.linalg.qr(np.vstack(blocks))
    mean = np.linalg.solve(r, q.T @ np.concatenate(rhs))
    ri = np.linalg.inv(r)
    k = n - 1 if at is None else int(np.searchsorted(times, at))
    return mean[k * d:(k + 1) * d], (ri @ ri.T)[k * d:(k + 1) * d, k * d:(k + 1) * d]


def _start(sim: fd.Simulation, ref_t: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """A start off the truth at the first scan, with a covariance that holds the offset."""
    t0 = float(ref_t[0])
    x = sim.truth.at(np.array([t0]))[0] + np.array([200.0, -150.0, 2.0, -1.0])
    return t0, x, np.diag([500.0**2, 500.0**2, 10.0**2, 10.0**2])


def _close(got: tuple[np.ndarray, np.ndarray], want: tuple[np.ndarray, np.ndarray]) -> None:
    """Means to 1e-6 of the largest standard deviation, covariances to 1e-7 relative."""
    np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-6 * np.sqrt(np.diag(want[1])).max())
    np.testing.assert_allclose(got[1], want[1], rtol=1e-7, atol=1e-9 * np.abs(want[1]).max())


def test_the_recursion_is_the_batch_posterior_of_the_linearised_model() -> None:
    """At the last scan and at one half-way, the filter's mean and covariance equal the batch solution."""
    sim, model = _recording()
    m = sim.measurements
    ref_t = np.unique(m.time)
    ref_x = _reference(sim, ref_t, np.random.default_rng(0))
    t0, x, P = _start(sim, ref_t)
    post = linearized_filter(m, model, ref_t, ref_x, t0, x, P)
    t = post.times
    np.testing.assert_array_equal(t, ref_t)
    for stop in (t.size // 2, t.size - 1):
        want = _batch(model, m.subset(m.time <= t[stop]), ref_t, ref_x, t0, x, P)
        _close((post.means[stop], post.covariances[stop]), want)
        got = post.at(np.array([t[stop]]))
        _close((got[0][0], got[1][0]), want)


def test_with_a_horizon_the_posterior_is_the_batch_solutions_interior_block() -> None:
    """The state at a time given the scans up to a later horizon (the smoother's read-out) is the block at
    that time of the batch solution over those scans: at a scan, between two scans (a state with no
    measurement), at the start, and with the horizon between scans or at the time itself (the filter's,
    carried to a time between scans)."""
    sim, model = _recording(4)
    m = sim.measurements
    ref_t = np.unique(m.time)
    ref_x = _reference(sim, ref_t, np.random.default_rng(3))
    t0, x, P = _start(sim, ref_t)
    post = linearized_filter(m, model, ref_t, ref_x, t0, x, P)
    mid = 0.5 * (ref_t[3] + ref_t[4])
    cases = [(ref_t[3], ref_t[8]), (mid, ref_t[8] + 0.1), (t0, ref_t[5]), (ref_t[2], ref_t[-1]), (mid, mid)]
    got = post.at(np.array([c[0] for c in cases]), np.array([c[1] for c in cases]))
    for k, (t, h) in enumerate(cases):
        want = _batch(model, m.subset(m.time <= h), ref_t, ref_x, t0, x, P, at=t)
        _close((got[0][k], got[1][k]), want)


def test_times_before_the_start_or_horizons_before_their_time_are_refused() -> None:
    sim, model = _recording()
    m = sim.measurements
    ref_t = np.unique(m.time)
    post = linearized_filter(m, model, ref_t, sim.truth.at(ref_t), *_start(sim, ref_t))
    with pytest.raises(ValueError, match="before the start"):
        post.at(np.array([ref_t[0] - 0.5]))
    with pytest.raises(ValueError, match="horizon"):
        post.at(np.array([ref_t[3]]), np.array([ref_t[2]]))


def test_each_posterior_reads_only_the_measurements_up_to_its_time() -> None:
    sim, model = _recording(5)
    m = sim.measurements
    ref_t = np.unique(m.time)
    ref_x = _reference(sim, ref_t, np.random.default_rng(1))
    t0 = float(ref_t[0])
    x, P = sim.truth.at(np.array([t0]))[0], np.diag([400.0**2, 400.0**2, 8.0**2, 8.0**2])
    whole = linearized_filter(m, model, ref_t, ref_x, t0, x, P)
    cut = float(ref_t[ref_t.size // 3])
    part = linearized_filter(m.subset(m.time <= cut), model, ref_t, ref_x, t0, x, P)
    k = part.times.size
    for name in ("times", "means", "covariances", "predicted_means", "predicted_covariances"):
        np.testing.assert_array_equal(getattr(part, name), getattr(whole, name)[:k])


def test_the_reference_is_carried_at_constant_velocity_between_its_times() -> None:
    _, model = _recording()
    ref_t = np.array([0.0, 1.0, 3.0])
    ref_x = np.array([[0.0, 0.0, 10.0, -5.0], [20.0, 0.0, 1.0, 2.0], [0.0, 50.0, -3.0, 0.0]])
    got = model.motion.along(ref_t, ref_x, np.array([-1.0, 0.0, 0.5, 1.0, 2.5, 3.0, 4.0]))
    want = np.array([[-10.0, 5.0, 10.0, -5.0], [0.0, 0.0, 10.0, -5.0], [5.0, -2.5, 10.0, -5.0],
                     [20.0, 0.0, 1.0, 2.0], [21.5, 3.0, 1.0, 2.0], [0.0, 50.0, -3.0, 0.0],
                     [-3.0, 50.0, -3.0, 0.0]])
    np.testing.assert_array_equal(got, want)


def test_the_mean_square_error_is_the_covariance_plus_the_offset_squared() -> None:
    rng = np.random.default_rng(2)
    L = rng.normal(size=(3, 4, 4))
    covs = L @ np.swapaxes(L, 1, 2)
    means, estimates = rng.normal(size=(3, 4)), rng.normal(size=(3, 4))
    got = mean_square_errors(estimates, means, covs)
    for k in range(3):
        d = estimates[k] - means[k]
        np.testing.assert_allclose(got[k], covs[k] + np.outer(d, d), rtol=1e-14)
