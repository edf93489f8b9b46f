r"""The detectable zone: where a track may start, in the geometry's own frame.

The paper draws its initiation candidates "uniformly within the detectable
zone" (Section 3) — for its geometries the box x 2–48 km, y ±5 km, speed up
to 200 m/s.  Here the zone belongs to the geometry: a box in the sensors'
frame (:func:`fgdoppler.frames.sensor_frame`) and a speed bound, so that a
rigid motion of the sensors moves the zone with them.

Default rule (:func:`default_zone`), with :math:`(u_i, v_i)` the distinct
sensors in the sensor frame and :math:`D = \max u_i - \min u_i` their extent
along its first axis (the first pair's baseline, unless that pair is
monostatic or nearly so: :func:`fgdoppler.frames.sensor_frame`):

.. math::

    u \in \big[\min u_i + D/25,\ \max u_i - D/25\big], \qquad
    v \in \big[\min(-D/10,\ \min v_i - D/25),\ \max(D/10,\ \max v_i + D/25)\big],

speed at most 200 m/s, and for a 3-D problem (see
:attr:`fgdoppler.geometry.Geometry.dim`) heights :math:`w` above the
sensors' plane in :math:`[0, D/4]` (0–12.5 km for a 50 km baseline).  In words: the stretch between the end sensors, less
the 4 % next to them (where the paper's zone stops 2 km short of a 50 km
baseline), and 10 % of the extent either side of the first baseline, widened
to reach 4 % beyond every sensor off it.  For the paper's two geometries this
is exactly the paper's box.

The zone is used three ways: the candidate grid of the initiation is laid
out in it (:mod:`fgdoppler.estimators.grid`), the region wall keeps the
initiation's start inside it (:func:`fgdoppler.factors.region_factor`), and
the weak prior spans it (:meth:`Zone.prior`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.frames import Frame

__all__ = ["DEFAULT_SPEED_MAX", "Zone", "ZoneBox", "ZoneLimits", "default_zone"]

FloatArray = NDArray[np.float64]

#: The paper's maximum target speed (m/s).
DEFAULT_SPEED_MAX = 200.0


def _interval(value: object, name: str) -> tuple[float, float]:
    items = list(value) if isinstance(value, list | tuple | np.ndarray) else None
    if items is None or len(items) != 2 or not all(
            isinstance(v, int | float | np.floating | np.integer) and not isinstance(v, bool) for v in items):
        raise ValueError(f"zone {name} must be two numbers [low, high] in metres, got {value!r}")
    lo, hi = float(items[0]), float(items[1])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"zone {name} must be finite, got [{lo}, {hi}]")
    if not lo < hi:
        raise ValueError(f"zone {name} is empty or inverted: [{lo:g}, {hi:g}] needs low < high")
    return lo, hi


def _speed_max(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer) or not (
            math.isfinite(value) and value > 0):
        raise ValueError(f"zone speed_max must be a positive number of m/s, got {value!r}")
    return float(value)


def _check_bounds(box: Zone | ZoneBox) -> None:
    """Validate and normalise a frozen zone's (or box's) intervals and speed bound in place."""
    object.__setattr__(box, "along", _interval(box.along, "along"))
    object.__setattr__(box, "across", _interval(box.across, "across"))
    if box.altitude is not None:
        object.__setattr__(box, "altitude", _interval(box.altitude, "altitude"))
    object.__setattr__(box, "speed_max", _speed_max(box.speed_max))


@dataclass(frozen=True, kw_only=True)
class ZoneBox:
    """A zone's box and speed bound in its own axes, without its frame: what ``--zone``, ``--altitude`` and
    ``--speed-max`` give.

    The zone a finding advises (:attr:`~fgdoppler.estimators.verdict.Reason.zone`) is one: its numbers are
    those of the command-line options that give it (:meth:`options`), in the axes of the zone the user
    gave (the geometry's frame for the default one), so it stays the same whatever frame the estimator ran in.

    Parameters
    ----------
    along, across, speed_max, altitude
        As :class:`Zone`'s.

    Raises
    ------
    ValueError
        As :class:`Zone`.
    """

    along: tuple[float, float]
    across: tuple[float, float]
    speed_max: float
    altitude: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        _check_bounds(self)

    def options(self) -> str:
        """The command-line options that give this box (``--zone``, ``--altitude``, ``--speed-max``), its bounds
        rounded outward to the metre and the speed up to the m/s."""
        def box(iv: tuple[float, float]) -> str:
            return f"{math.floor(iv[0])} {math.ceil(iv[1])}"
        alt = "" if self.altitude is None else f" --altitude {box(self.altitude)}"
        return f"--zone {box(self.along)} {box(self.across)}{alt} --speed-max {math.ceil(self.speed_max)}"

    def union(self, other: ZoneBox) -> ZoneBox:
        """The smallest box holding both, with the larger speed bound.

        Raises
        ------
        ValueError
            If one box has an altitude band and the other not.
        """
        if (self.altitude is None) != (other.altitude is None):
            raise ValueError("cannot join a 2-D zone box with a 3-D one")

        def hull(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
            return min(a[0], b[0]), max(a[1], b[1])
        return ZoneBox(along=hull(self.along, other.along), across=hull(self.across, other.across),
                       speed_max=max(self.speed_max, other.speed_max),
                       altitude=None if self.altitude is None or other.altitude is None
                       else hull(self.altitude, other.altitude))

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form, with the options that give it."""
        out: dict[str, object] = {"along": list(self.along), "across": list(self.across),
                                  "speed_max": self.speed_max}
        if self.altitude is not None:
            out["altitude"] = list(self.altitude)
        out["options"] = self.options()
        return out


@dataclass(frozen=True, kw_only=True)
class Zone:
    """A box in a frame and a speed bound: where a track may start.

    Parameters
    ----------
    frame
        The frame the box is given in (default: world coordinates).
    along, across
        ``(low, high)`` of the first and second local coordinate, metres.
    speed_max
        Largest target speed, m/s.
    altitude
        ``(low, high)`` of the third local coordinate (height above the
        sensors' plane, metres) for a 3-D zone; ``None`` for a 2-D one.  The
        frame's dimension must match (3 with an altitude band, 2 without).

    Raises
    ------
    ValueError
        If an interval is empty, inverted or not finite, or ``speed_max``
        is not a positive finite number.
    """

    frame: Frame = field(default_factory=Frame.identity)
    along: tuple[float, float]
    across: tuple[float, float]
    speed_max: float = DEFAULT_SPEED_MAX
    altitude: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        _check_bounds(self)
        if self.frame.dim != self.dim:
            raise ValueError(f"a {self.dim}-D zone (altitude band {'set' if self.altitude else 'not set'}) "
                             f"needs a {self.dim}-D frame, got {self.frame.dim}-D")

    @property
    def dim(self) -> int:
        """Spatial dimension: 3 with an altitude band, else 2."""
        return 2 if self.altitude is None else 3

    @property
    def intervals(self) -> tuple[tuple[float, float], ...]:
        """``(low, high)`` per local axis: along, across and (3-D) altitude."""
        return (self.along, self.across) if self.altitude is None else (self.along, self.across, self.altitude)

    @property
    def extents(self) -> tuple[float, ...]:
        """Side lengths of the box (m), one per local axis."""
        return tuple(hi - lo for lo, hi in self.intervals)

    @property
    def area(self) -> float:
        """Horizontal area of the box (m²), along × across."""
        return (self.along[1] - self.along[0]) * (self.across[1] - self.across[0])

    def corners(self) -> FloatArray:
        """The box's corners in world coordinates, ``(4, d)``, in order around it (3-D: on its floor)."""
        (a0, a1), (c0, c1) = self.along, self.across
        local = np.array([[a0, c0], [a1, c0], [a1, c1], [a0, c1]])
        if self.altitude is not None:
            local = np.column_stack([local, np.full(4, self.altitude[0])])
        return self.frame.points_to_world(local)

    def _check_states(self, states: ArrayLike) -> FloatArray:
        x = np.asarray(states, dtype=float)
        if x.ndim == 0 or x.shape[-1] != 2 * self.dim:
            raise ValueError(f"a {self.dim}-D zone takes states (..., {2 * self.dim}), got shape {x.shape}")
        return x

    def contains(self, states: ArrayLike, *, tol: float = 0.0) -> NDArray[np.bool_]:
        """Whether each state ``(..., 2d)`` starts in the zone (position in the box, speed below the bound)."""
        x = self._check_states(states)
        d = self.dim
        u = self.frame.points_to_local(x[..., :d])
        speed = np.linalg.norm(x[..., d:], axis=-1)
        inside = speed <= self.speed_max + tol
        for i, (lo, hi) in enumerate(self.intervals):
            inside &= (u[..., i] >= lo - tol) & (u[..., i] <= hi + tol)
        return inside

    def excess(self, state: ArrayLike) -> tuple[FloatArray, FloatArray]:
        r"""How far a state lies outside the zone, and the Jacobian of that.

        With :math:`\mathbf u = \mathbf B(\mathbf p - \mathbf o)` the local position
        (components :math:`u_i`, box :math:`[l_i, h_i]`),

        .. math::

            e_i(\mathbf x) = \min(0, u_i - l_i) + \max(0, u_i - h_i)\quad (i < d),\qquad
            e_d(\mathbf x) = \max(0, \lVert \mathbf v \rVert - s_{max}),

        zero inside, continuous and piecewise linear in position.  The
        Jacobian rows of the position terms are the local axes.  ``d + 1``
        rows for a ``d``-dimensional zone.
        """
        # Plain floats: this runs at every Levenberg-Marquardt step of the initiation as the zone wall's Python
        # callback (a third of a constant-velocity window's refinement), where numpy's per-call overhead would
        # be most of the cost.  Inside the zone, the common case, nothing but the tests is computed.
        d = self.dim
        x = np.asarray(state, dtype=float).reshape(-1).tolist()
        if len(x) != 2 * d:
            raise ValueError(f"a {d}-D zone takes a state of {2 * d} numbers, got {len(x)}")
        e = np.zeros(d + 1)
        J = np.zeros((d + 1, 2 * d))
        origin = self.frame.origin
        rel = [x[i] - origin[i] for i in range(d)]
        for i, ((lo, hi), row) in enumerate(zip(self.intervals, self.frame.basis, strict=True)):
            v = 0.0
            for k in range(d):
                v += row[k] * rel[k]
            if v < lo or v > hi:
                e[i] = v - lo if v < lo else v - hi
                J[i, :d] = row
        vel = x[d:]
        speed = math.hypot(*vel)
        if speed > self.speed_max:
            e[d] = speed - self.speed_max
            J[d, d:] = [c / speed for c in vel]
        return e, J

    def excess_text(self, state: ArrayLike) -> str:
        """:meth:`excess` of ``state`` in a finding's words, each number named by its axis
        (``"excess along, across, speed: 0, 1.2e+03, 0"``; 3-D adds ``altitude``)."""
        excess, _ = self.excess(state)
        axes = "along, across, altitude" if self.dim == 3 else "along, across"
        return f"excess {axes}, speed: " + ", ".join(f"{v:.3g}" for v in excess)

    def prior(self) -> tuple[FloatArray, FloatArray]:
        """Mean and covariance of the weak Gaussian prior spanning the zone.

        Centre of the box with zero velocity; standard deviations equal to
        the box half-widths (at least 1 m) along the local axes and
        ``speed_max`` per velocity axis.
        """
        d = self.dim
        centre = self.frame.points_to_world([(lo + hi) / 2 for lo, hi in self.intervals])
        half = np.array([(hi - lo) / 2 for lo, hi in self.intervals])
        cov = np.diag(np.concatenate([np.maximum(half, 1.0) ** 2, np.full(d, max(self.speed_max, 1.0) ** 2)]))
        return np.concatenate([centre, np.zeros(d)]), self.frame.covariances_to_world(cov)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form (the frame included)."""
        out: dict[str, object] = {"along": list(self.along), "across": list(self.across),
                                  "speed_max": self.speed_max}
        if self.altitude is not None:
            out["altitude"] = list(self.altitude)
        out["frame"] = self.frame.to_dict()
        return out

    def reaching(self, state: ArrayLike, margin: float = 0.25) -> Zone:
        r"""The zone widened just enough to hold the start ``state`` ``(2d,)``, with a margin.

        On each local axis whose interval :math:`[l_i, h_i]` misses the
        start's coordinate :math:`u_i`, the near bound moves past it by
        ``margin`` :math:`m` times the start's distance from the far bound
        (:math:`h_i' = u_i + m(u_i - l_i)` above,
        :math:`l_i' = u_i - m(h_i - u_i)` below); a speed bound below
        the start's speed :math:`s` becomes :math:`(1 + m)s`.  Everything
        the zone held it still holds.
        """
        x = self._check_states(state).reshape(-1)
        d = self.dim
        u = self.frame.points_to_local(x[:d])
        bounds = []
        for ui, (lo, hi) in zip(u, self.intervals, strict=True):
            if ui > hi:
                hi = ui + margin * (ui - lo)
            elif ui < lo:
                lo = ui - margin * (hi - ui)
            bounds.append((float(lo), float(hi)))
        speed = float(np.linalg.norm(x[d:]))
        return replace(self, along=bounds[0], across=bounds[1], altitude=bounds[2] if d == 3 else None,
                       speed_max=(1.0 + margin) * speed if speed > self.speed_max else self.speed_max)

    def box(self) -> ZoneBox:
        """The box and speed bound in the zone's own axes, without its frame."""
        return ZoneBox(along=self.along, across=self.across, speed_max=self.speed_max, altitude=self.altitude)

    def options(self) -> str:
        """The command-line options that give this zone (``--zone``, ``--altitude``, ``--speed-max``), its
        bounds rounded outward to the metre and the speed up to the m/s (:meth:`ZoneBox.options`)."""
        return self.box().options()

    def relative_to(self, frame: Frame) -> Zone:
        """The same zone with its frame expressed in ``frame``'s local coordinates."""
        return replace(self, frame=self.frame.relative_to(frame))

    def distance_to(self, points: ArrayLike) -> float:
        """Smallest distance (m) from the box to any of the world ``points`` (0 if one is inside)."""
        u = self.frame.points_to_local(np.asarray(points, dtype=float).reshape(-1, self.dim))
        lo = np.array([iv[0] for iv in self.intervals])
        hi = np.array([iv[1] for iv in self.intervals])
        return float(np.min(np.linalg.norm(np.maximum(0.0, np.maximum(lo - u, u - hi)), axis=1)))


@dataclass(frozen=True, kw_only=True)
class ZoneLimits:
    """A user's overrides of the default zone, in the geometry's frame (``None``: keep the rule's value).

    Parameters
    ----------
    along : tuple of float or None, default None
        ``(low, high)`` along the first pair's baseline (m).
    across : tuple of float or None, default None
        ``(low, high)`` across it (m).
    speed_max : float or None, default None
        Largest target speed (m/s).
    altitude : tuple of float or None, default None
        ``(low, high)`` height above the sensors' plane (m).  Setting it makes
        the problem 3-D (:attr:`fgdoppler.geometry.Geometry.dim`).
    """

    along: tuple[float, float] | None = None
    across: tuple[float, float] | None = None
    speed_max: float | None = None
    altitude: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.along is not None:
            object.__setattr__(self, "along", _interval(self.along, "along"))
        if self.across is not None:
            object.__setattr__(self, "across", _interval(self.across, "across"))
        if self.altitude is not None:
            object.__setattr__(self, "altitude", _interval(self.altitude, "altitude"))
        sm = self.speed_max
        if sm is not None and (isinstance(sm, bool) or not isinstance(sm, int | float)
                               or not (math.isfinite(sm) and sm > 0)):
            raise ValueError(f"zone speed_max must be a positive number of m/s, got {sm!r}")

    @property
    def empty(self) -> bool:
        """True if nothing is overridden."""
        return self.along is None and self.across is None and self.speed_max is None and self.altitude is None

    def apply(self, zone: Zone) -> Zone:
        """``zone`` with these overrides."""
        if self.altitude is not None and zone.altitude is None:
            raise ValueError("an altitude band needs a 3-D zone (build the zone from a geometry with these limits)")
        return replace(zone, along=self.along or zone.along, across=self.across or zone.across,
                       altitude=self.altitude or zone.altitude,
                       speed_max=zone.speed_max if self.speed_max is None else float(self.speed_max))

    def merged(self, other: ZoneLimits) -> ZoneLimits:
        """These limits with ``other``'s set values on top (e.g. command-line options over a TOML table)."""
        return ZoneLimits(along=other.along or self.along, across=other.across or self.across,
                          speed_max=self.speed_max if other.speed_max is None else other.speed_max,
                          altitude=other.altitude or self.altitude)

    def to_dict(self) -> dict[str, object]:
        """The set values only (the TOML ``[zone]`` table)."""
        d: dict[str, object] = {}
        if self.along is not None:
            d["along"] = list(self.along)
        if self.across is not None:
            d["across"] = list(self.across)
        if self.speed_max is not None:
            d["speed_max"] = float(self.speed_max)
        if self.altitude is not None:
            d["altitude"] = list(self.altitude)
        return d


def default_zone(frame: Frame, tx: ArrayLike, rx: ArrayLike, *, speed_max: float = DEFAULT_SPEED_MAX) -> Zone:
    """The default zone of a set of pairs in their frame (rule in the module docstring)."""
    sensors = np.unique(np.vstack([np.asarray(tx, dtype=float), np.asarray(rx, dtype=float)]), axis=0)
    local = frame.points_to_local(sensors)
    u_min, u_max = float(local[:, 0].min()), float(local[:, 0].max())
    v_min, v_max = float(local[:, 1].min()), float(local[:, 1].max())
    D = u_max - u_min
    return Zone(frame=frame, along=(u_min + D / 25, u_max - D / 25),
                across=(min(-D / 10, v_min - D / 25), max(D / 10, v_max + D / 25)), speed_max=speed_max,
                altitude=(0.0, D / 4) if frame.dim == 3 else None)
