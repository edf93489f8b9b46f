r"""Sensor errors drawn afresh for every simulated run: calibration offsets and site displacements.

A :class:`~fgdoppler.simulation.Scenario` holds *fixed* sensor errors
(``bias``, ``site_error``): every run of a Monte Carlo study then shares
them, and its NEES says how the trackers fare against that one
displacement.  Whether a declared uncertainty (the trackers' ``bias_sigma``,
``site_sigma``) is right *on average* needs the errors drawn from it, a new
draw each run — what :class:`ErrorDraws` adds to a scenario:

.. math::

    \mathbf b^{(r)} = \mathbf b + \boldsymbol\beta^{(r)},\quad \beta_p^{(r)} \sim N(0, \sigma_{b,p}^2);
    \qquad
    \boldsymbol\delta_s^{(r)} = \boldsymbol\delta_s + \boldsymbol\epsilon_s^{(r)},\quad
    \boldsymbol\epsilon_s^{(r)} \sim N(\mathbf 0, \sigma_{s}^2\mathbf I_d),

for each pair :math:`p` and each site :math:`s`
(:meth:`~fgdoppler.geometry.Geometry.sites`) in all :math:`d` coordinates,
:math:`\mathbf b` and :math:`\boldsymbol\delta_s` the scenario's own.  Clock
errors are not drawn: they move the times at which a run's truth is
reported, and a study's runs share one time grid.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fgdoppler.simulation import Scenario

__all__ = ["ErrorDraws"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class ErrorDraws:
    """Standard deviations of the sensor errors drawn for each run (module docstring).

    Parameters
    ----------
    bias_sigma : float or tuple of float, default 0
        Each pair's constant Doppler offset (m/s): one value or one per pair.
    site_sigma : float or tuple of float, default 0
        Each site's displacement in every coordinate (m): one value, or one
        per site in the order the pairs first name them
        (:meth:`~fgdoppler.geometry.Geometry.sites`).
    """

    bias_sigma: float | tuple[float, ...] = 0.0
    site_sigma: float | tuple[float, ...] = 0.0

    def __post_init__(self) -> None:
        for name, unit, each in (("bias_sigma", "m/s", "pair"), ("site_sigma", "m", "site")):
            value = getattr(self, name)
            v = np.asarray(value, dtype=float).reshape(-1)
            if v.size == 0 or not np.all(np.isfinite(v) & (v >= 0)):
                raise ValueError(f"{name} must be one value >= 0 ({unit}) or one per {each}, got {value!r}")
            object.__setattr__(self, name, float(v[0]) if np.ndim(value) == 0 else tuple(float(x) for x in v))

    def sigmas(self, scenario: Scenario) -> tuple[FloatArray, FloatArray]:
        """The standard deviations per pair (m/s) and per site (m) of ``scenario``'s geometry.

        Raises
        ------
        ValueError
            If a value count is neither one nor one per pair (per site).
        """
        from fgdoppler.estimators.calibration import per_pair_sigmas
        from fgdoppler.estimators.site_offsets import site_sigmas

        return (per_pair_sigmas(self.bias_sigma, scenario.geometry.n_pairs),
                site_sigmas(self.site_sigma, scenario.geometry))

    def applied(self, scenario: Scenario, rng: np.random.Generator) -> Scenario:
        """``scenario`` with one draw of the errors added to its own ``bias`` and ``site_error``.

        The site displacements are drawn first, ``(n_sites, dim)`` standard
        normals, then one per pair for the offsets: the same generator gives
        the same draws whichever standard deviations are zero.  A part whose
        standard deviations are all zero leaves the scenario's own as it is.
        """
        bias_sigma, site_sigma = self.sigmas(scenario)
        positions = scenario.geometry.sites()[0]
        eps = rng.standard_normal(positions.shape) * site_sigma[:, None]
        beta = rng.standard_normal(bias_sigma.size) * bias_sigma
        moves, shifts = bool(np.any(site_sigma > 0)), bool(np.any(bias_sigma > 0))
        if not (moves or shifts):
            return scenario
        return replace(scenario,
                       site_error=tuple(float(v) for v in (scenario.site_errors + eps).reshape(-1)) if moves
                       else scenario.site_error,
                       bias=tuple(float(v) for v in scenario.biases + beta) if shifts else scenario.bias)
