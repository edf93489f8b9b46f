"""The triangular inverse behind the smoother's and iSAM2's covariances."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from scipy.linalg import solve_triangular

from fgdoppler.estimators.marginals import _inverse_r, upper_inverse


def _graded(d: int, seed: int) -> np.ndarray:
    """An upper-triangular R with rows scaled over ten decades (cond ~1e10), as near the baseline."""
    rng = np.random.default_rng(seed)
    R = np.triu(rng.standard_normal((d, d))) + 3.0 * np.eye(d)
    return np.logspace(3, -7, d)[:, None] * R


@pytest.mark.parametrize("d", [4, 6])
@pytest.mark.parametrize("seed", range(5))
def test_upper_inverse_is_the_triangular_inverse(d: int, seed: int) -> None:
    # Exactly upper triangular, and backward stable componentwise as a triangular inversion is
    # (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., sec. 14.2: the left residual
    # |X R - I| <= c_d u |X||R|, c_d of order d), so the graded rows cost no accuracy; then equal to
    # a dedicated triangular solve within the forward bound that follows, 2 c_d u |R^-1||R||R^-1|.
    R = _graded(d, seed)
    Ri = upper_inverse(R)
    assert np.array_equal(Ri, np.triu(Ri))
    u = np.finfo(float).eps / 2
    assert np.all(np.abs(Ri @ R - np.eye(d)) <= d * u * (np.abs(Ri) @ np.abs(R)))
    ref = solve_triangular(R, np.eye(d))
    assert np.all(np.abs(Ri - ref) <= 2 * d * u * (np.abs(ref) @ np.abs(R) @ np.abs(ref)))


def test_a_conditional_with_a_vanishing_diagonal_is_indeterminate() -> None:
    R = _graded(4, 0)
    R[2, 2] = 0.0
    c = gtsam.GaussianConditional(7, np.zeros(4), R)
    with pytest.raises(RuntimeError, match="indeterminate"):
        _inverse_r(c)
    good = gtsam.GaussianConditional(7, np.zeros(4), _graded(4, 1))
    assert np.array_equal(_inverse_r(good), upper_inverse(_graded(4, 1)))
