"""The Huber loss: gross outliers cost little accuracy, in the initiation and every estimator."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.settings import SampledCovarianceSettings
from fgdoppler.models.robust import huber_residuals, huber_rho, huber_weights


def test_the_three_forms_of_the_loss_agree() -> None:
    r = np.linspace(-20.0, 20.0, 4001)
    k = 1.345
    e, d = huber_residuals(r, k)
    np.testing.assert_allclose(e**2, huber_rho(r, k), rtol=1e-12, atol=1e-12)
    # derivative of the transformed residual by central differences, away from the kink at |r| = k
    h = 1e-6
    fd_d = (huber_residuals(r + h, k)[0] - huber_residuals(r - h, k)[0]) / (2 * h)
    away = np.abs(np.abs(r) - k) > 1e-3
    np.testing.assert_allclose(d[away], fd_d[away], rtol=1e-6)
    # the IRLS weight is the loss's psi(r) / (2 r): rho'(r) = 2 r w(r)
    fd_rho = (huber_rho(r + h, k) - huber_rho(r - h, k)) / (2 * h)
    np.testing.assert_allclose(fd_rho[away], 2 * r[away] * huber_weights(r[away], k), rtol=1e-6, atol=1e-9)
    assert np.array_equal(huber_rho(r, None), r * r) and np.all(huber_weights(r, None) == 1.0)


def test_the_loss_in_place_is_the_loss() -> None:
    # the grid's hot loop writes the loss over the residuals (out=r): the same numbers, to the bit, as a fresh
    # array and as the definition, at the kink, at zero and for non-finite residuals
    k = 1.345
    r = np.concatenate([np.linspace(-20.0, 20.0, 4001), [k, -k, 0.0, -0.0, np.inf, -np.inf, np.nan]])
    a = np.abs(r)
    with np.errstate(invalid="ignore"):
        defined = np.where(a <= k, r * r, 2.0 * k * a - k * k)
    fresh = huber_rho(r, k)
    in_place = r.copy()
    assert huber_rho(in_place, k, out=in_place) is in_place
    np.testing.assert_array_equal(fresh, defined)
    np.testing.assert_array_equal(in_place, defined)
    assert float(huber_rho(3.0, k)) == 2.0 * k * 3.0 - k * k and float(huber_rho(-1.0, k)) == 1.0


def _outliers(m: fd.Measurements, rng: np.random.Generator) -> fd.Measurements:
    z = m.doppler.copy()
    idx = rng.choice(len(m), round(0.05 * len(m)), replace=False)
    z[idx] += rng.choice([-100.0, 100.0], idx.size)
    return fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)


def _states_only(settings: fd.TrackerSettings) -> fd.TrackerSettings:
    """``settings`` without a filter's sampled covariances, which change no state (only covariances, unused here)."""
    if isinstance(settings, SampledCovarianceSettings):
        return dataclasses.replace(settings, sampled_covariance=False)
    return settings


# Two long studies (20 recordings x 2 losses x every estimator: 100-150 s each on two cores), run with
# -m slow so the default run stays inside the CI budget; by default the outliers' cases of
# test_verdict.py::test_degenerate_cases_are_never_wrong_and_ok (both losses, every estimator) and the
# robust Levenberg-Marquardt tests below hold the robust estimators to account.
@pytest.mark.slow
@pytest.mark.parametrize(("case", "x"), [("a", 45e3), ("b", 5e3)])
def test_five_percent_gross_outliers_cost_at_most_half_the_clean_accuracy(case: str, x: float) -> None:
    # 5 % of the measurements replaced by +-100 m/s (100 sigma) outliers; with the Huber loss every estimator's
    # time-averaged position RMSE is within 1.5x its clean RMSE.  Measured (40 runs, seed 3): 1.05-1.33x;
    # 1.08-1.15x since the smoother's LM fix (2026-11-26; the smoother 1.14x and 1.15x); without the loss
    # 8-100x.
    scen = fd.paper_scenario(case, x)
    se: dict[tuple[str, str], list[float]] = {}
    for seq in np.random.SeedSequence(3).spawn(20):
        rng = np.random.default_rng(seq)
        sim = fd.simulate(scen, rng)
        for label, meas, k in (("clean", sim.measurements, None), ("robust", _outliers(sim.measurements, rng), 1.345)):
            init = fd.initiate(meas.first_per_pair(10), scen.geometry, fd.InitiationSettings(huber_k=k))
            # one call for all: each estimate is run_estimator's own, the filters' restart fits computed once
            results = fd.run_estimators(fd.ESTIMATORS, meas, scen.geometry, init,
                                        {n: _states_only(i.settings(huber_k=k)) for n, i in fd.ESTIMATORS.items()},
                                        verify=False)
            for name, r in results.items():
                e = r.primary.states - sim.truth.at(r.primary.times)
                se.setdefault((name, label), []).append(float(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))
    ratios = {n: np.sqrt(np.mean(se[(n, "robust")]) / np.mean(se[(n, "clean")])) for n in fd.ESTIMATORS}
    assert all(v <= 1.5 for v in ratios.values()), ratios


