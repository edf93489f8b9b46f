"""The trackers' window re-solve: GTSAM's LM on small windows, the offline smoother's O(N) solver on large ones."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators import window as window_module
from fgdoppler.estimators.window import LARGE_WINDOW, solve_window


def test_a_large_window_reaches_the_optimum_gtsams_lm_reaches() -> None:
    # Two independent solvers of the same objective (graph of CustomFactors by GTSAM, numpy rows by the
    # smoother's LM) from the same guesses on a well-observed window of more than LARGE_WINDOW scans, with the
    # model's process noise in the truth: where both converge they agree far inside the states' spread.
    scen = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=150.0, dt=0.5,
                       process_noise=fd.ConstantVelocity(q=1e-3))
    sim = fd.simulate(scen, np.random.default_rng(5))
    m = sim.measurements
    model = fd.TrackingModel.of(scen.geometry)
    times = m.scans().times
    assert len(times) > LARGE_WINDOW
    start = sim.truth.states[0] + np.array([300.0, -200.0, 2.0, -1.0])
    guesses = model.motion.propagate(start, times - times[0])
    large, note = solve_window(model, m, guesses, prior=model.prior())
    assert note is None
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(window_module, "LARGE_WINDOW", len(times))  # the same window through GTSAM's LM
        small, note = solve_window(model, m, guesses, prior=model.prior())
    assert note is None
    assert not np.array_equal(large, small)  # two solvers indeed
    np.testing.assert_allclose(large[:, :2], small[:, :2], rtol=0, atol=1e-3)  # m, of errors of tens of m
    np.testing.assert_allclose(large[:, 2:], small[:, 2:], rtol=0, atol=1e-5)  # m/s (measured: 2e-4 m, 9e-7 m/s)


def test_a_window_that_fails_returns_the_guesses_and_says_why() -> None:
    model = fd.TrackingModel.of(fd.paper_geometry("a"))
    m = fd.Measurements.from_arrays(np.arange(300) * 0.5, np.zeros(300, dtype=int), np.zeros(300), 1.0)
    g = np.zeros((300, 4))  # every state on the receiver at the origin: the model is undefined there
    states, note = solve_window(model, m, g, prior=model.prior())
    np.testing.assert_array_equal(states, g)
    assert note is not None and note.startswith("window start: LM failed")
