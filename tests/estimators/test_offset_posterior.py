"""Calibration offsets integrated out of a sampled track's likelihood: against the Gaussian marginal written out
in full, finite differences and the exact conditional of a linear problem."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from fgdoppler.estimators.offset_posterior import OffsetPrior


def _problem(rng: np.random.Generator, n_states: int = 3) -> tuple[OffsetPrior, np.ndarray, np.ndarray, np.ndarray,
                                                                    np.ndarray, np.ndarray]:
    """Three channels, the middle one calibrated; 9 measurements and ``n_states`` predictions of them."""
    prior = OffsetPrior.independent((0.8, 0.0, 1.7), 3, 4)
    assert prior is not None
    pair = np.array([0, 1, 2, 0, 2, 2, 1, 0, 0])
    sigma = rng.uniform(0.5, 2.0, pair.size)
    z = rng.normal(0.0, 3.0, pair.size)
    h = rng.normal(0.0, 3.0, (n_states, pair.size))  # h_j(x_i) of three states
    x = rng.normal(0.0, 100.0, (n_states, 4))
    return prior, pair, sigma, z, h, x


def _stats(prior: OffsetPrior, pair: np.ndarray, sigma: np.ndarray, z: np.ndarray,
           h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    E = prior.incidence(pair, sigma)
    return ((z - h) / sigma) @ E, np.sum(E * E, axis=0)


def _marginal(prior: OffsetPrior, pair: np.ndarray, sigma: np.ndarray, z: np.ndarray, h: np.ndarray,
              x: np.ndarray) -> np.ndarray:
    """log N(z; h + B mu0(x), D + B S B') written out: B maps each uncertain offset to its pair's measurements."""
    B = np.zeros((pair.size, prior.size))
    col = prior.channel[pair]
    B[col >= 0, col[col >= 0]] = 1.0
    S = np.linalg.inv(prior.S_inv)
    cov = np.diag(sigma**2) + B @ S @ B.T
    return np.array([multivariate_normal(h[i] + B @ prior.mean(x[i:i + 1])[0], cov).logpdf(z)
                     for i in range(h.shape[0])])


def _closed_form(prior: OffsetPrior, pair: np.ndarray, sigma: np.ndarray, z: np.ndarray, h: np.ndarray,
                 x: np.ndarray) -> np.ndarray:
    s, a = _stats(prior, pair, sigma, z, h)
    gauss = -0.5 * np.sum(((z - h) / sigma) ** 2, axis=1) - np.sum(np.log(sigma * np.sqrt(2 * np.pi)))
    return np.asarray(gauss + prior.extra(x, s, a) + prior.log_det(a))


def test_the_offsets_integrate_out_to_the_gaussian_marginal() -> None:
    # independent offsets, and the correlated, state-dependent prior a re-anchoring leaves
    rng = np.random.default_rng(1)
    prior, pair, sigma, z, h, x = _problem(rng)
    np.testing.assert_allclose(_closed_form(prior, pair, sigma, z, h, x), _marginal(prior, pair, sigma, z, h, x),
                               rtol=1e-12, atol=1e-9)
    A = rng.normal(size=(2, 2))
    moved = dataclasses.replace(prior, m_b=np.array([0.3, -0.6]), m_x=rng.normal(0, 50, 4),
                                K=rng.normal(0, 0.01, (2, 4)), S_inv=np.linalg.inv(A @ A.T + 0.5 * np.eye(2)))
    np.testing.assert_allclose(_closed_form(moved, pair, sigma, z, h, x), _marginal(moved, pair, sigma, z, h, x),
                               rtol=1e-12, atol=1e-9)
    # without data the offsets change nothing
    assert np.all(prior.extra(x, np.zeros((3, 2)), np.zeros(2)) == 0.0)
    np.testing.assert_allclose(moved.extra(x, np.zeros((3, 2)), np.zeros(2)), 0.0, atol=1e-12)
    assert moved.log_det(np.zeros(2)) == pytest.approx(0.0, abs=1e-12)


def test_a_calibrated_pair_carries_no_offset() -> None:
    assert OffsetPrior.independent(0.0, 2, 4) is None
    assert OffsetPrior.independent((0.0, 0.0), 2, 4) is None
    prior = OffsetPrior.independent((0.0, 2.0), 2, 4)
    assert prior is not None and prior.size == 1 and list(prior.channel) == [-1, 0]
    np.testing.assert_array_equal(prior.incidence(np.array([0, 1, 0]), np.array([1.0, 0.5, 2.0])),
                                  [[0.0], [2.0], [0.0]])
    with pytest.raises(ValueError, match="one per pair"):
        OffsetPrior.independent((1.0, 1.0, 1.0), 2, 4)


def test_the_joint_problem_at_the_offsets_mode_is_the_marginal() -> None:
    # profile(): half the sum of squares of the joint residuals at the offsets' conditional mode equals the
    # marginal's negative log-likelihood (less its constants); the Jacobian is that of the joint residuals
    # r(x) + E b and L(b - mu0(x)) with respect to (x, b) (central differences of a linear r(x) = J x - c);
    # and the offsets' conditional mode zeroes the joint gradient in b.
    rng = np.random.default_rng(2)
    prior, pair, sigma, _, _, _ = _problem(rng, 1)
    prior = dataclasses.replace(prior, m_b=np.array([0.2, 0.4]), K=rng.normal(0, 0.01, (2, 4)))
    J = rng.normal(0.0, 0.02, (pair.size, 4))
    c = rng.normal(0.0, 2.0, pair.size)
    x = rng.normal(0.0, 100.0, 4)
    E = prior.incidence(pair, sigma)

    def joint(xb: np.ndarray) -> np.ndarray:
        L = np.linalg.cholesky(prior.S_inv).T
        return np.concatenate([J @ xb[:4] - c + E @ xb[4:], L @ (xb[4:] - prior.mean(xb[None, :4])[0])])

    rows, jac = prior.profile(x, J @ x - c, J, E)
    # the same problem in the marginal's terms: r = (h - z) / sigma, so z - h = -sigma r
    s, a = -(J @ x - c) @ E, np.sum(E * E, axis=0)
    marginal = -0.5 * np.sum((J @ x - c) ** 2) + prior.extra(x[None], s[None], a)[0]
    assert -0.5 * rows @ rows == pytest.approx(marginal, rel=1e-12)
    b = prior.posterior(x[None], s[None], a)[0][0]
    np.testing.assert_allclose(rows, joint(np.concatenate([x, b])), rtol=1e-12, atol=1e-12)
    step = 1e-3
    fd_jac = np.column_stack([(joint(np.concatenate([x, b]) + step * e) - joint(np.concatenate([x, b]) - step * e))
                              / (2 * step) for e in np.eye(6)])
    np.testing.assert_allclose(jac, fd_jac, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose((jac.T @ rows)[4:], 0.0, atol=1e-10 * np.abs(jac).max() * np.abs(rows).max())


def test_reanchoring_a_linear_problem_keeps_the_offsets_exact_conditional() -> None:
    # When the data's statistics are linear in the state, s = x G, the offsets' posterior given the state is
    # exactly N((s + mu0 S^-1) Lambda^-1, Lambda^-1) with a mean linear in x: the moment-matched prior of the
    # new anchor (no motion between the anchors) must reproduce that slope and covariance to rounding, whatever
    # the cloud of states.
    rng = np.random.default_rng(3)
    prior = OffsetPrior.independent((0.8, 1.7), 2, 4)
    assert prior is not None
    G = rng.normal(0.0, 0.05, (4, 2))
    x = rng.normal(0.0, 100.0, (500, 4))
    a = np.array([12.0, 30.0])
    w = rng.uniform(0.1, 1.0, 500)
    new = prior.reanchored(x, x, x @ G, a, w)
    cov = np.linalg.inv(prior.precision(a))
    np.testing.assert_allclose(new.K, (G @ cov).T, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(new.S_inv), cov, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(new.mean(x), prior.posterior(x, x @ G, a)[0], rtol=1e-9, atol=1e-9)