def _with_outliers(s: int, run: int) -> tuple[fd.Measurements, fd.TrackingModel, fd.Initiation]:
    """Paper scenario ``s``, recording ``run`` of seed 3, with 5 % gross outliers; its robust initiation."""
    scen = fd.paper_scenarios()[s]
    rng = np.random.default_rng(np.random.SeedSequence([3, s, run]))
    m = _outliers(fd.simulate(scen, rng).measurements, rng)
    model = fd.TrackingModel.of(scen.geometry)
    return m, model, fd.initiate(m.first_per_pair(10), model, fd.InitiationSettings(huber_k=1.345))


def test_the_robust_linear_model_meets_the_cost_where_it_is_built() -> None:
    # The smoother's measurement rows carry the IRLS weights: at the linearisation point the model holds
    # w r^2 = k|r| for an outlier where the Huber cost holds 2k|r| - k^2.  The cost less model_gap is the
    # model's value at a zero step, for any states (here the truth-free initial trajectory) and damping.
    from fgdoppler.estimators.smoother import initial_trajectory
    from fgdoppler.estimators.smoother_solve import _Problem

    m, model, init = _with_outliers(5, 0)
    settings = fd.SmootherSettings(huber_k=1.345)
    x = initial_trajectory(m, model, init, settings)
    prob = _Problem(model, m, 1.345, model.prior(), None, None)
    assert prob.model_gap(x) > 100.0  # six outliers of about 100 sigma: k(|r| - k) each
    for lam in (0.0, 1e-3):
        gfg = prob.system(x, lam)
        at_zero = prob.model_cost(gfg, np.zeros_like(x), lam)
        np.testing.assert_allclose(prob.cost(x) - prob.model_gap(x), at_zero, rtol=1e-10)
    assert _Problem(model, m, None, model.prior(), None, None).model_gap(x) == 0.0


@pytest.mark.parametrize("s", [0, 5])
def test_with_the_huber_loss_levenberg_marquardt_stops_at_a_minimum(s: int) -> None:
    # Case a 5 km and case b 45 km with 5 % outliers of 100 sigma: from where the smoother stops, a full
    # Gauss-Newton step of the robust model (IRLS) predicts no further decrease, and Levenberg-Marquardt
    # started there again does not lower the cost.  Measured before the model's predicted decrease was taken
    # from its own value (model_gap): LM, its damping raised at every step, stopped where such a step still
    # predicted 13 (case a 5 km) and 34 (case b 45 km), and 1.4-40 in cost above where it stops now in runs
    # 0-2 of case b 45 km, 7.6-16 in case a 5 km.
    from fgdoppler.estimators.smoother import initial_trajectory
    from fgdoppler.estimators.smoother_solve import _Problem, solve_smoother

    m, model, init = _with_outliers(s, 0)
    settings = fd.SmootherSettings(huber_k=1.345)
    x0 = initial_trajectory(m, model, init, settings)
    sol = solve_smoother(m, model, x0, settings, prior=model.prior())
    assert all(r.code != "not-converged" for r in sol.reasons)
    zone = model.zone
    assert zone is not None
    sp, sv = settings.wall_sigma
    prob = _Problem(model, m, 1.345, model.prior(), None, (zone, np.array([sp] * zone.dim + [sv])))
    gfg = prob.system(sol.states, 0.0)
    dx, _ = prob.solve(gfg)
    decrement = prob.cost(sol.states) - prob.model_gap(sol.states) - prob.model_cost(gfg, dx, 0.0)
    assert decrement < 1e-6 * sol.cost, (decrement, sol.cost)
    again = solve_smoother(m, model, sol.states, settings, prior=model.prior())
    assert again.cost >= sol.cost - 1e-6 * sol.cost
