"""Sensor geometry: bistatic Tx–Rx pairs, the paper's configurations, ellipse helpers.

A bistatic pair is a transmitter and a receiver at fixed positions in the
plane (metres).  The locus of points with a constant bistatic range
``r_T + r_R`` is the *bistatic ellipse* with foci at Tx and Rx; a target moving
along it produces zero bistatic Doppler, which is the paper's source of
unobservability (Section 4).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._text import distance_text
from fgdoppler.frames import AXIS_MIN_SHARE, SENSOR_EPS, Frame, sensor_frame
from fgdoppler.geodetic import GeodeticOrigin
from fgdoppler.zone import DEFAULT_SPEED_MAX, Zone, ZoneLimits, default_zone

__all__ = [
    "SPEED_OF_LIGHT",
    "WAVELENGTH_LIMITS",
    "BistaticPair",
    "Geometry",
    "bistatic_range",
    "ellipse_tangent",
    "is_mirror_image",
    "mirrored",
    "pair_labels",
    "paper_geometry",
    "principal_line",
    "reflected",
]

#: Lattice (m) the sensors are snapped to in their own frame (:meth:`Geometry.in_frame`).
SNAP = 1e-3


def _is_number(v: object) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool | np.bool_)


def _point(value: ArrayLike, name: str) -> tuple[float, ...]:
    items = value.tolist() if isinstance(value, np.ndarray) else value
    if not isinstance(items, list | tuple) or not all(_is_number(v) for v in items):
        raise ValueError(f"{name} must be two or three numbers (x, y[, z]) in metres, got {value!r}")
    arr = np.asarray(items, dtype=float)
    if arr.shape not in ((2,), (3,)):
        raise ValueError(f"{name} must be a 2- or 3-vector (x, y[, z]) in metres, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must have finite coordinates, got {tuple(float(v) for v in arr)}")
    return tuple(float(v) for v in arr)


def _padded(point: tuple[float, ...], d: int) -> tuple[float, ...]:
    return point + (0.0,) * (d - len(point))


def pair_labels(observation: object) -> Callable[[int], str]:
    """How a message names pair ``i`` of ``observation``'s geometry (:meth:`Geometry.pair_label`: ``"1 (north)"``
    where the geometry names its pairs, as a measurement file may), or by its index for a model without one."""
    geometry = getattr(observation, "geometry", None)
    return geometry.pair_label if isinstance(geometry, Geometry) else str


def principal_line(points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    r"""The least-squares line through ``points`` ``(m, d)``: their centroid :math:`\mathbf c`, the unit direction
    of largest spread and the singular values of :math:`\mathbf p_i - \mathbf c` (the second one 0 when every
    point lies on the line)."""
    p = np.asarray(points, dtype=float)
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c)
    return c, vt[0], s


def mirrored(states: ArrayLike, geometry: Geometry) -> NDArray[np.float64]:
    """2-D states reflected across the least-squares line through the sensors (every pair's Tx and Rx):
    :func:`reflected` across the line through their centroid along their principal direction.  With every
    sensor on that line the reflected track gives exactly the same Doppler.

    Raises
    ------
    ValueError
        For states other than 2-D ``(n, 4)``.
    """
    c, u, _ = principal_line(np.vstack([geometry.tx, geometry.rx])[:, :2])
    return reflected(states, c, u)


def reflected(states: ArrayLike, point: ArrayLike, direction: ArrayLike) -> NDArray[np.float64]:
    r"""2-D states reflected across the line through ``point`` along the unit vector ``direction``.

    With :math:`\mathbf c` the point and :math:`\mathbf n` the line's unit normal,
    :math:`\mathbf p \to \mathbf c + \mathbf M(\mathbf p - \mathbf c)` and
    :math:`\mathbf v \to \mathbf M\mathbf v`, :math:`\mathbf M = \mathbf I - 2\mathbf n\mathbf n^\top`.
    Distances and range rates to every point of the line are unchanged, so every pair whose Tx and Rx lie
    on it sees the reflected track with the same Doppler.

    Raises
    ------
    ValueError
        For states other than 2-D ``(n, 4)``.
    """
    x = np.asarray(states, dtype=float)
    if x.ndim != 2 or x.shape[1] != 4:
        raise ValueError(f"reflected takes 2-D states (n, 4), got {x.shape}")
    c = np.asarray(point, dtype=float)
    u = np.asarray(direction, dtype=float)
    m = np.eye(2) - 2.0 * np.outer([-u[1], u[0]], [-u[1], u[0]])
    return np.column_stack([c + (x[:, :2] - c) @ m, x[:, 2:] @ m])


#: What a finding says of a rival that is the reported solution's mirror image (:func:`is_mirror_image`); such a
#: finding also carries ``mirror="sensors"`` (:class:`~fgdoppler.estimators.verdict.Reason`), on which the command
#: line prints the ``--half-plane`` options of either side of the sensors' line.
MIRROR_ADVICE = ("mirror image across the sensors' line: if the target's side of that line is known, give it "
                 "(--half-plane)")


def is_mirror_image(point: ArrayLike, other: ArrayLike, geometry: Geometry) -> bool:
    r"""Whether the 2-D position ``other`` is ``point``'s mirror image across the sensors' line (:func:`mirrored`),
    to within a quarter of their distance: :math:`\lVert \mathbf q - \mathbf p'\rVert <
    \tfrac14\lVert \mathbf q - \mathbf p\rVert`, :math:`\mathbf p' = \mathbf c + \mathbf M(\mathbf p -
    \mathbf c)` the image of :math:`\mathbf p`."""
    p = np.asarray(point, dtype=float)[:2]
    q = np.asarray(other, dtype=float)[:2]
    image = mirrored(np.r_[p, 0.0, 0.0][None], geometry)[0, :2]
    return bool(np.linalg.norm(q - image) < 0.25 * np.linalg.norm(q - p))


#: Characters a pair name may not hold: the measurement CSV's separators and quotes, and line breaks.
_NAME_FORBIDDEN = frozenset(',"\'\n\r')


def _checked_names(names: object, n: int) -> tuple[str, ...]:
    """``names`` as a tuple, checked (rule: :class:`Geometry`'s ``pair_names``)."""
    out = tuple(names) if isinstance(names, list | tuple) else names
    if not isinstance(out, tuple) or not all(isinstance(v, str) for v in out):
        raise TypeError(f"pair_names must be a sequence of strings, got {names!r}")
    if not out:
        return out
    if len(out) != n:
        raise ValueError(f"pair_names has {len(out)} name(s) for {n} pair(s): name every pair or none")
    for i, v in enumerate(out):
        if not v or v != v.strip() or _NAME_FORBIDDEN & set(v):
            raise ValueError(f"pair {i}'s name {v!r} must be non-empty text without surrounding spaces, "
                             "commas, quotes or line breaks")
        try:
            float(v)
        except ValueError:
            pass
        else:
            raise ValueError(f"pair {i}'s name {v!r} is a number: a measurement file's pair {v} would be read as "
                             "an index; give it a name that is not a number")
    repeated = sorted({v for v in out if out.count(v) > 1})
    if repeated:
        raise ValueError(f"pair names must be unique: {', '.join(map(repr, repeated))} given twice")
    return out


#: Speed of light in vacuum (m/s): a carrier of frequency f_c has the wavelength c / f_c.
SPEED_OF_LIGHT = 299_792_458.0

#: Carrier wavelengths (m) a geometry accepts: 0.1 mm (3 THz) to 10 km (30 kHz).  A value beyond is
#: almost certainly a frequency given for a wavelength, or a unit slip.
WAVELENGTH_LIMITS = (1e-4, 1e4)


def _checked_wavelengths(values: object, n: int) -> tuple[float, ...]:
    """``values`` as a tuple of floats, checked (rule: :class:`Geometry`'s ``wavelengths``)."""
    if not isinstance(values, list | tuple) or not all(_is_number(v) for v in values):
        raise TypeError(f"wavelengths must be a sequence of numbers (metres), got {values!r}")
    out = tuple(float(v) for v in values)
    if out and len(out) != n:
        raise ValueError(f"wavelengths has {len(out)} value(s) for {n} pair(s): give every pair's wavelength or none")
    lo, hi = WAVELENGTH_LIMITS
    for i, v in enumerate(out):
        if not (np.isfinite(v) and lo <= v <= hi):
            hint = (f"; if {v:g} is the carrier frequency in Hz, the wavelength is {SPEED_OF_LIGHT / v:.6g} m "
                    "(c / f_c)" if np.isfinite(v) and v > hi else "")
            raise ValueError(f"pair {i}'s wavelength {v:g} m is outside [{lo:g}, {hi:g}] m{hint}")
    return out


@dataclass(frozen=True)
class BistaticPair:
    r"""One transmitter–receiver pair.

    Parameters
    ----------
    tx, rx
        Transmitter and receiver positions ``(x, y)`` or ``(x, y, z)`` in
        metres (two coordinates mean ``z = 0``: a sensor on the ground), finite.
        They may coincide (within :data:`SENSOR_EPS`): a monostatic radar,
        whose bistatic range :math:`r_T + r_R = 2r` and range rate
        :math:`2\dot r` are twice its own.
    """

    tx: tuple[float, ...]
    rx: tuple[float, ...]

    def __init__(self, tx: ArrayLike, rx: ArrayLike) -> None:
        t = _point(tx, "tx")
        r = _point(rx, "rx")
        object.__setattr__(self, "tx", t)
        object.__setattr__(self, "rx", r)

    @property
    def monostatic(self) -> bool:
        """Whether Tx and Rx are at the same place (within :data:`SENSOR_EPS`)."""
        return self.baseline <= SENSOR_EPS

    @property
    def baseline(self) -> float:
        """Tx–Rx distance ``L`` in metres."""
        d = max(len(self.tx), len(self.rx))
        return float(np.linalg.norm(np.subtract(_padded(self.tx, d), _padded(self.rx, d))))

    def swapped(self) -> BistaticPair:
        """The same pair with the roles of Tx and Rx exchanged."""
        return BistaticPair(tx=self.rx, rx=self.tx)


@dataclass(frozen=True, kw_only=True)
class Geometry:
    r"""A set of bistatic pairs observing the same target.

    Parameters
    ----------
    pairs
        One or more :class:`BistaticPair`.  Pair ``i`` is addressed by the
        0-based index ``i`` in measurement files.
    name
        Optional label (e.g. ``"a"`` for the paper's case (a)).
    zone_limits
        Overrides of the default detectable zone in the sensors' frame
        (the ``[zone]`` table of the geometry file); see :attr:`zone`.  An
        altitude band makes the problem 3-D (:attr:`dim`).
    pair_names
        Optional names of the pairs, one per pair in their order (``()``:
        none), e.g. the receivers' sites: a measurement file may then give
        a pair by its name instead of its index, so that a file and a
        geometry listing the pairs in different orders cannot be matched
        wrongly (:meth:`~fgdoppler.measurements.Measurements.from_csv`).  Each is non-empty text without
        surrounding spaces, not a number (it would read as an index),
        without a comma, quote or line break, and unique.
    wavelengths
        Optional carrier wavelength of each pair in metres, one per pair in
        their order (``()``: none), :math:`\lambda = c / f_c`: with them a
        measurement file may give each Doppler as the frequency shift
        :math:`f_D` in Hz (column ``doppler_hz``), read as the bistatic range
        rate :math:`-\lambda f_D`
        (:meth:`~fgdoppler.measurements.Measurements.from_csv`).  Each is
        finite and within :data:`WAVELENGTH_LIMITS`.  Nothing else uses
        them: every estimate is in metres and m/s.
    geodetic_origin
        Where the sensors were given as latitude, longitude and height
        (:mod:`fgdoppler.geodetic`): the origin of the local east-north-up
        frame their positions are in (``x`` east, ``y`` north, ``z`` up, in
        metres), with which estimates convert back to latitude and longitude.
        ``None``: a frame of the user's own.  A change of frame or scale
        (:meth:`in_frame`, :meth:`scaled`, :meth:`mirrored_x`) drops it.
    """

    pairs: tuple[BistaticPair, ...]
    name: str = ""
    zone_limits: ZoneLimits = field(default_factory=ZoneLimits)
    pair_names: tuple[str, ...] = ()
    wavelengths: tuple[float, ...] = ()
    geodetic_origin: GeodeticOrigin | None = None
    _tx: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _rx: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pairs = tuple(self.pairs)
        if len(pairs) == 0:
            raise ValueError("a Geometry needs at least one bistatic pair")
        for i, p in enumerate(pairs):
            if not isinstance(p, BistaticPair):
                raise TypeError(f"pair {i} is {type(p).__name__}, expected BistaticPair")
        object.__setattr__(self, "pairs", pairs)
        object.__setattr__(self, "pair_names", _checked_names(self.pair_names, len(pairs)))
        object.__setattr__(self, "wavelengths", _checked_wavelengths(self.wavelengths, len(pairs)))
        if self.geodetic_origin is not None and not isinstance(self.geodetic_origin, GeodeticOrigin):
            raise TypeError(f"geodetic_origin must be a GeodeticOrigin or None, got {self.geodetic_origin!r}")
        d = 3 if self.zone_limits.altitude is not None or any(len(p.tx) == 3 or len(p.rx) == 3 for p in pairs) \
            else 2
        tx = np.array([_padded(p.tx, d) for p in pairs], dtype=float)
        rx = np.array([_padded(p.rx, d) for p in pairs], dtype=float)
        tx.setflags(write=False)
        rx.setflags(write=False)
        object.__setattr__(self, "_tx", tx)
        object.__setattr__(self, "_rx", rx)
        spread = np.max(np.linalg.norm(np.vstack([tx, rx]) - rx[0], axis=1))
        if not spread > SENSOR_EPS:
            raise ValueError(
                f"every sensor is at one place, {tuple(float(v) for v in rx[0])}: from one site a Doppler history fixes range and "
                "speed but not the bearing (any rotation of the track about the site fits the same data); "
                "give at least two sensor positions")

    @property
    def n_pairs(self) -> int:
        """Number of bistatic pairs."""
        return len(self.pairs)

    @property
    def dim(self) -> int:
        """Spatial dimension of the problem: 3 if a sensor has three coordinates or the zone an
        altitude band, else 2.  Estimators of this geometry use states of ``2 * dim`` numbers
        (``[x, y, vx, vy]`` or ``[x, y, z, vx, vy, vz]``)."""
        return int(self._tx.shape[1])

    @property
    def state_dim(self) -> int:
        """Length of a state vector, ``2 * dim``."""
        return 2 * self.dim

    @property
    def tx(self) -> NDArray[np.float64]:
        """Transmitter positions, shape ``(n_pairs, dim)`` (read-only)."""
        return self._tx

    @property
    def rx(self) -> NDArray[np.float64]:
        """Receiver positions, shape ``(n_pairs, dim)`` (read-only)."""
        return self._rx

    def positions(self, d: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Transmitter and receiver positions with ``d`` coordinates, for states of ``2 d`` numbers.

        A 2-D geometry serves 3-D states with its sensors at ``z = 0``; a 3-D
        one serves 2-D states only if every sensor is on the ground.

        Raises
        ------
        ValueError
            If ``d`` is not 2 or 3, or 2-D states meet sensors above the ground.
        """
        if d == self.dim:
            return self._tx, self._rx
        if d == 3:
            return self._pad3
        if d == 2:
            if np.any(self._tx[:, 2]) or np.any(self._rx[:, 2]):
                raise ValueError("2-D states [x, y, vx, vy] cannot be used with sensors above the ground "
                                 "(a sensor has z != 0): use 3-D states [x, y, z, vx, vy, vz]")
            return self._flat
        raise ValueError(f"states must have 4 or 6 numbers (2-D or 3-D), got {2 * d}")

    @cached_property
    def _pad3(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        tx, rx = (np.column_stack([a, np.zeros(len(a))]) for a in (self._tx, self._rx))
        tx.setflags(write=False)
        rx.setflags(write=False)
        return tx, rx

    @cached_property
    def _flat(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        tx, rx = np.ascontiguousarray(self._tx[:, :2]), np.ascontiguousarray(self._rx[:, :2])
        tx.setflags(write=False)
        rx.setflags(write=False)
        return tx, rx

    @cached_property
    def radars(self) -> tuple[int, ...]:
        r"""The pairs that are radars: Tx and Rx at one place, or nearly so.

        Pair :math:`p` is one where its baseline :math:`L_p \le \max(\epsilon,\ a\,D)`, :math:`D` the
        largest distance between two sensors of the geometry, :math:`a` =
        :data:`~fgdoppler.frames.AXIS_MIN_SHARE` and :math:`\epsilon` =
        :data:`~fgdoppler.frames.SENSOR_EPS` (the rule that keeps such a pair from setting the sensors'
        frame; it scales with the layout).  Its bistatic range rate is then twice the radar's radial
        velocity to second order in :math:`L_p / r` (:math:`r` its range), and a file may give that
        velocity instead.
        """
        cut = max(SENSOR_EPS, AXIS_MIN_SHARE * self.extent)
        return tuple(int(k) for k in np.flatnonzero(np.linalg.norm(self._tx - self._rx, axis=1) <= cut))

    def sensors(self) -> NDArray[np.float64]:
        """Distinct sensor positions (Tx and Rx), shape ``(n_sensors, dim)``."""
        return np.unique(np.vstack([self._tx, self._rx]), axis=0)

    def sites(self) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
        """The sensor sites and which site each pair's transmitter and receiver is.

        A site is a distinct sensor position: a transmitter shared by two
        pairs is one, and so is a monostatic radar.  Sites are numbered in
        the order the pairs first name them (pair 0's transmitter, its
        receiver, pair 1's transmitter, …); a position within
        :data:`~fgdoppler.frames.SENSOR_EPS` of one already named is that
        site.  The paper's case (a) has the sites Tx1, Rx, Tx2; case (b)
        Tx, Rx1, Rx2.

        Returns
        -------
        positions : ndarray, shape ``(n_sites, dim)``
        tx_site, rx_site : ndarray of int, shape ``(n_pairs,)``
        """
        named: list[NDArray[np.float64]] = []

        def site(point: NDArray[np.float64]) -> int:
            for i, s in enumerate(named):
                if np.linalg.norm(point - s) <= SENSOR_EPS:
                    return i
            named.append(point)
            return len(named) - 1

        tx_site, rx_site = [], []
        for t, r in zip(self._tx, self._rx, strict=True):
            tx_site.append(site(t))
            rx_site.append(site(r))
        return np.array(named), np.array(tx_site, dtype=np.intp), np.array(rx_site, dtype=np.intp)

    def with_sites_moved(self, displacement: ArrayLike) -> Geometry:
        """The same geometry with site ``s`` (:meth:`sites`) moved by ``displacement[s]`` (m).

        ``displacement`` has ``dim`` numbers per site, ``(n_sites, dim)`` or flat (site-major).  The name,
        zone, pair names, wavelengths and geodetic origin stay.

        Raises
        ------
        ValueError
            If ``displacement`` has not ``dim`` finite numbers per site.
        """
        positions, tx_site, rx_site = self.sites()
        delta = np.asarray(displacement, dtype=float)
        if delta.size != positions.size or not np.all(np.isfinite(delta)):
            raise ValueError(f"a site displacement needs {self.dim} finite numbers per site ({positions.shape[0]} "
                             f"sites: {positions.size} numbers), got {delta.size}")
        delta = delta.reshape(positions.shape)
        return replace(self, pairs=tuple(BistaticPair(tx=self._tx[i] + delta[tx_site[i]],
                                                      rx=self._rx[i] + delta[rx_site[i]])
                                         for i in range(self.n_pairs)))

    def pair_label(self, i: int) -> str:
        """Pair ``i`` as a measurement file names it: its 0-based index, with its name where the geometry gives
        one (``"1 (north)"``)."""
        return f"{i} ({self.pair_names[i]})" if self.pair_names else str(i)

    @cached_property
    def extent(self) -> float:
        """The sensors' extent: the largest distance between two sensors (m)."""
        s = self.sensors()
        return float(np.max(np.linalg.norm(s[:, None, :] - s[None, :, :], axis=-1)))

    @cached_property
    def frame(self) -> Frame:
        """The sensors' own frame (:func:`fgdoppler.frames.sensor_frame`): identity for the paper's geometries."""
        return sensor_frame(self._tx, self._rx)

    @cached_property
    def scan_rank(self) -> NDArray[np.intp]:
        """Each pair's place in the order in which a filter takes simultaneous measurements, ``(n_pairs,)``.

        The pairs sorted by their receiver's, then their transmitter's
        coordinates in the sensors' own frame (:attr:`frame`, snapped as in
        :meth:`in_frame`), lexicographically; pairs at the same positions
        share a rank.  The order belongs to the sensors, not to their
        numbering: renumbering the pairs after the first (which defines the
        frame) permutes the ranks with them, and a rigidly moved copy of the
        geometry has the same ones, to the bit.  A sequential filter's answer
        depends slightly on the order of a scan's updates
        (:meth:`fgdoppler.estimators.ekf.ExtendedKalmanFilter.add_scan`).
        """
        local = self.in_frame(self.frame)
        keys = np.hstack([local.rx, local.tx])
        _, rank = np.unique(keys, axis=0, return_inverse=True)
        out = np.asarray(rank, dtype=np.intp).reshape(-1)
        out.setflags(write=False)
        return out

    def default_zone(self, *, speed_max: float = DEFAULT_SPEED_MAX) -> Zone:
        """The default detectable zone in :attr:`frame` (:func:`fgdoppler.zone.default_zone`)."""
        return default_zone(self.frame, self._tx, self._rx, speed_max=speed_max)

    @cached_property
    def zone(self) -> Zone:
        """The detectable zone: the default rule with :attr:`zone_limits` applied."""
        return self.zone_limits.apply(self.default_zone())

    def in_3d(self, altitude: tuple[float, float] | None = None) -> Geometry:
        """The same sensors as a 3-D problem (two-coordinate sensors at ``z = 0``).

        ``altitude`` overrides the zone's altitude band (default: the rule of
        :mod:`fgdoppler.zone`, heights 0 to a quarter of the sensors' extent).
        """
        pairs = tuple(BistaticPair(tx=_padded(p.tx, 3), rx=_padded(p.rx, 3)) for p in self.pairs)
        limits = self.zone_limits if altitude is None else replace(self.zone_limits, altitude=altitude)
        return replace(self, pairs=pairs, zone_limits=limits)

    def with_zone(self, limits: ZoneLimits) -> Geometry:
        """The same sensors with other zone overrides."""
        return replace(self, zone_limits=limits)

    def scaled(self, factor: float) -> Geometry:
        """The same geometry in other length units: every sensor coordinate and the zone's along, across and
        altitude limits multiplied by ``factor`` (its speed bound, in m/s, kept).

        Raises
        ------
        ValueError
            If ``factor`` is not a positive finite number.
        """
        if not (np.isfinite(factor) and factor > 0):
            raise ValueError(f"a length scale factor must be positive and finite, got {factor!r}")

        def times(band: tuple[float, float] | None) -> tuple[float, float] | None:
            return None if band is None else (band[0] * factor, band[1] * factor)

        limits = self.zone_limits
        return replace(self, pairs=tuple(BistaticPair(tx=np.multiply(p.tx, factor), rx=np.multiply(p.rx, factor))
                                         for p in self.pairs),
                       zone_limits=replace(limits, along=times(limits.along), across=times(limits.across),
                                           altitude=times(limits.altitude)),
                       geodetic_origin=None)

    def check_zone(self, reach: float = 10.0) -> None:
        """Raise :class:`ValueError` if the zone lies more than ``reach`` sensor extents from every sensor.

        The sensor extent is the largest distance between two sensors; a zone
        farther away than ten of them is almost certainly a unit or sign
        mistake (kilometres for metres, a flipped axis).
        """
        sensors = self.sensors()
        extent = self.extent
        d = self.zone.distance_to(sensors)
        if d > reach * extent:
            raise ValueError(f"the zone (along {list(self.zone.along)}, across {list(self.zone.across)} m) lies "
                             f"{distance_text(d)} from the nearest sensor, more than {reach:g} sensor extents "
                             f"({distance_text(extent)}): check its units and signs")

    def in_frame(self, frame: Frame, *, snap: float | None = SNAP) -> Geometry:
        """The same pairs with positions in ``frame``'s local coordinates, snapped to a ``snap``-metre lattice.

        Snapping makes the local geometry of a rigidly moved copy of the
        problem identical to the bit, not only to rounding (a 1,000 km
        translation leaves ~1e-10 m of rounding in every coordinate, and
        Levenberg–Marquardt stopping in a flat valley amplifies that to
        1e-5 of the answer).  ``None`` keeps the coordinates as computed.
        """
        if frame.dim not in (self.dim, 3):
            raise ValueError(f"a {self.dim}-D geometry cannot be moved into a {frame.dim}-D frame")

        def local(point: tuple[float, ...]) -> NDArray[np.float64]:
            u = frame.points_to_local(_padded(point, frame.dim))
            return u if snap is None else np.round(u / snap) * snap + 0.0

        return replace(self, pairs=tuple(BistaticPair(tx=local(p.tx), rx=local(p.rx)) for p in self.pairs),
                       geodetic_origin=None)

    @property
    def on_lattice(self) -> bool:
        """True if every sensor coordinate is already on the :data:`SNAP` lattice (nothing to snap)."""
        xy = np.vstack([self._tx, self._rx])
        return bool(np.array_equal(np.round(xy / SNAP) * SNAP + 0.0, xy))

    def mirrored_x(self, x_mirror: float) -> Geometry:
        """The geometry reflected about the vertical line ``x = x_mirror``."""
        return Geometry(
            pairs=tuple(
                BistaticPair(
                    tx=(2 * x_mirror - p.tx[0], *p.tx[1:]), rx=(2 * x_mirror - p.rx[0], *p.rx[1:])
                )
                for p in self.pairs
            ),
            name=self.name,
            pair_names=self.pair_names,
            wavelengths=self.wavelengths,
        )

    # -- TOML -----------------------------------------------------------------
    def toml_text(self) -> str:
        """The geometry file's text (format: :mod:`fgdoppler.geometry_file`)."""
        from fgdoppler.geometry_file import geometry_text

        return geometry_text(self)

    def to_toml(self, path: str | Path) -> None:
        """Write the geometry as TOML, atomically (format: :mod:`fgdoppler.geometry_file`)."""
        from fgdoppler.geometry_file import write_geometry

        write_geometry(self, path)

    @classmethod
    def from_toml(cls, path: str | Path) -> Geometry:
        """Read a geometry file (format and errors: :func:`fgdoppler.geometry_file.read_geometry`)."""
        from fgdoppler.geometry_file import read_geometry

        geometry: Geometry = read_geometry(path)
        return geometry


def paper_geometry(case: str) -> Geometry:
    """The sensor positions of the paper's Table 1.

    Parameters
    ----------
    case
        ``"a"``: two transmitters, one receiver — Tx1 (50 km, 0), Tx2 (50 km, 1 km),
        Rx (0, 0); pairs are (Tx1, Rx) and (Tx2, Rx).
        ``"b"``: one transmitter, two receivers — Tx (50 km, 0), Rx1 (0, 0),
        Rx2 (0, 1 km); pairs are (Tx, Rx1) and (Tx, Rx2).
    """
    key = case.lower().strip()
    if key == "a":
        pairs = (
            BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)),
            BistaticPair(tx=(50e3, 1e3), rx=(0.0, 0.0)),
        )
    elif key == "b":
        pairs = (
            BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)),
            BistaticPair(tx=(50e3, 0.0), rx=(0.0, 1e3)),
        )
    else:
        raise ValueError(f"unknown paper geometry {case!r}: expected 'a' or 'b'")
    return Geometry(pairs=pairs, name=key)


