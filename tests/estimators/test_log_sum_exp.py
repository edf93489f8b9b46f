"""log_sum_exp against SciPy's logsumexp (an independent implementation), analytic values and its edge cases."""

from __future__ import annotations

import numpy as np
import pytest
import scipy
from scipy.special import logsumexp

from fgdoppler.estimators.log_sum_exp import log_sum_exp

#: The SciPy whose arithmetic log_sum_exp repeats (the particle estimators' tracks then do not depend on which of
#: the two normalises their weights); older ones sum the same terms in another order.
SAME_BITS = tuple(int(v) for v in scipy.__version__.split(".")[:2]) >= (1, 17)


def _agree(ours: np.ndarray, theirs: np.ndarray) -> None:
    if SAME_BITS:
        np.testing.assert_array_equal(ours, theirs)
    else:
        np.testing.assert_allclose(ours, theirs, rtol=1e-14, atol=0.0)


def test_it_is_scipys_logsumexp_on_weights_like_the_particles() -> None:
    rng = np.random.default_rng(7)
    for trial in range(400):
        n = int(rng.integers(1, 5000))
        a = rng.normal(size=n) * rng.uniform(0.01, 2000.0)  # log weights spread from flat to one dominant
        if trial % 5 == 0:
            a[rng.integers(n, size=max(1, n // 10))] = -np.inf  # particles off the support
        if trial % 7 == 0:
            a = np.round(a)  # ties for the maximum
        ours = log_sum_exp(a)
        assert ours.shape == ()
        _agree(ours, np.asarray(logsumexp(a)))
        table = rng.normal(size=(int(rng.integers(1, 9)), n)) * 40.0  # mixture components x particles
        _agree(log_sum_exp(table, axis=0), logsumexp(table, axis=0))
        _agree(log_sum_exp(table, axis=0, keepdims=True), logsumexp(table, axis=0, keepdims=True))
        _agree(log_sum_exp(table, axis=1), logsumexp(table, axis=1))


def test_analytic_values() -> None:
    assert log_sum_exp(np.log([1.0, 2.0, 3.0])) == pytest.approx(np.log(6.0), rel=1e-15)
    # n equal entries: a + log n exactly as the formula's log m term gives it
    assert log_sum_exp(np.full(8, -1234.5)) == -1234.5 + np.log(8.0)
    # far beyond exp's range, either way
    assert log_sum_exp([1000.0, 1000.0 + np.log(3.0)]) == pytest.approx(1000.0 + np.log(4.0), rel=1e-15)
    assert log_sum_exp([-1e5, -1e5]) == pytest.approx(-1e5 + np.log(2.0), rel=1e-15)
    # a term below the largest by more than the double's precision adds nothing
    assert log_sum_exp([0.0, -800.0]) == 0.0


def test_edge_cases_give_what_the_direct_sum_gives() -> None:
    assert log_sum_exp([-np.inf, -np.inf]) == -np.inf
    assert log_sum_exp([np.inf, 1.0]) == np.inf
    assert np.isnan(log_sum_exp([np.nan, 1.0]))
    assert log_sum_exp([5.0]) == 5.0
    assert log_sum_exp(np.zeros(0)) == -np.inf
    np.testing.assert_array_equal(log_sum_exp(np.zeros((3, 0)), axis=1), np.full(3, -np.inf))
    # one column all -inf beside a finite one: each column on its own
    np.testing.assert_array_equal(log_sum_exp(np.array([[-np.inf, 0.0], [-np.inf, 0.0]]), axis=0),
                                  [-np.inf, np.log(2.0)])
