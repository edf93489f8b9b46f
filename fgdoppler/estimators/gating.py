r"""Measurement gating and robust weights, shared by every tracker.

The gate compares each measurement with the prediction of the state it is
about to update:

.. math::

    \mathrm{NIS}_j = \frac{(z_j - h_j(\mathbf x^-))^2}{\mathbf H_j\mathbf P^-\mathbf H_j' + \sigma_j^2},

and rejects it when :math:`\mathrm{NIS}_j` exceeds the χ²₁ quantile of the
gate probability.  Every value is logged; every rejection is an event.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fgdoppler.estimators.verdict import Event
from fgdoppler.models.observation import MeasurementModel

__all__ = ["NISGate"]

FloatArray = NDArray[np.float64]


class NISGate:
    """A χ²₁ gate on normalised innovations, with its log.

    Parameters
    ----------
    probability
        Gate probability; ``None`` accepts everything (the NIS is still logged).
    events
        Where rejections are reported (the tracker's event list).
    """

    def __init__(self, probability: float | None, events: list[Event]) -> None:
        self.threshold = float(chi2.ppf(probability, 1)) if probability is not None else math.inf
        self.events = events
        #: ``(time, channel, NIS, accepted)`` of every gated measurement.
        self.log: list[tuple[float, int, float, bool]] = []

    def accept(self, t: float, channel: int, nis: float) -> bool:
        """Log one measurement's NIS; True if it passes the gate."""
        ok = nis <= self.threshold
        self.log.append((t, channel, nis, ok))
        if not ok:
            self.events.append(Event(time=t, message=f"pair {channel}: NIS {nis:.1f} > gate {self.threshold:.1f}, "
                                                      "measurement rejected"))
        return ok

    def scan(self, model: MeasurementModel, x_pred: FloatArray, P_pred: FloatArray, t: float,
             channels: NDArray[np.intp], z: FloatArray, sigma: FloatArray) -> NDArray[np.bool_]:
        """Gate the measurements of one scan against a prediction; returns the mask of those kept."""
        n = x_pred.size
        h, H = model.predict_and_jacobian(np.broadcast_to(x_pred, (channels.size, n)), channels)
        nis = (z - h) ** 2 / (np.einsum("ij,jk,ik->i", H, P_pred, H) + sigma**2)
        return np.array([self.accept(t, int(c), float(v)) for c, v in zip(channels, nis, strict=True)], dtype=bool)

    def as_array(self) -> FloatArray:
        """The log as an ``(m, 4)`` array: time, channel, NIS, accepted (1/0)."""
        return np.array(self.log, dtype=float).reshape(-1, 4)