def resolve_geometry(spec: str | Path | Geometry) -> Geometry:
    """A geometry from a preset name (``"a"``, ``"b"``), a TOML path, or itself."""
    if isinstance(spec, Geometry):
        return spec
    text = str(spec)
    if text.lower() in ("a", "b"):
        return paper_geometry(text)
    path = Path(text)
    if not path.exists():
        raise ValueError(f"geometry {text!r} is neither a preset ('a', 'b') nor an existing file")
    return Geometry.from_toml(path)


def bistatic_range(points: ArrayLike, geometry: Geometry) -> NDArray[np.float64]:
    r"""Bistatic range :math:`r_T + r_R` of points for every pair.

    .. math:: r_i(\mathbf p) = \lVert \mathbf p - \mathbf t_i\rVert + \lVert \mathbf p - \mathbf r_i\rVert

    Parameters
    ----------
    points
        Positions ``(..., d)`` or states ``(..., 2d)`` (then their positions), ``d`` 2 or 3.

    Returns
    -------
    ndarray, shape ``(..., n_pairs)``
    """
    p = np.asarray(points, dtype=float)
    d = p.shape[-1] // 2 if p.shape[-1] in (4, 6) else p.shape[-1]
    tx, rx = geometry.positions(d)
    p = p[..., None, :d]
    return np.linalg.norm(p - tx, axis=-1) + np.linalg.norm(p - rx, axis=-1)


