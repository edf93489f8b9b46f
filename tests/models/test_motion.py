from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd


def test_F_closed_form() -> None:
    T = 0.7
    F = fd.ConstantVelocity().F(T)
    np.testing.assert_array_equal(F, [[1, 0, T, 0], [0, 1, 0, T], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert fd.ConstantVelocity().F(np.array([0.5, 1.0])).shape == (2, 4, 4)


def test_discrete_Q_is_paper_gamma_q_gamma() -> None:
    T, s2 = 0.5, 0.3
    G = np.array([[0.5 * T**2, 0], [0, 0.5 * T**2], [T, 0], [0, T]])
    Q = fd.ConstantVelocity(q=s2, form="discrete").Q(T)
    np.testing.assert_allclose(Q, G @ (s2 * np.eye(2)) @ G.T, rtol=1e-15)
    assert np.linalg.matrix_rank(Q) == 2


def test_continuous_Q_closed_form_and_full_rank() -> None:
    T, q = 0.5, 0.02
    Q = fd.ConstantVelocity(q=q).Q(T)
    block = q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
    np.testing.assert_allclose(Q[np.ix_([0, 2], [0, 2])], block, rtol=1e-15)
    np.testing.assert_allclose(Q[np.ix_([1, 3], [1, 3])], block, rtol=1e-15)
    assert Q[0, 1] == Q[0, 3] == 0
    assert np.linalg.matrix_rank(Q) == 4


def test_continuous_Q_is_integral_of_F_L_L_F() -> None:
    # Q(T) = q * int_0^T F(s) L L' F(s)' ds with L = [0 0 1 0; 0 0 0 1]'; midpoint rule.
    T, q, n = 0.8, 0.1, 4000
    s = (np.arange(n) + 0.5) * T / n
    L = np.zeros((4, 2))
    L[2, 0] = L[3, 1] = 1
    FL = fd.ConstantVelocity().F(s) @ L
    Qn = q * np.einsum("kij,klj->il", FL, FL) * T / n
    np.testing.assert_allclose(fd.ConstantVelocity(q=q).Q(T), Qn, rtol=1e-6)


def test_Q_adds_over_split_intervals() -> None:
    # Continuous model: Q(a+b) = F(b) Q(a) F(b)' + Q(b).
    m = fd.ConstantVelocity(q=0.05)
    a, b = 0.3, 0.45
    Fb = m.F(b)
    np.testing.assert_allclose(m.Q(a + b), Fb @ m.Q(a) @ Fb.T + m.Q(b), rtol=1e-13)


def test_sqrt_information_and_rejections() -> None:
    m = fd.ConstantVelocity(q=0.01)
    R = m.sqrt_information(0.5)
    np.testing.assert_allclose(R.T @ R, np.linalg.inv(m.Q(0.5)), rtol=1e-9)
    with pytest.raises(ValueError, match="full-rank"):
        fd.ConstantVelocity(q=0.01, form="discrete").sqrt_information(0.5)
    with pytest.raises(ValueError, match="full-rank"):
        m.sqrt_information(0.0)
    with pytest.raises(ValueError):
        fd.ConstantVelocity(q=-1.0)


def test_propagate_and_noise(rng: np.random.Generator) -> None:
    m = fd.ConstantVelocity(q=0.2)
    x = np.array([1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(m.propagate(x, 0.5), m.F(0.5) @ x)
    w = m.sample_noise(0.5, rng, size=20000)
    np.testing.assert_allclose(np.cov(w.T), m.Q(0.5), atol=4 * np.sqrt(2.0 / 20000) * np.max(np.diag(m.Q(0.5))))
