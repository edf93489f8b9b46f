r"""Observability: the paper's measure, its maps and speed table, and a marginal-covariance report.

The paper (Section 4) quantifies observability of an initial state by

.. math:: O(\mathbf x_0) = \log_{10}\det\big(\mathbf J(\mathbf x_0)'\mathbf J(\mathbf x_0)\big),

with :math:`\mathbf J` the batch Jacobian of Eq. 15 (unit noise), floored at
:math:`-40` where :math:`\det \le 10^{-40}` (then :math:`\mathbf x_0` counts as
unobservable).  :math:`\det(\mathbf J'\mathbf J)` is evaluated as the product
of the squared singular values of :math:`\mathbf J`, which is accurate where
forming :math:`\mathbf J'\mathbf J` first would square the condition number.

Sampling pattern of the study
    The paper does not state the measurement batch behind its maps and
    Table 2.  A search over samples per pair (2–40) and intervals (0.01–2 s)
    finds that **two synchronous samples per pair, 1 s apart** (a square 4×4
    Jacobian, the minimal batch) with the evaluation points at y = +2 km
    reproduces Table 2's maxima to 0.05 and minima to 1.0 at all four speeds
    (see ``studies/table2_speed.py``); :data:`TABLE2_SAMPLING` holds it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.grid import grid_states
from fgdoppler.estimators.marginals import marginal_covariances
from fgdoppler.factors import X
from fgdoppler.geometry import Geometry, ellipse_tangent, paper_geometry
from fgdoppler.graphs import chain_graph, chain_values, cv_graph
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import StackedTimes, cv_doppler_jacobian
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import DopplerModel
from fgdoppler.simulation import Trajectory

__all__ = [
    "DEFAULT_HEADINGS_DEG",
    "DEFAULT_X",
    "O_FLOOR",
    "PAPER_GROUPS",
    "PAPER_TABLE2",
    "TABLE2_SAMPLING",
    "ObservabilityMap",
    "ObservabilityReport",
    "SamplingPattern",
    "SpeedTable",
    "default_along",
    "geometry_speed_table",
    "log10_det_information",
    "observability_map",
    "observability_measure",
    "observability_report",
    "speed_table",
]

FloatArray = NDArray[np.float64]

#: The paper's floor: O = -40 marks an unobservable state.
O_FLOOR = -40.0
#: Initial x grid of the paper's maps: 1–49 km every 500 m (97 points).
DEFAULT_X: FloatArray = np.arange(1e3, 49e3 + 1.0, 500.0)
#: Heading grid of the paper's maps: 0–350° every 10° (36 values).
DEFAULT_HEADINGS_DEG: FloatArray = np.arange(0.0, 360.0, 10.0)

#: The paper's evaluation groups (Fig. 3): group -> (geometry case, y offset in m).
PAPER_GROUPS: dict[int, tuple[str, float]] = {1: ("a", 0.0), 2: ("a", 2e3), 3: ("b", 0.0), 4: ("b", 2e3)}

#: Table 2 of the paper: group -> speed (m/s) -> (max O, min O).
PAPER_TABLE2: dict[int, dict[float, tuple[float, float]]] = {
    2: {100.0: (-10.8, -34.9), 75.0: (-11.9, -34.9), 50.0: (-13.3, -36.3), 25.0: (-15.7, -38.0)},
    4: {100.0: (-10.8, -34.9), 75.0: (-11.9, -34.9), 50.0: (-13.3, -36.5), 25.0: (-15.7, -38.1)},
}


@dataclass(frozen=True, kw_only=True)
class SamplingPattern:
    """Measurement times of an observability study (the paper's "batch").

    Pair ``i`` measures at ``offsets[i] + k * interval`` for
    ``k = 0 .. samples_per_pair - 1`` (times relative to :math:`\\mathbf x_0`).
    """

    samples_per_pair: int = 2
    interval: float = 1.0
    offsets: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.samples_per_pair < 1:
            raise ValueError(f"samples_per_pair must be >= 1, got {self.samples_per_pair}")
        if not (self.interval > 0 and np.isfinite(self.interval)):
            raise ValueError(f"interval must be > 0, got {self.interval}")
        if self.offsets is not None and not all(np.isfinite(o) for o in self.offsets):
            raise ValueError(f"offsets must be finite, got {self.offsets}")

    def times(self, n_pairs: int) -> list[FloatArray]:
        """One array of times per pair."""
        offs = (0.0,) * n_pairs if self.offsets is None else self.offsets
        if len(offs) != n_pairs:
            raise ValueError(f"{len(offs)} offsets for {n_pairs} pairs")
        k = np.arange(self.samples_per_pair, dtype=float) * self.interval
        return [np.asarray(o + k, dtype=float) for o in offs]

    def describe(self) -> str:
        """Human-readable summary."""
        off = "synchronous" if not self.offsets or not any(self.offsets) else f"offsets {self.offsets} s"
        return f"{self.samples_per_pair} samples per pair every {self.interval:g} s ({off})"


#: The sampling that reproduces the paper's Table 2 (module docstring).
TABLE2_SAMPLING = SamplingPattern(samples_per_pair=2, interval=1.0)


def log10_det_information(J: ArrayLike, *, floor: float = O_FLOOR) -> FloatArray:
    r""":math:`\log_{10}\det(\mathbf J'\mathbf J)` from the singular values of :math:`\mathbf J`, floored.

    Parameters
    ----------
    J
        Jacobians, shape ``(..., n_Z, 4)``.
    floor
        Returned where :math:`\det \le 10^{\text{floor}}` (including exact zero
        and fewer rows than columns).
    """
    J = np.asarray(J, dtype=float)
    if J.shape[-2] < J.shape[-1]:
        return np.full(J.shape[:-2], floor)
    s = np.linalg.svd(J, compute_uv=False)
    with np.errstate(divide="ignore"):
        logdet = 2.0 * np.sum(np.log10(s), axis=-1)
    return np.where(np.isfinite(logdet) & (logdet > floor), logdet, floor)


def observability_measure(
    x0: ArrayLike, geometry: Geometry, times: Sequence[ArrayLike] | StackedTimes
) -> float | FloatArray:
    r"""The paper's observability measure :math:`O(\mathbf x_0)` (Eq. 18).

    Parameters
    ----------
    x0
        Initial state(s) ``[x, y, vx, vy]`` ``(..., 4)``, or ``[x, y, z, vx, vy, vz]``
        ``(..., 6)`` for a 3-D problem.
    geometry
        Sensor pairs.
    times
        One array of measurement times per pair, relative to the time of ``x0``.

    Returns
    -------
    float or ndarray of shape ``(...)``
        :math:`\log_{10}\det(\mathbf J'\mathbf J)` with unit noise, floored at −40.
        A 3-D value is the determinant of a 6×6 information (units m⁻⁶ s⁻⁶ …
        rather than m⁻⁴ s⁻⁴): compare 3-D values with 3-D values only.
    """
    O = log10_det_information(cv_doppler_jacobian(x0, geometry, times))
    return float(O) if O.ndim == 0 else O


def default_along(geometry: Geometry) -> FloatArray:
    """The map's default along-baseline grid: from :math:`D/50` to :math:`D - D/50` every :math:`D/100` in the sensors' frame.

    :math:`D` is the sensors' extent along the first pair's baseline; for the
    paper's geometries this is :data:`DEFAULT_X` (1–49 km every 500 m).
    """
    u = geometry.frame.points_to_local(geometry.sensors())[:, 0]
    lo, D = float(u.min()), float(np.ptp(u))
    return np.arange(lo + D / 50, lo + D - D / 50 + D / 1e6, D / 100)


@dataclass(frozen=True, kw_only=True)
class ObservabilityMap:
    """O over initial position × heading at a fixed offset and speed (paper Figs. 4–7).

    Positions and headings are in the geometry's own frame
    (:attr:`fgdoppler.geometry.Geometry.frame`): ``x`` along the first pair's
    baseline, ``y`` across it, heading clockwise from the across axis — the
    paper's x, y and heading for its geometries, whose frame is the identity.
    """

    geometry: Geometry
    x: FloatArray
    heading_deg: FloatArray
    y: float
    speed: float
    sampling: SamplingPattern
    O: FloatArray = field(repr=False)

    @property
    def unobservable(self) -> NDArray[np.bool_]:
        """Cells at the −40 floor."""
        return self.O <= O_FLOOR

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "geometry": self.geometry.name,
            "y": self.y,
            "speed": self.speed,
            "sampling": self.sampling.describe(),
            "x": self.x.tolist(),
            "heading_deg": self.heading_deg.tolist(),
            "O": self.O.tolist(),
            "max": float(self.O.max()),
            "min": float(self.O.min()),
        }


def observability_map(
    geometry: Geometry,
    *,
    y: float,
    speed: float = 100.0,
    x: ArrayLike | None = None,
    heading_deg: ArrayLike = DEFAULT_HEADINGS_DEG,
    sampling: SamplingPattern = TABLE2_SAMPLING,
    chunk: int = 20_000,
    progress: Callable[[int], None] | None = None,
) -> ObservabilityMap:
    """Evaluate O over an ``x × heading`` grid in the geometry's frame (vectorised, ``chunk`` states at a time).

    ``x`` defaults to :func:`default_along`.  ``progress``, if given, is
    called with the number of states done after each chunk (for progress bars).
    """
    xs = (default_along(geometry) if x is None else np.asarray(x, dtype=float)).reshape(-1)
    hs = np.asarray(heading_deg, dtype=float).reshape(-1)
    states = geometry.frame.states_to_world(grid_states(xs, y, speed, hs).reshape(-1, 4))
    times = StackedTimes.from_per_pair(sampling.times(geometry.n_pairs))
    out = np.empty(states.shape[0])
    for start in range(0, states.shape[0], chunk):
        sl = slice(start, start + chunk)
        out[sl] = log10_det_information(cv_doppler_jacobian(states[sl], geometry, times))
        if progress is not None:
            progress(min(chunk, states.shape[0] - start))
    return ObservabilityMap(
        geometry=geometry, x=xs, heading_deg=hs, y=float(y), speed=float(speed), sampling=sampling,
        O=out.reshape(xs.size, hs.size),
    )


@dataclass(frozen=True, kw_only=True)
class SpeedTable:
    """Max and min of O over each group's map at several speeds (paper Table 2).

    ``groups`` are the paper's group numbers, or a label for a geometry of
    one's own (:func:`geometry_speed_table`).
    """

    groups: tuple[int | str, ...]
    speeds: tuple[float, ...]
    sampling: SamplingPattern
    #: ``values[g][s] = (max, min)``
    values: dict[int | str, dict[float, tuple[float, float]]]

    def compare(self) -> list[dict[str, Any]]:
        """Rows with ours and the paper's values side by side (where the paper has them)."""
        rows = []
        for g in self.groups:
            for s in self.speeds:
                mx, mn = self.values[g][s]
                paper = PAPER_TABLE2.get(g, {}).get(s) if isinstance(g, int) else None
                rows.append({
                    "group": g, "speed": s, "max": mx, "min": mn,
                    "paper_max": None if paper is None else paper[0],
                    "paper_min": None if paper is None else paper[1],
                })
        return rows

    def to_markdown(self) -> str:
        """A Markdown table with the sampling used."""
        lines = [
            f"Sampling: {self.sampling.describe()}",
            "",
            "| group | speed (m/s) | max O | paper max | min O | paper min |",
            "|---|---|---|---|---|---|",
        ]
        for r in self.compare():
            pm = "—" if r["paper_max"] is None else f"{r['paper_max']:.1f}"
            pn = "—" if r["paper_min"] is None else f"{r['paper_min']:.1f}"
            lines.append(f"| {r['group']} | {r['speed']:g} | {r['max']:.2f} | {pm} | {r['min']:.2f} | {pn} |")
        return "\n".join(lines)


def speed_table(
    *,
    groups: Sequence[int] = (2, 4),
    speeds: Sequence[float] = (100.0, 75.0, 50.0, 25.0),
    sampling: SamplingPattern = TABLE2_SAMPLING,
    x: ArrayLike = DEFAULT_X,
    heading_deg: ArrayLike = DEFAULT_HEADINGS_DEG,
) -> SpeedTable:
    """The paper's Table 2 (max and min of O over each group's map per speed)."""
    values: dict[int | str, dict[float, tuple[float, float]]] = {}
    for g in groups:
        case, y = PAPER_GROUPS[g]
        values[g] = _speed_row(paper_geometry(case), y, speeds, sampling, x, heading_deg)
    return SpeedTable(groups=tuple(groups), speeds=tuple(float(s) for s in speeds), sampling=sampling, values=values)


def geometry_speed_table(
    geometry: Geometry,
    *,
    y: float,
    speeds: Sequence[float] = (100.0, 75.0, 50.0, 25.0),
    sampling: SamplingPattern = TABLE2_SAMPLING,
    x: ArrayLike | None = None,
    heading_deg: ArrayLike = DEFAULT_HEADINGS_DEG,
    label: str | None = None,
) -> SpeedTable:
    """Table 2 for a geometry of one's own: max and min of O over its map at offset ``y``, per speed."""
    name = label or geometry.name or "geometry"
    return SpeedTable(groups=(name,), speeds=tuple(float(s) for s in speeds), sampling=sampling,
                      values={name: _speed_row(geometry, y, speeds, sampling, x, heading_deg)})


def _speed_row(geometry: Geometry, y: float, speeds: Sequence[float], sampling: SamplingPattern,
               x: ArrayLike | None, heading_deg: ArrayLike) -> dict[float, tuple[float, float]]:
    row = {}
    for s in speeds:
        m = observability_map(geometry, y=y, speed=s, x=x, heading_deg=heading_deg, sampling=sampling)
        row[float(s)] = (float(m.O.max()), float(m.O.min()))
    return row


# -- the report -------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class ObservabilityReport:
    """Per-time accuracy achievable from a scenario, from the graph linearised at the truth.

    Attributes
    ----------
    times
        State times, shape ``(n,)``.
    status
        ``"ok"``, or ``"indeterminate"`` when the information matrix is
        singular (then the per-time arrays are ``None``).
    message
        Why it is indeterminate (empty when ok).
    pos_std, vel_std
        Standard deviations ``(n, d)`` of the position (m) and velocity (m/s) components.
    weakest_direction
        Unit vector ``(n, d)`` of the dominant eigenvector of the position covariance.
    weakest_std
        Standard deviation (m) along it, ``(n,)``.
    covariances
        Marginal covariances ``(n, 2d, 2d)``.
    O_x0
        The paper's measure over all measurement times (unit σ).
    cond_JtJ
        Condition number of :math:`\\mathbf J'\\mathbf J` (``inf`` if singular).
    tangent_angle_deg
        Angle in [0°, 90°] between the heading and each pair's bistatic
        ellipse tangent, ``(n, n_pairs)``; near 0° the motion follows the
        ellipse and that pair's Doppler carries little information.  In 3-D
        the angle between the velocity and each pair's ellipsoid tangent plane.
    """

    times: FloatArray
    status: str
    message: str
    O_x0: float
    cond_JtJ: float
    tangent_angle_deg: FloatArray
    pos_std: FloatArray | None = None
    vel_std: FloatArray | None = None
    weakest_direction: FloatArray | None = None
    weakest_std: FloatArray | None = None
    covariances: FloatArray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form (``cond_JtJ`` is ``null`` when infinite)."""
        def arr(a: FloatArray | None) -> object:
            return None if a is None else a.tolist()
        return {
            "status": self.status,
            "message": self.message,
            "O_x0": self.O_x0,
            "cond_JtJ": self.cond_JtJ if np.isfinite(self.cond_JtJ) else None,
            "times": self.times.tolist(),
            "pos_std": arr(self.pos_std),
            "vel_std": arr(self.vel_std),
            "weakest_direction": arr(self.weakest_direction),
            "weakest_std": arr(self.weakest_std),
            "tangent_angle_deg": self.tangent_angle_deg.tolist(),
        }


def _tangent_angles(states: FloatArray, geometry: Geometry) -> FloatArray:
    d = states.shape[1] // 2
    v = states[:, d:]
    if d == 3:  # angle to the tangent plane: 90° minus the angle to the gradient u_T + u_R
        tx, rx = geometry.positions(3)
        p = states[:, None, :3]
        grad = (p - tx) / np.linalg.norm(p - tx, axis=-1, keepdims=True) + \
            (p - rx) / np.linalg.norm(p - rx, axis=-1, keepdims=True)
        gn = np.linalg.norm(grad, axis=-1)
        speed = np.linalg.norm(v, axis=1)
        sin = np.abs(np.einsum("npk,nk->np", grad, v)) / np.maximum(gn * speed[:, None], 1e-300)
        return np.rad2deg(np.arcsin(np.clip(sin, 0.0, 1.0)))
    tangents = ellipse_tangent(states[:, :2], geometry)  # (n, n_pairs, 2)
    speed = np.linalg.norm(v, axis=1, keepdims=True)
    u = np.divide(v, speed, out=np.zeros_like(v), where=speed > 0)
    cosang = np.abs(np.einsum("npk,nk->np", tangents, u))
    return np.rad2deg(np.arccos(np.clip(cosang, 0.0, 1.0)))


def observability_report(
    geometry: Geometry,
    truth: Trajectory,
    measurements: Measurements,
    *,
    motion: ConstantVelocity | None = None,
    prior_covariance: ArrayLike | None = None,
) -> ObservabilityReport:
    """Linearise the Doppler factor graph at the truth and report marginal accuracies.

    Parameters
    ----------
    geometry
        Sensor pairs.
    truth
        True states at (at least) every measurement time; the report is
        given at the distinct measurement times.
    measurements
        Their times, pairs and sigmas are used (values are irrelevant: the
        graph is evaluated at the truth).
    motion
        ``None``: deterministic constant velocity — one state :math:`\\mathbf x_0`
        with the paper's constant-velocity window; per-time covariances are
        :math:`\\mathbf F(t)\\mathbf P_0\\mathbf F(t)'`.  Otherwise one state
        per measurement time with Doppler and motion factors.
    prior_covariance
        Optional Gaussian prior on the first state, centred on the truth.
    """
    measurements.check(geometry)
    times = measurements.scans().times
    states = truth.at(times)
    t0 = times[0]
    order = measurements.stacked_order()
    stacked = StackedTimes(pair=measurements.pair[order], t=measurements.time[order] - t0)
    J = cv_doppler_jacobian(states[0], geometry, stacked)
    n = J.shape[1]
    s = np.linalg.svd(J, compute_uv=False) if J.shape[0] >= n else np.zeros(n)
    O = float(log10_det_information(J))
    cond = float(s[0] ** 2 / s[-1] ** 2) if s[-1] > 0 else float("inf")
    angles = _tangent_angles(states, geometry)
    prior = None if prior_covariance is None else (states[0], prior_covariance)
    if motion is None:
        graph, _ = cv_graph(geometry, stacked, measurements.doppler[order], measurements.sigma[order], prior=prior)
        values, keys = chain_values(states[:1]), [X(0)]
    else:
        graph, _ = chain_graph(measurements, DopplerModel(geometry=geometry), motion, prior=prior)
        values, keys = chain_values(states), [X(k) for k in range(times.size)]
    res = marginal_covariances(graph, values, keys)
    common: dict[str, Any] = {"times": times, "O_x0": O, "cond_JtJ": cond, "tangent_angle_deg": angles}
    if not res.ok:
        return ObservabilityReport(status="indeterminate", message=res.message, **common)
    covs = res.covariances
    assert covs is not None
    if motion is None:
        F = ConstantVelocity(dim=states.shape[-1] // 2).F(times - t0)
        covs = F @ covs[0] @ np.swapaxes(F, -1, -2)
    d = states.shape[-1] // 2
    pos = covs[:, :d, :d]
    w, V = np.linalg.eigh(pos)
    direction = V[:, :, -1] * np.sign(V[:, 0:1, -1] + (V[:, 0:1, -1] == 0))
    return ObservabilityReport(
        status="ok",
        message="",
        pos_std=np.sqrt(np.diagonal(pos, axis1=1, axis2=2)),
        vel_std=np.sqrt(np.diagonal(covs[:, d:, d:], axis1=1, axis2=2)),
        weakest_direction=direction,
        weakest_std=np.sqrt(np.clip(w[:, -1], 0.0, None)),
        covariances=covs,
        **common,
    )
