r"""Which side of a line of sensors a 2-D track is on, and how many measurements settle it.

A pair whose Tx and Rx lie on a line sees a track and its mirror image
across that line with the same Doppler (:func:`~fgdoppler.geometry.reflected`).
Where the sensors of every reporting pair lie on one line nothing settles the
side (the judge's ``data`` finding).  Where all but a few measurements come
from pairs on one line, those few alone settle it, and one wrong value among
them — a dead receiver's 0, an outlier — can put the track on the wrong
side, kilometres off, while it fits every other measurement exactly as well
as the right side does.

:func:`side_margins` measures, for every line through the sensors of a
reporting pair, what the measurements of the pairs off it say for the
track's side: with :math:`r_i` the whitened residual of measurement
:math:`i` about the track and :math:`r'_i` about its mirror image,

.. math:: \delta_i = \rho(r'_i) - \rho(r_i), \qquad
          \rho(r) = \min(r^2, c^2), \qquad
          M = \sum_{i\ \text{off the line}} \delta_i, \qquad
          M_{-1} = M - \max(0, \max_i \delta_i),

with :math:`c` the robust initiation's outlier cut (one gross error weighs
at most :math:`c^2` either way).  :math:`M` is how much worse the mirror
image explains the data (the measurements of the pairs on the line add
nothing to it), :math:`M_{-1}` the same without the one measurement that
favours the track's side most.  :func:`side_reason` gives a ``competing``
finding where :math:`M_{-1}` is below
:data:`~fgdoppler.estimators.ambiguity.COMPETING` (:math:`\chi^2_1` at 95 %):
then the side rests on a single measurement, and where :math:`M < 0` the
mirror image explains the data better than the track itself.

The mirror image is not refitted: the best track on that side fits at least
as well as the image, so :math:`M` bounds the cost difference from above and
the finding errs towards silence.  In 3-D every rotation about such a line
keeps those pairs' Doppler, a family this module does not search.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from fgdoppler._text import distance_text, pairs_text, time_text
from fgdoppler.estimators.ambiguity import COMPETING
from fgdoppler.estimators.initiation import OUTLIER_CUT, whitened_residuals
from fgdoppler.estimators.verdict import Reason
from fgdoppler.geometry import Geometry, pair_labels, reflected
from fgdoppler.measurements import Measurements
from fgdoppler.models.observation import DopplerModel
from fgdoppler.models.tracking import TrackingModel

__all__ = ["ON_LINE", "SideMargin", "sensor_lines", "side_margins", "side_reason"]

FloatArray = NDArray[np.float64]

#: A sensor lies on a line when its distance from it is at most this share of the sensors' extent (the judge's
#: one-line `data` finding takes the same share of their spread along the line).
ON_LINE = 1e-9


@dataclass(frozen=True, kw_only=True)
class SideMargin:
    """What the measurements off one line of sensors say for a track's side of it (module docstring).

    Parameters
    ----------
    on
        The reporting pairs whose Tx and Rx lie on the line.
    point, direction
        A point of the line and its unit direction (m, 2-D).
    off
        How many measurements come from the other pairs.
    margin
        :math:`M`: how much worse the track's mirror image explains the data (negative: better).
    robust_margin
        :math:`M_{-1}`: the same without the measurement that favours the track's side most.
    deciding
        Row (in the measurements) of that measurement.
    distance
        How far the track's last position is from its mirror image (m).
    """

    on: tuple[int, ...]
    point: FloatArray
    direction: FloatArray
    off: int
    margin: float
    robust_margin: float
    deciding: int
    distance: float


def sensor_lines(geometry: Geometry, used: NDArray[np.int64]
                 ) -> list[tuple[FloatArray, FloatArray, tuple[int, ...]]]:
    """Every line that holds both sensors of one of the ``used`` pairs or more: ``(point, unit direction,
    pairs on it)``, once per set of pairs — each bistatic pair's baseline, and the line through two radars.
    2-D geometries only (the first two coordinates are read)."""
    tx, rx = geometry.tx[:, :2], geometry.rx[:, :2]
    tol = ON_LINE * max(geometry.extent, 1.0)
    radar = np.linalg.norm(rx[used] - tx[used], axis=1) <= tol
    candidates = [(tx[p], rx[p] - tx[p]) for p in used[~radar]]
    candidates += [(tx[a], tx[b] - tx[a]) for a, b in combinations(used[radar], 2)
                   if np.linalg.norm(tx[b] - tx[a]) > tol]
    out: list[tuple[FloatArray, FloatArray, tuple[int, ...]]] = []
    seen: set[tuple[int, ...]] = set()
    for c, d in candidates:
        u = d / np.linalg.norm(d)
        n = np.array([-u[1], u[0]])
        on_line = (np.abs((tx[used] - c) @ n) <= tol) & (np.abs((rx[used] - c) @ n) <= tol)
        on = tuple(int(p) for p in used[on_line])
        if on not in seen:
            seen.add(on)
            out.append((c, u, on))
    return out


def side_margins(measurements: Measurements, model: TrackingModel, states: FloatArray) -> list[SideMargin]:
    """:class:`SideMargin` of every line of :func:`sensor_lines` with measurements off it.

    ``states`` ``(n_scans, 4)`` holds the track's state at every scan of ``measurements``.
    """
    if not isinstance(model.observation, DopplerModel):
        return []
    used = np.unique(measurements.pair)
    at_scan = states[measurements.scans().scan_of]
    cut2 = OUTLIER_CUT**2
    base = np.minimum(whitened_residuals(model, measurements, at_scan) ** 2, cut2)
    out = []
    for c, u, on in sensor_lines(model.observation.geometry, used):
        off = ~np.isin(measurements.pair, on)
        if not off.any():
            continue
        image = reflected(at_scan[off], c, u)
        delta = np.minimum(whitened_residuals(model, measurements.subset(off), image) ** 2, cut2) - base[off]
        top = int(np.argmax(delta))
        margin = float(delta.sum())
        out.append(SideMargin(
            on=on, point=c, direction=u, off=int(off.sum()), margin=margin,
            robust_margin=margin - max(float(delta[top]), 0.0), deciding=int(np.flatnonzero(off)[top]),
            distance=float(np.linalg.norm(reflected(states[-1:], c, u)[0, :2] - states[-1, :2]))))
    return out


def side_reason(measurements: Measurements, model: TrackingModel, states: FloatArray) -> Reason | None:
    """A ``doubtful`` ``competing`` finding where a single measurement, or none, settles the track's side of a
    line of sensors (the line of :func:`side_margins` with the smallest :math:`M_{-1}`, where it is below
    :data:`~fgdoppler.estimators.ambiguity.COMPETING`); ``None`` otherwise.  It carries ``mirror="pairs"``
    and the pairs on that line (the command line prints the ``--half-plane`` options of either side)."""
    margins = side_margins(measurements, model, states)
    if not margins:
        return None
    worst = min(margins, key=lambda s: s.robust_margin)
    if worst.robust_margin >= COMPETING:
        return None
    label = pair_labels(model.observation)
    on = pairs_text(worst.on, label)
    off = pairs_text([int(p) for p in np.unique(measurements.pair[~np.isin(measurements.pair, worst.on)])], label)
    image = (f"the track's mirror image across the line of the sensors of {on}, {distance_text(worst.distance)} away "
             f"at the end, fits every measurement of {'that pair' if len(worst.on) == 1 else 'those pairs'} "
             "exactly as well")
    many = f"{worst.off} measurement{'s' if worst.off > 1 else ''} of {off}"
    if worst.margin < 0.0:
        said = (f"{image}, and the {many} favour it: it explains the data better (cost lower by "
                f"{-worst.margin:.2f}), so the track is likely on the wrong side")
    elif worst.margin < COMPETING:
        said = (f"{image}, and the {many} barely tell the two apart (cost higher by only {worst.margin:.2f} < "
                f"{COMPETING:.2f}): the data do not settle the track's side")
    else:
        k = worst.deciding
        at = f"at t = {time_text(float(measurements.time[k]))} s"
        apart = (f"only the one measurement of {off}, {at}, tells the two apart: without it" if worst.off == 1 else
                 f"only the {many} tell the two apart: without the one that favours this side most (pair "
                 f"{label(int(measurements.pair[k]))} {at})")
        said = (f"{image}, and {apart} the image explains the data about as well (cost higher by only "
                f"{max(worst.robust_margin, 0.0):.2f} < {COMPETING:.2f}; {worst.margin:.2f} with it), so one wrong "
                "value there puts the track on the wrong side")
    return Reason(code="competing", status="doubtful", message=(
        f"{said} (check {'that measurement' if worst.off == 1 else 'those measurements'}; if the target's side "
        "of that line is known, give it with --half-plane)"), mirror="pairs", pairs=worst.on)
