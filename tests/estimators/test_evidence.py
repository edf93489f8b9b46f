"""The window evidence that weighs an ambiguous initiation's solutions (:func:`window_log_evidence`)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from scipy.stats import norm, poisson

import fgdoppler as fd
from fgdoppler.estimators.ambiguity import hypotheses, hypothesis_weights
from fgdoppler.estimators.initiation import EVIDENCE_DRAWS, InitiationSettings, window_log_evidence
from fgdoppler.estimators.registry import hypotheses_of
from fgdoppler.factors import X, prior_factor
from fgdoppler.graphs import chain_values


def _gaussian_case(start: np.ndarray) -> tuple[float, float, float]:
    """A one-state graph whose posterior is exactly N(mu, diag(sd^2)) and a box zone around part of it.

    Returns the evidence, the exact value and the sampling tolerance of its zone term.
    """
    mu = np.array([1000.0, 200.0, 5.0, -3.0])
    sd = np.array([300.0, 150.0, 10.0, 10.0])
    graph = gtsam.NonlinearFactorGraph()
    graph.add(prior_factor(X(0), mu, np.diag(sd**2)))
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(5e3, 0.0), rx=(0.0, 0.0)),))
    zone = fd.Zone(along=(800.0, 5000.0), across=(0.0, 500.0), speed_max=1e4)
    model = fd.TrackingModel.of(g, zone=zone)
    logz = window_log_evidence(graph, 1, chain_values([start]), model)
    assert logz is not None
    # exact: the objective is 0 at the mode, det A = det Sigma^-1, and the zone keeps the box's
    # Gaussian probability (the speed bound, 1e4 m/s at 10 m/s spread, keeps everything)
    p = float(np.prod([norm.cdf((hi - m) / s) - norm.cdf((lo - m) / s)
                       for (lo, hi), m, s in zip(zone.intervals, mu[:2], sd[:2], strict=True)]))
    exact = float(np.sum(np.log(sd)) + np.log(p))
    # the zone term is a binomial share of EVIDENCE_DRAWS draws: 4 standard errors of its log
    return logz, exact, 4.0 * np.sqrt((1.0 - p) / (EVIDENCE_DRAWS * p))


@pytest.mark.parametrize("offset", [0.0, 1.0])
def test_evidence_of_a_gaussian_posterior_is_its_volume_times_the_zone_share(offset: float) -> None:
    """Laplace is exact for a Gaussian; started off the mode (offset of one sd), LM finds it first."""
    start = np.array([1000.0, 200.0, 5.0, -3.0]) + offset * np.array([300.0, -150.0, 10.0, 10.0])
    logz, exact, tol = _gaussian_case(start)
    assert abs(logz - exact) < tol


def test_exact_mirror_solutions_carry_the_same_evidence() -> None:
    """All sensors on one line and a zone symmetric about it: a solution and its mirror weigh the same."""
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)), fd.BistaticPair(tx=(60e3, 0.0), rx=(0.0, 0.0))))
    sc = fd.Scenario(geometry=g, x0=(42e3, 4e3, -60.0, -80.0), duration=10.0, sigma=0.5)
    sim = fd.simulate(sc, np.random.default_rng(0))
    init = fd.initiate(sim.measurements.first_per_pair(20), g, InitiationSettings())
    assert len(init.alternatives) == 1 and init.log_evidence is not None
    alt = init.alternatives[0].log_evidence
    assert alt is not None
    # the volumes and costs agree to LM's convergence; the zone shares differ only by sampling:
    # both are ~1 here (4 km from the line, the zone reaches 6 km), so the tolerance is small
    assert abs(alt - init.log_evidence) < 4.0 * np.sqrt(1.0 / EVIDENCE_DRAWS)
    w = hypothesis_weights(init)
    assert w is not None and w.shape == (2,)
    np.testing.assert_allclose(w, [0.5, 0.5], atol=0.05)


def test_closed_form_initiations_keep_the_cost_weights() -> None:
    """Only LM computes the evidence; ILS and grid answers fall back to e^{-c/2} (weights None)."""
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)), fd.BistaticPair(tx=(60e3, 0.0), rx=(0.0, 0.0))))
    sc = fd.Scenario(geometry=g, x0=(42e3, 4e3, -60.0, -80.0), duration=10.0, sigma=0.5)
    w = fd.simulate(sc, np.random.default_rng(0)).measurements.first_per_pair(20)
    for method in ("ils", "grid"):
        init = fd.initiate(w, g, InitiationSettings(method=method))
        assert init.log_evidence is None
        assert hypothesis_weights(init) is None


@pytest.mark.slow
def test_mirror_solutions_outside_the_zone_weigh_what_the_truth_says() -> None:
    """Calibration on the paper's six scenarios (100 runs each, their own seed; about 2 minutes).

    Every alternative there is held at the zone's along-baseline edge.  If
    the weights are calibrated, the number of windows whose truth is most
    probable under an alternative's Gaussian is (close to) Poisson
    with mean the sum of the alternatives' weights: that count is 0 here,
    which the evidence weights explain (P(0) well above 1 %) and the window
    costs' e^{-c/2} weights do not (their mean puts P(0) below 1 %).
    """
    alt_w, cost_w, in_alt = [], [], 0
    for s in range(6):
        scen = fd.paper_scenarios()[s]
        model = fd.TrackingModel.of(scen.geometry)
        for r in range(100):
            sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([31, s, r])))
            init = fd.initiate(sim.measurements.first_per_pair(10), model)
            if not init.ambiguous:
                continue
            hyps = hypotheses(init)
            w = hypothesis_weights(init)
            assert w is not None
            c = np.exp(-0.5 * np.array([h.cost for h in hyps]))
            alt_w.append(1.0 - w[0])
            cost_w.append(1.0 - c[0] / c.sum())
            truth = sim.truth.states[int(np.argmin(np.abs(sim.truth.times - init.t_start)))]
            dens = []
            for h in hyps:
                assert h.P_start is not None
                d = h.x_start - truth
                dens.append(-0.5 * (d @ np.linalg.solve(h.P_start, d) + np.linalg.slogdet(h.P_start)[1]))
            in_alt += int(np.argmax(dens) != 0)
    assert len(alt_w) >= 20
    assert poisson.cdf(in_alt, sum(alt_w)) > 0.01
    assert poisson.cdf(in_alt, sum(cost_w)) < 0.01


def test_registry_starts_an_ambiguous_initiation_with_the_evidence_weights() -> None:
    """The trackers' prior weights for an ambiguous window are :func:`hypothesis_weights` (case a 45 km, run 33 of seed 7).

    Where the start is not split: this window's curvature probe ratio (4.5)
    lies beyond the default ``split_ratio`` (2.5), so by default the trackers
    start from the terms of its sampled posterior instead, proposed from
    both solutions; with ``split_ratio=inf`` (the split on the ``nonlinear``
    finding alone) from one hypothesis per solution.
    """
    s, seed, r = 2, 7, 33
    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    assert init.ambiguous and not any(x.code == "nonlinear" and x.status != "ok" for x in init.reasons)
    assert init.curvature is not None and fd.EKFSettings().splits(init.curvature)
    terms, tw = hypotheses_of("ekf", sim.measurements, model, init, fd.EKFSettings())
    assert tw is not None and 2 < len(terms) == tw.size <= fd.EKFSettings().components
    assert all(h.window_summarised for h in terms) and np.isclose(tw.sum(), 1.0)
    hyps, w = hypotheses_of("ekf", sim.measurements, model, init, fd.EKFSettings(split_ratio=float("inf")))
    expected = hypothesis_weights(init)
    assert w is not None and expected is not None and len(hyps) == w.size == 2
    np.testing.assert_array_equal(w, expected)
    # the alternative held at the zone's edge keeps a few percent, not the half its window cost gives it
    assert w[1] < 0.05