def ellipse_tangent(points: ArrayLike, geometry: Geometry) -> NDArray[np.float64]:
    r"""Unit tangent of each pair's bistatic ellipse through the given points.

    The gradient of the bistatic range is :math:`\mathbf u_T + \mathbf u_R`
    (sum of the unit vectors from Tx and from Rx to the point); the tangent is
    that gradient rotated by +90°.  On the baseline segment between Tx and Rx
    the gradient vanishes (the ellipse degenerates to the segment); there the
    tangent is taken along the baseline.

    A plane notion: in 3-D the directions that leave a pair blind form the
    plane perpendicular to the gradient, not one tangent; this function takes
    horizontal positions ``(..., 2)`` of a geometry whose sensors are on the ground.

    Returns
    -------
    ndarray, shape ``(..., n_pairs, 2)``

    Raises
    ------
    ValueError
        If a point coincides with a sensor, or a sensor is above the ground.
    """
    p = np.asarray(points, dtype=float)[..., None, :2]
    tx, rx = geometry.positions(2)
    dt = p - tx
    dr = p - rx
    nt = np.linalg.norm(dt, axis=-1, keepdims=True)
    nr = np.linalg.norm(dr, axis=-1, keepdims=True)
    if np.any(nt <= SENSOR_EPS) or np.any(nr <= SENSOR_EPS):
        raise ValueError("a point coincides with a sensor: the bistatic ellipse is undefined there")
    grad = dt / nt + dr / nr
    gnorm = np.linalg.norm(grad, axis=-1, keepdims=True)
    baseline = rx - tx
    length = np.linalg.norm(baseline, axis=-1, keepdims=True)
    # a monostatic pair's circle never degenerates off its sensor: its base_dir is never chosen
    base_dir = np.broadcast_to(baseline / np.where(length > 0.0, length, 1.0), grad.shape)
    tangent = np.stack([-grad[..., 1], grad[..., 0]], axis=-1)
    degenerate = gnorm < 1e-12
    safe = np.where(degenerate, 1.0, gnorm)
    return np.where(degenerate, base_dir, tangent / safe)

