r"""Is a Gaussian covariance a fair description of a likelihood?  A two-point probe.

A least-squares estimate's covariance :math:`\mathbf P = \mathbf I^{-1}` comes
from the quadratic model of the cost at the optimum: moving the state by
:math:`\boldsymbol\delta` raises the cost by
:math:`\boldsymbol\delta^\top\mathbf I\,\boldsymbol\delta`.  Near the Tx–Rx
baseline, far from it, or with a short window, the Doppler likelihood of
the start state is a thin curved valley and that model fails: the
covariance then misstates where the target can be, by orders of magnitude
in Mahalanobis terms, while the estimate itself may be fine.

The probe moves the state three of its reported standard deviations along
the major axis of the position uncertainty —
:math:`\boldsymbol\delta = \mathbf P_{:,p}\mathbf v / \sqrt{\mathbf v^\top\mathbf P_{pp}\mathbf v}`
with :math:`\mathbf v` the major eigenvector of the position block, the
other components following at their conditional means — to both sides, and
compares the cost rises :math:`\Delta_\pm` with the quadratic model's
:math:`9\,\boldsymbol\delta^\top\mathbf I\,\boldsymbol\delta` (9 when
:math:`\mathbf P = \mathbf I^{-1}`):

* a curved valley: the straight line leaves it on both sides, the smaller
  rise exceeds the prediction :math:`L` times;
* a flat one: on some side the cost rises by less than :math:`1/L` of the
  prediction; the uncertainty is larger than stated.

Away from an optimum (the paper's grid and ILS estimates) the rises first
lose their linear term, and only the first test applies (the
Gauss–Newton model of a point with large residuals is not its curvature).

With :data:`CURVATURE_LIMIT` :math:`L = 10`.  Measured on the initiation
windows of the paper's scenarios (60 runs each, seed 99): the
well-observed ones (case a 45 km, case b 5 km) give ratios 1.1–1.7 and a
consistent covariance (mean NEES 4.6–4.8 for 4 dimensions); case a 5 km and
case b 45 km give 53–1,700 and a median NEES of 53–57 (the true state only
1–10 above the minimum cost: a good estimate with a wrong covariance); the
25 km scenarios lie between (4–1,100, median 11).  There (150 runs each,
seed 7), windows with ratio ≤ 10 have mean NEES 3.9 and 1.4 % beyond the
χ²₄ 99.9 % quantile; those above 10 have mean NEES 7–17 and 11 % beyond it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgdoppler._text import distance_text
from fgdoppler.estimators.verdict import Reason

__all__ = ["CURVATURE_LIMIT", "curvature_check", "curvature_reason", "probe_axis", "probe_rises", "rises_along"]

FloatArray = NDArray[np.float64]

#: How far (as a factor on the quadratic model's cost rise of 9) the probe may stray before the
#: covariance is called a poor description of the likelihood.
CURVATURE_LIMIT = 10.0
#: The probe's distance in standard deviations.
PROBE_SIGMAS = 3.0


def probe_axis(P: FloatArray, order: int = 0) -> tuple[FloatArray, float]:
    r"""The probe's unit step :math:`\boldsymbol\delta` (one standard deviation) and the position σ along it.

    :math:`\boldsymbol\delta = \mathbf P_{:,p}\mathbf v / \sqrt{\mathbf v^\top\mathbf P_{pp}\mathbf v}` with
    :math:`\mathbf v` the major eigenvector of the position block (``order`` 1: the next one): the other
    components follow at their conditional means, and
    :math:`\boldsymbol\delta^\top\mathbf P^{-1}\boldsymbol\delta = 1`.  The coordinates along two
    eigenvectors are uncorrelated, so the steps along them are the regressions on each alone and on both.
    """
    k = P.shape[0] // 2  # position block (2-D or 3-D)
    Ppp = P[:k, :k]
    _, V = np.linalg.eigh(Ppp)
    v = V[:, -1 - order]
    sd = float(np.sqrt(v @ Ppp @ v))
    return P[:, :k] @ v / sd, sd


def probe_rises(cost: Callable[[FloatArray], Any], x: FloatArray, P: FloatArray,
                information: FloatArray, *, rows: bool = False) -> tuple[float, float, float, float]:
    r"""Cost rises at ``x ∓ 3δ`` less the linear term, the quadratic model's rise, and the position σ along δ.

    ``information`` is :math:`\mathbf J^\top\mathbf J` of the whitened
    residuals: in the quadratic model a step :math:`\boldsymbol\delta`
    raises the cost (a sum of squares) by
    :math:`\boldsymbol\delta^\top\mathbf I\,\boldsymbol\delta`.  At a point
    that is not an optimum (a grid node) the rises first lose the linear
    term :math:`\pm 3\,\nabla c^\top\boldsymbol\delta` (slope by a central
    difference), so that only curvature is compared; at an optimum that term
    is zero.  With ``rows`` the cost takes the five probe points as the rows
    of one array and returns their five costs (one call of a vectorised
    cost instead of five).
    """
    d, sd = probe_axis(P)
    lo, hi = rises_along(cost, x, d, rows=rows)
    step = PROBE_SIGMAS * d
    return lo, hi, float(step @ information @ step), sd


def rises_along(cost: Callable[[FloatArray], Any], x: FloatArray, d: FloatArray, *, rows: bool = False
                ) -> tuple[float, float]:
    r"""The cost's rises at ``x ∓ 3d`` less the linear term :math:`\pm 3\,\nabla c^\top\mathbf d` (a central
    difference): :func:`probe_rises` for a given step ``d`` (one standard deviation) of ``x``'s shape (a state, or
    with ``rows`` false a whole trajectory)."""
    h = 1e-3
    steps = np.array([0.0, h, -h, -PROBE_SIGMAS, PROBE_SIGMAS])

    def at(step: float) -> float:
        try:
            c = cost(x + step * d) if not rows else cost((x + step * d)[None])[0]
        except ValueError:  # a trajectory through a sensor
            return np.inf
        return float(c) if np.isfinite(c) else np.inf

    try:
        costs = np.asarray(cost(x + steps[:, None] * d), dtype=float) if rows else None
    except ValueError:  # one of them through a sensor: each alone
        costs = None
    if costs is None:
        costs = np.array([at(float(step)) for step in steps])
    # Python floats: inf - inf is nan without a warning, as the five scalar calls always gave
    c0, ch, cmh, clo, chi = (float(c) if np.isfinite(c) else np.inf for c in costs)
    slope = (ch - cmh) / (2.0 * h)
    slope = slope if np.isfinite(slope) else 0.0
    return clo - c0 + PROBE_SIGMAS * slope, chi - c0 - PROBE_SIGMAS * slope


def curvature_reason(cost: Callable[[FloatArray], float], x: FloatArray, P: FloatArray,
                     information: FloatArray, *, at_optimum: bool = True) -> Reason | None:
    """A ``"doubtful"`` ``nonlinear`` finding when the probe strays beyond :data:`CURVATURE_LIMIT`, else ``None``.

    ``P`` is the reported covariance (it sets the probe), ``information``
    the cost's own quadratic model (it sets the prediction).  The test for
    a flat valley needs ``x`` to be an optimum (``at_optimum``): elsewhere
    the Gauss–Newton model leaves out the residuals' second-order terms,
    which lower the curvature by themselves.
    """
    return curvature_check(cost, x, P, information, at_optimum=at_optimum)[1]


def curvature_check(cost: Callable[[FloatArray], float], x: FloatArray, P: FloatArray,
                    information: FloatArray, *, at_optimum: bool = True) -> tuple[float, Reason | None]:
    r"""The probe's ratio :math:`\min(\Delta_-, \Delta_+) / 9\,\boldsymbol\delta^\top\mathbf I\,\boldsymbol\delta`
    and :func:`curvature_reason`'s finding from the same five costs.

    The ratio is 1 where the covariance describes the likelihood, above 1
    in a curved valley and below it in a flat one; on the paper's
    initiation windows it is 1.1–2.0 in the well-observed scenarios and
    3.2 and more in the others (docs/concepts.md, "Where a Gaussian start
    is split").  The Gaussian trackers
    split their start by it (:attr:`GaussianSumSettings.split_ratio
    <fgdoppler.estimators.settings.GaussianSumSettings>`) before it is far
    enough from 1 to be a finding.  Away from an optimum (``at_optimum``
    false) a ratio below 1 says nothing (the Gauss–Newton model's missing
    second-order terms lower it by themselves, :func:`curvature_reason`),
    so it is returned as 1 there: only the curved side can be read.
    """
    lo, hi, quad, sd = probe_rises(cost, x, P, information)
    ratio = min(lo, hi) / quad
    if not at_optimum:
        ratio = max(ratio, 1.0)
    where = (f"{PROBE_SIGMAS:g} standard deviations ({distance_text(PROBE_SIGMAS * sd, km_decimals=2)}) along the position's "
             f"major axis raise the cost by {lo:.3g} and {hi:.3g} where its quadratic model predicts {quad:.3g}")
    if ratio > CURVATURE_LIMIT:
        return ratio, Reason(code="nonlinear", status="doubtful", message=(
            f"the likelihood is a curved valley, not the ellipsoid of the covariance: {where}; "
            "the covariance misstates the uncertainty (poor observability)"))
    if ratio < 1.0 / CURVATURE_LIMIT:  # never away from an optimum: the ratio is at least 1 there
        return ratio, Reason(code="nonlinear", status="doubtful", message=(
            f"the likelihood is flatter than the covariance says: {where}; the uncertainty is larger than stated"))
    return ratio, None
