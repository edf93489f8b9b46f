r"""Multi-start grid search over initial states (paper Section 3, grid of Section 5).

The candidates fill the zone (:class:`~fgdoppler.zone.Zone`): a regular grid
of initial position laid out in the zone's own frame, of speed up to the
zone's bound, and of heading measured in that frame, so the candidate set
moves with the sensors under any rigid motion.  Every candidate
:math:`\mathbf x_0^{0i}` is scored by its weighted residual

.. math:: e^i = \sum_j \Big(\frac{Z_j - g_j(\mathbf x_0^{0i})}{\sigma_j}\Big)^2

(the paper's unweighted :math:`e^i` up to a constant factor when all σ are
equal).  The grid is evaluated in chunks so memory stays bounded whatever its
size, and the K best *distinct* candidates are returned: the local minima of
the cost over the 4-D grid (heading wraps around), best first — separated
optima, not K neighbours of one optimum.

Resolution (:class:`GridSpec`)
    Position step :math:`D/50`, with :math:`D` the sensors' extent along
    the zone's first axis (the paper's 1 km for its 50 km baseline),
    coarsened where the zone would need more than ``max_positions`` nodes
    (then :math:`\sqrt{\text{area}/\texttt{max\_positions}}`) and refined
    where a side would get fewer than 5 nodes; speed step
    :math:`s_{\max}/20` (the paper's 10 m/s up to 200 m/s); heading step 20°.
    Cost: (position nodes) × (speeds) × (headings) × (measurements) Doppler
    evaluations, about 7 ns each on the 2-core machine — 26 ms for the
    paper's 186,120 candidates × 20 measurements when every candidate is
    scored on every measurement (2026-11-23).

Pruned search
    The cost is a sum of non-negative terms, so its sum over part of the
    window bounds it from below.  Every candidate is first scored on about
    a quarter of each pair's measurements, evenly spread; only those with
    the lowest bounds are scored on all of them, as many as it takes to make
    the K best local minima certain (:func:`_best_minima`); where that takes
    many (outliers outside the first quarter), the bounds still below the
    best minima found are first tightened quarter by quarter.  The result is
    the exhaustive search's to the bit: 15 ms against 26 ms on the paper's
    window, 15.6 ms against 42 ms on a restart check's 32 measurements
    (``python -m benchmarks --only grid``).  Where few measurements carry
    the window (fewer than ``2 * PRUNE_STRIDE``) every candidate is scored
    on all of them.

3-D problems (zone with an altitude band)
    The horizontal grid above is repeated at ``altitude_levels`` heights
    (default 4, the midpoints of equal slices of the band: 1.56, 4.69, 7.81
    and 10.9 km for the default 0–12.5 km) with level flight (:math:`\dot z = 0`); the
    initiation's Levenberg–Marquardt then refines all six components from
    the best candidates.  The cost is ``altitude_levels`` times the 2-D grid's:
    for the paper's zone and window 744,480 candidates in 0.055 s against
    186,120 in 0.015 s in 2-D (0.10 s and 0.025 s without the pruned search
    below; 2-core machine, median of 7, 2026-11-23).  Levels at mid-slices rather than at
    the band's ends keep candidates off the sensors' plane, where the
    Doppler's derivative with respect to height vanishes (a target at
    :math:`z = 0` and its mirror at :math:`-z` give the same Doppler for
    ground sensors).

Speed lower bound
    The paper starts the speed grid at the largest measured Doppler, but a
    bistatic Doppler :math:`h = \mathbf v\cdot(\mathbf u_T + \mathbf u_R)` satisfies
    :math:`|h| \le \lVert\mathbf v\rVert\,\lVert\mathbf u_T+\mathbf u_R\rVert \le 2\lVert\mathbf v\rVert`
    (equality for a target beyond the sensors on the baseline extension), so
    the paper's bound can exclude the truth.  With noise,
    :math:`|h_j| \ge |Z_j| - n\sigma_j` except with probability below
    :math:`2\Phi(-n)` per measurement, giving

    .. math:: s_{\min} = \tfrac12\max\big(0,\ \max_j(|Z_j| - n\sigma_j)\big),

    which never exceeds the true speed for noise-free data and, with the
    default :math:`n = 5`, only if some noise sample exceeds 5σ.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import minimum_filter

from fgdoppler.frames import Frame
from fgdoppler.geometry import Geometry
from fgdoppler.models.doppler import StackedTimes, _cv
from fgdoppler.models.robust import huber_rho
from fgdoppler.zone import Zone

__all__ = ["GridResult", "GridSpec", "HalfPlane", "grid_costs", "grid_search", "grid_states", "speed_lower_bound"]

FloatArray = NDArray[np.float64]
#: Whether each (sensor, time) term is computed once and read by every measurement that needs it
#: (:func:`_term_plan`); off, every measurement computes its own two (the same numbers, more work).
SHARE_TERMS = True
#: The pruned search (:func:`_best_minima`) first scores every candidate on about one measurement in this many
#: (each pair's, evenly spread): a lower bound of its cost.
PRUNE_STRIDE = 4
#: Share of the grid, lowest bounds first, then scored on every measurement; doubled until the K best minima
#: are certain.
PRUNE_FIRST_SHARE = 1.0 / 64
#: Relative margin by which a cost must lie below the lowest bound not yet scored: the bound is the same terms
#: summed in another order, so the two may differ by rounding.
PRUNE_MARGIN = 1e-9
#: The scored candidates' neighbours are compared one by one (:math:`3^d` each, fewer where one is lower) while
#: scored × :math:`3^d` is below this many times :math:`d` × the grid's size, the work of a minimum filter's
#: :math:`d` passes over the whole grid; measured on 4-D and 5-D grids of 0.3-0.5 million candidates, the
#: neighbour test costs the same as the filter at 12-20 % of the grid scored.
NEIGHBOUR_TEST_WORK = 4


def _axis(start: float, stop: float, step: float, name: str) -> FloatArray:
    if not (np.isfinite(start) and np.isfinite(stop) and np.isfinite(step)) or step <= 0 or stop < start:
        raise ValueError(f"{name} grid needs finite start <= stop and step > 0, got ({start}, {stop}, {step})")
    return np.arange(start, stop + 1e-9 * step, step)


#: Why a half plane is refused for a 3-D problem (in any frame, before anything is computed).
THREE_D_REFUSAL = "a half-plane is a 2-D constraint; a 3-D zone's altitude band bounds the height instead"


@dataclass(frozen=True, kw_only=True)
class HalfPlane:
    """The side of a line the target is known to be on: ``normal · (p - point) >= 0``.

    For the paper's geometries, ``HalfPlane(point=(0, 0), normal=(0, 1))``
    says "north of the Tx1–Rx1 baseline" and removes the mirror ambiguity.
    """

    point: tuple[float, float] = (0.0, 0.0)
    normal: tuple[float, float] = (0.0, 1.0)

    def __post_init__(self) -> None:
        n = np.asarray(self.normal, dtype=float)
        if n.shape != (2,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise ValueError(f"normal must be a non-zero 2-vector, got {self.normal}")

    def contains(self, positions: ArrayLike) -> NDArray[np.bool_]:
        """Whether each position ``(..., 2)`` (or state) lies in the half plane."""
        p = np.asarray(positions, dtype=float)[..., :2]
        return (p - np.asarray(self.point)) @ np.asarray(self.normal, dtype=float) >= 0

    def in_frame(self, frame: Frame) -> HalfPlane:
        """The same half plane in ``frame``'s local coordinates."""
        return self.transformed(frame, to_world=False)

    def transformed(self, frame: Frame, *, to_world: bool) -> HalfPlane:
        r"""The same half plane out of (``to_world``) or into ``frame``'s local coordinates.

        With :math:`\mathbf u = \mathbf B(\mathbf p - \mathbf o)`, the
        condition :math:`\mathbf n\cdot(\mathbf p - \mathbf q) \ge 0` reads
        :math:`(\mathbf B\mathbf n)\cdot(\mathbf u - \mathbf u_q) \ge 0`
        (:math:`\mathbf B` orthonormal).
        """
        if frame.dim != 2:
            raise ValueError(THREE_D_REFUSAL)
        if frame.is_identity:
            return self
        n = np.asarray(self.normal, dtype=float)
        if to_world:
            return HalfPlane(point=tuple(frame.points_to_world(self.point)), normal=tuple(frame.B.T @ n))
        return HalfPlane(point=tuple(frame.points_to_local(self.point)), normal=tuple(frame.B @ n))


@dataclass(frozen=True, kw_only=True)
class GridSpec:
    """Resolution of the candidate grid over a zone (defaults: the rule of the module docstring).

    Parameters
    ----------
    position_step : float or None, default None
        Spacing of the position nodes along both zone axes (m); ``None``
        for the rule.
    heading_step_deg : float, default 20.0
        Heading spacing in degrees, clockwise from the zone frame's second
        axis (the paper's ``0..259°`` is a typo for ``0..340°``).
    speed_step : float or None, default None
        Speed spacing (m/s); ``None`` for ``speed_max / 20``.
    speed_min : float or None, default None
        Fixed lower end of the speed grid; ``None`` derives it from the data
        with :func:`speed_lower_bound`.
    n_sigma : float, default 5.0
        Noise allowance of the derived lower bound.
    max_positions : int, default 2000
        Largest number of horizontal position nodes the rule may use.
    altitude_levels : int, default 4
        Heights tried in a 3-D zone: the midpoints of this many equal slices
        of its altitude band (level flight at each).
    """

    position_step: float | None = None
    heading_step_deg: float = 20.0
    speed_step: float | None = None
    speed_min: float | None = None
    n_sigma: float = 5.0
    max_positions: int = 2000
    altitude_levels: int = 4

    def __post_init__(self) -> None:
        if isinstance(self.altitude_levels, bool) or not isinstance(self.altitude_levels, int) \
                or self.altitude_levels < 1:
            raise ValueError(f"altitude_levels must be an integer >= 1, got {self.altitude_levels!r}")
        for name in ("position_step", "speed_step"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0 or None, got {v}")
        if not (np.isfinite(self.heading_step_deg) and 0 < self.heading_step_deg <= 180):
            raise ValueError(f"heading_step_deg must be in (0, 180], got {self.heading_step_deg}")
        if self.max_positions < 4:
            raise ValueError(f"max_positions must be >= 4, got {self.max_positions}")

    def step(self, zone: Zone, extent: float) -> float:
        """Position step over ``zone`` for sensors spanning ``extent`` metres along its first axis."""
        if self.position_step is not None:
            return float(self.position_step)
        step = extent / 50
        a, b = zone.extents[:2]
        if (a / step + 1) * (b / step + 1) > self.max_positions:
            step = float(np.sqrt(zone.area / self.max_positions))
        return min(step, min(a, b) / 4)

    def levels(self, zone: Zone) -> FloatArray:
        """Heights of the candidate grid in a 3-D zone (empty for a 2-D zone)."""
        if zone.altitude is None:
            return np.zeros(0)
        lo, hi = zone.altitude
        return lo + (np.arange(self.altitude_levels) + 0.5) * (hi - lo) / self.altitude_levels

    def axes(self, zone: Zone, extent: float, s_min: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The along, across, speed and heading (rad) axes over ``zone`` for a speed lower bound."""
        lo = s_min if self.speed_min is None else self.speed_min
        if lo > zone.speed_max:
            raise ValueError(
                f"the data need a speed of at least {lo:.1f} m/s but the zone's speed bound is "
                f"{zone.speed_max:.1f} m/s: raise the speed bound (--speed-max) or check the data's units (doppler "
                "is the bistatic range rate in m/s, not a Doppler shift in Hz: from f_D, doppler = -wavelength * f_D; "
                "a file may give doppler_hz and sigma_hz columns instead, with each pair's wavelength in the geometry "
                "file)"
            )
        step = self.step(zone, extent)
        speed_step = self.speed_step if self.speed_step is not None else zone.speed_max / 20
        return (
            _axis(*zone.along, step, name="along"),
            _axis(*zone.across, step, name="across"),
            _axis(lo, zone.speed_max, speed_step, name="speed"),
            np.deg2rad(_axis(0.0, 360.0 - self.heading_step_deg, self.heading_step_deg, name="heading")),
        )


def grid_states(x: ArrayLike, y: float, speed: float, heading_deg: ArrayLike) -> FloatArray:
    """States on an ``x × heading`` grid at fixed ``y`` and speed, shape ``(nx, nh, 4)``.

    Heading is clockwise from +y: ``vx = v sin h``, ``vy = v cos h``.
    """
    xs = np.asarray(x, dtype=float).reshape(-1)
    h = np.deg2rad(np.asarray(heading_deg, dtype=float).reshape(-1))
    X_, H_ = np.meshgrid(xs, h, indexing="ij")
    return np.stack([X_, np.full_like(X_, y), speed * np.sin(H_), speed * np.cos(H_)], axis=-1)


def speed_lower_bound(doppler: ArrayLike, sigma: ArrayLike, n_sigma: float = 5.0, *,
                      pair: ArrayLike | None = None, time: ArrayLike | None = None) -> float:
    r"""Lower bound on the target speed from Doppler data: :math:`\tfrac12\max(0, \max_j |Z_j| - n\sigma_j)`.

    A bistatic Doppler (range rate) is at most twice the speed: each of its
    two range rates is at most the speed.  With ``pair`` and ``time`` the
    bound is robust to isolated outliers: each pair's values
    :math:`|Z_j| - n\sigma_j` enter as the median of three consecutive ones
    (time order), so one gross outlier cannot raise it, and a true peak
    lowers it at most to its neighbours' (a weaker bound, never a false one);
    a pair with fewer than three measurements does not count.
    """
    z = np.abs(np.asarray(doppler, dtype=float))
    a = z - n_sigma * np.broadcast_to(np.asarray(sigma, dtype=float), z.shape)
    if pair is None or time is None:
        return 0.5 * max(0.0, float(np.max(a))) if z.size else 0.0
    pairs, times = np.asarray(pair).reshape(-1), np.asarray(time, dtype=float).reshape(-1)
    best = 0.0
    for p in np.unique(pairs):
        mine = a[pairs == p][np.argsort(times[pairs == p], kind="stable")]
        if mine.size >= 3:
            best = max(best, float(np.max(np.median(np.stack([mine[:-2], mine[1:-1], mine[2:]]), axis=0))))
    return 0.5 * best


def _states_from_axes(zone: Zone, us: FloatArray, vs: FloatArray, ws: FloatArray, speeds: FloatArray,
                      headings: FloatArray, flat: NDArray[np.intp]) -> FloatArray:
    if zone.dim == 2:
        i, j, k, m = np.unravel_index(flat, (us.size, vs.size, speeds.size, headings.size))
        local = np.stack([us[i], vs[j], speeds[k] * np.sin(headings[m]), speeds[k] * np.cos(headings[m])], axis=-1)
    else:
        i, j, lv, k, m = np.unravel_index(flat, (us.size, vs.size, ws.size, speeds.size, headings.size))
        local = np.stack([us[i], vs[j], ws[lv], speeds[k] * np.sin(headings[m]), speeds[k] * np.cos(headings[m]),
                          np.zeros(i.size)], axis=-1)
    return zone.frame.states_to_world(local)


def grid_costs(
    geometry: Geometry,
    times: StackedTimes,
    doppler: ArrayLike,
    sigma: ArrayLike,
    states: ArrayLike,
    *,
    chunk: int = 4096,
    huber_k: float | None = None,
) -> FloatArray:
    """Weighted residual cost of each candidate state, evaluated ``chunk`` candidates at a time.

    The cost is :math:`\\sum_j \\rho(r_j)` with :func:`huber_rho` (the sum of
    squares without ``huber_k``).  Candidates whose trajectory passes through
    a sensor get ``inf`` (they cannot explain finite Doppler).
    """
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    z = np.asarray(doppler, dtype=float)
    w = 1.0 / np.broadcast_to(np.asarray(sigma, dtype=float), z.shape)
    x = np.asarray(states, dtype=float)
    x = x.reshape(-1, x.shape[-1])
    out = np.empty(x.shape[0])
    for start in range(0, x.shape[0], chunk):
        sl = slice(start, start + chunk)
        g, _, mask = _cv(x[sl], geometry, times, jacobian=False, singular="mask")
        r = (z - g) * w
        c = np.einsum("ij,ij->i", r, r) if huber_k is None else huber_rho(r, huber_k).sum(axis=-1)
        if mask is not None:
            c[np.any(mask, axis=-1)] = np.inf
        out[sl] = c
    return out


@dataclass(frozen=True, kw_only=True)
class GridResult:
    """The K best distinct grid candidates (best first) and the grid that produced them."""

    states: FloatArray
    costs: FloatArray
    n_candidates: int
    speed_min: float

    @property
    def best(self) -> FloatArray:
        """The candidate with the least cost (the paper's :math:`\\hat{\\mathbf x}_0^0`)."""
        return self.states[0]

    def transformed(self, frame: Frame, *, to_world: bool) -> GridResult:
        """The candidates moved out of (``to_world``) or into ``frame``'s local coordinates."""
        states = frame.states_to_world(self.states) if to_world else frame.states_to_local(self.states)
        return replace(self, states=states)


def _product_costs(
    geometry: Geometry,
    times: StackedTimes,
    z: FloatArray,
    w: FloatArray,
    pos: FloatArray,
    vel: FloatArray,
    chunk: int,
    huber_k: float | None = None,
) -> FloatArray:
    r"""Costs ``(n_pos, n_vel)`` of every (initial position, velocity) combination.

    For a sensor :math:`\mathbf s` let :math:`\mathbf a = \mathbf p_0 - \mathbf s`
    and :math:`U = \mathbf a\cdot\mathbf v` (independent of time).  Along the
    constant-velocity trajectory the range rate at time :math:`t` is

    .. math:: \dot r = \frac{U + t s^2}{\sqrt{\lVert\mathbf a\rVert^2 + 2tU + t^2 s^2}},\qquad s^2 = \lVert\mathbf v\rVert^2,

    so each position and sensor need one dot product per velocity, and each
    measurement a handful of element-wise operations.  Positions are processed
    ``chunk // n_vel`` at a time; the arithmetic per element does not depend
    on the chunking, so results are identical for any chunk.

    A term :math:`\dot r` depends on the sensor and the time only, so where
    several pairs share a sensor and measure at the same instant (one
    transmitter seen by several receivers, as in the paper's case a with its
    shared receiver) it is computed once per candidate and read by every
    measurement that needs it (:data:`SHARE_TERMS`); the sums are taken in
    the same order, so the costs are the same to the bit.  With one
    transmitter and four synchronous receivers this takes the grid from 4 × 2
    to 4 + 1 terms per instant.  The offsets, the dot products, the terms and
    the sum over the measurements run in one compiled loop
    (:mod:`fgdoppler.estimators.grid_kernels`), one pass per position instead
    of numpy's pass per operation over arrays of positions × sensors ×
    velocities.
    """
    d = pos.shape[1]
    sensors, plan = _term_plan(geometry, times, d)
    s2 = _squared_speed(vel)
    out = np.empty((pos.shape[0], vel.shape[0]))
    step = max(1, chunk // max(1, vel.shape[0]))
    for start in range(0, pos.shape[0], step):
        acc = _chunk_costs(pos[start:start + step], sensors, vel, s2, False, plan, z, w, huber_k)
        acc[~np.isfinite(acc)] = np.inf
        out[start:start + step] = acc
    return out


def _pair_costs(geometry: Geometry, times: StackedTimes, z: FloatArray, w: FloatArray, pos: FloatArray,
                vel: FloatArray, chunk: int, huber_k: float | None = None) -> FloatArray:
    """Costs ``(n,)`` of the candidates ``(pos[i], vel[i])``: :func:`_product_costs`'s arithmetic, to the bit."""
    d = pos.shape[1]
    sensors, plan = _term_plan(geometry, times, d)
    s2 = _squared_speed(vel)
    out = np.empty(pos.shape[0])
    for start in range(0, pos.shape[0], max(1, chunk)):
        sl = slice(start, start + max(1, chunk))
        acc = _chunk_costs(pos[sl], sensors, vel[sl], s2[sl], True, plan, z, w, huber_k)[:, 0]
        acc[~np.isfinite(acc)] = np.inf
        out[sl] = acc
    return out


@dataclass(frozen=True, kw_only=True)
class _TermPlan:
    """The distinct (sensor, time) terms of a window and each measurement's transmitter and receiver term."""

    sensor: NDArray[np.intp]
    time: FloatArray
    tx: NDArray[np.intp]
    rx: NDArray[np.intp]


def _term_plan(geometry: Geometry, times: StackedTimes, d: int) -> tuple[FloatArray, _TermPlan]:
    """The distinct sensors and the window's terms among them (:data:`SHARE_TERMS`)."""
    sensors, inverse = np.unique(np.vstack(geometry.positions(d)), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    sensor = np.concatenate([inverse[times.pair], inverse[geometry.n_pairs + times.pair]])
    time = np.concatenate([times.t, times.t])
    if SHARE_TERMS:
        # a transmitter seen by several receivers at one instant (or a receiver shared by several transmitters)
        # needs its term once
        key, index = np.unique(np.stack([sensor.astype(float), time]), axis=1, return_inverse=True)
        index = index.reshape(-1)
        return sensors, _TermPlan(sensor=key[0].astype(np.intp), time=key[1], tx=index[:times.size],
                                  rx=index[times.size:])
    every = np.arange(sensor.size, dtype=np.intp)
    return sensors, _TermPlan(sensor=sensor.astype(np.intp), time=time, tx=every[:times.size], rx=every[times.size:])


def _squared_speed(vel: FloatArray) -> FloatArray:
    s2 = vel[:, 0] ** 2 + vel[:, 1] ** 2
    return s2 + vel[:, 2] ** 2 if vel.shape[1] == 3 else s2


def _chunk_costs(pos: FloatArray, sensors: FloatArray, vel: FloatArray, s2: FloatArray, per_position: bool,
                 plan: _TermPlan, z: FloatArray, w: FloatArray, huber_k: float | None) -> FloatArray:
    """:func:`_product_costs` for one chunk of positions ``(P, d)`` against every velocity ``(V, d)``, or with
    ``per_position`` each position with its own velocity (the result ``(P, 1)``), in the compiled loop of
    :func:`fgdoppler.estimators.grid_kernels.window_costs`.

    No per-element guard: a trajectory through a sensor makes the root 0 (or NaN for a round-off negative) and
    its cost inf or NaN, mapped to inf once by the caller.
    """
    from fgdoppler.estimators.grid_kernels import window_costs

    return window_costs(pos, sensors, vel, s2, per_position, plan.sensor, plan.time, plan.tx, plan.rx, z, w,
                        huber_k)


def grid_search(
    geometry: Geometry,
    times: StackedTimes,
    doppler: ArrayLike,
    sigma: ArrayLike,
    zone: Zone,
    spec: GridSpec | None = None,
    *,
    k_best: int = 5,
    half_plane: HalfPlane | None = None,
    chunk: int = 16384,
    huber_k: float | None = None,
) -> GridResult:
    """Score the whole grid over ``zone`` and return the ``k_best`` best local minima.

    Parameters
    ----------
    geometry, times, doppler, sigma
        The measurement window: times relative to the initial state's time.
    zone
        Where the candidates lie (positions and speeds), in its frame; a
        3-D zone adds the altitude levels of :meth:`GridSpec.levels`.
    spec
        Resolution (default: the rule of the module docstring).
    k_best
        How many distinct candidates to return.
    half_plane
        If given, candidates outside it are excluded.
    chunk
        Candidates per vectorised evaluation (bounds memory).
    huber_k
        Score with the Huber loss (:func:`huber_rho`) instead of squares.

    Raises
    ------
    ValueError
        If the data's speed lower bound exceeds the zone's speed bound, or no
        candidate has a finite cost.
    """
    spec = spec or GridSpec()
    if k_best < 1:
        raise ValueError(f"k_best must be >= 1, got {k_best}")
    z = np.asarray(doppler, dtype=float)
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), z.shape)
    s_min = speed_lower_bound(z, sig, spec.n_sigma)
    extent = float(np.ptp(zone.frame.points_to_local(geometry.sensors())[:, 0]))
    if half_plane is not None and zone.dim == 3:
        raise ValueError(THREE_D_REFUSAL)
    us, vs, speeds, headings = spec.axes(zone, extent, s_min)
    ws = spec.levels(zone)
    pos_axes = (us, vs) if zone.dim == 2 else (us, vs, ws)
    shape = (*(a.size for a in pos_axes), speeds.size, headings.size)
    n = int(np.prod(shape))
    local = np.stack(np.meshgrid(*pos_axes, indexing="ij"), axis=-1)
    P = zone.frame.points_to_world(local.reshape(-1, zone.dim))
    V = np.stack(np.meshgrid(speeds, headings, indexing="ij"), axis=-1).reshape(-1, 2)
    V = np.stack([V[:, 0] * np.sin(V[:, 1]), V[:, 0] * np.cos(V[:, 1])], axis=-1)
    if zone.dim == 3:  # level flight in the zone's frame
        V = np.column_stack([V, np.zeros(len(V))])
    V = zone.frame.vectors_to_world(V)
    allowed = None
    if half_plane is not None:
        pos_ok = half_plane.contains(P).reshape(us.size, vs.size)
        allowed = np.broadcast_to(pos_ok[:, :, None, None], shape).reshape(-1)
    # The heading axis wraps around only if the grid covers the full circle.
    full_circle = np.isclose((headings[-1] - headings[0]) + (headings[1] - headings[0] if headings.size > 1 else 0),
                             2 * np.pi)
    modes = ["nearest"] * (len(shape) - 1) + ["wrap" if full_circle else "nearest"]
    flat, cost = _best_minima(_Scorer(geometry=geometry, times=times, z=z, w=1.0 / sig, pos=P, vel=V, chunk=chunk,
                                      huber_k=huber_k), shape, modes, k_best, allowed)
    if flat.size == 0:
        raise ValueError("no grid candidate has a finite cost (all excluded or singular)")
    return GridResult(
        states=_states_from_axes(zone, us, vs, ws, speeds, headings, flat),
        costs=cost,
        n_candidates=n,
        speed_min=float(speeds[0]),
    )


@dataclass(frozen=True, kw_only=True)
class _Scorer:
    """Scores grid candidates (flat index ``i_pos * n_vel + i_vel``) on a window, or on part of it."""

    geometry: Geometry
    times: StackedTimes
    z: FloatArray
    w: FloatArray
    pos: FloatArray
    vel: FloatArray
    chunk: int
    huber_k: float | None

    def all(self) -> FloatArray:
        """Every candidate's cost, flat."""
        return _product_costs(self.geometry, self.times, self.z, self.w, self.pos, self.vel, self.chunk,
                              self.huber_k).reshape(-1)

    def some(self, flat: NDArray[np.intp]) -> FloatArray:
        """The costs of the candidates ``flat``, the same numbers as :meth:`all` gives them."""
        n_vel = self.vel.shape[0]
        return _pair_costs(self.geometry, self.times, self.z, self.w, self.pos[flat // n_vel],
                           self.vel[flat % n_vel], self.chunk, self.huber_k)

    def parts(self) -> list[_Scorer] | None:
        """The same candidates on :data:`PRUNE_STRIDE` disjoint parts of the measurements that together are all of
        them (``None`` when the window is too short for that to pay).

        The first part is about one measurement in :data:`PRUNE_STRIDE` of each pair, evenly spread in time and
        including each pair's first and last; each pair's other measurements are dealt in time order to the
        other parts in turn, so every part spans the window.
        """
        if self.times.size < 2 * PRUNE_STRIDE:
            return None
        label = np.empty(self.times.size, dtype=np.intp)
        for pair in np.unique(self.times.pair):
            idx = np.flatnonzero(self.times.pair == pair)
            idx = idx[np.argsort(self.times.t[idx], kind="stable")]
            n = -(-idx.size // PRUNE_STRIDE)
            first = np.zeros(idx.size, dtype=bool)
            first[np.unique(np.round(np.linspace(0, idx.size - 1, n)).astype(np.intp))] = True
            label[idx[first]] = 0
            label[idx[~first]] = 1 + np.arange(np.count_nonzero(~first)) % (PRUNE_STRIDE - 1)
        return [self._subset(np.flatnonzero(label == k)) for k in range(PRUNE_STRIDE) if np.any(label == k)]

    def _subset(self, sub: NDArray[np.intp]) -> _Scorer:
        return replace(self, times=StackedTimes(pair=self.times.pair[sub], t=self.times.t[sub]), z=self.z[sub],
                       w=self.w[sub])


def _local_minima(cost: FloatArray, shape: tuple[int, ...], modes: list[str]) -> NDArray[np.intp]:
    """Flat indices of the finite candidates no worse than any grid neighbour (3 per axis), ascending."""
    cube = cost.reshape(shape)
    return np.flatnonzero(((cube == minimum_filter(cube, size=3, mode=modes)) & np.isfinite(cube)).reshape(-1))


def _scored_minima(cost: FloatArray, shape: tuple[int, ...], modes: list[str],
                   scored: NDArray[np.intp]) -> NDArray[np.intp]:
    """:func:`_local_minima` where only the candidates ``scored`` have a finite cost: their neighbours compared in
    the compiled loop (:func:`fgdoppler.estimators.grid_kernels.minima_among`) while they are few, the filter
    over the whole grid once that costs less (:data:`NEIGHBOUR_TEST_WORK`)."""
    from fgdoppler.estimators.grid_kernels import minima_among

    if scored.size * 3 ** len(shape) >= NEIGHBOUR_TEST_WORK * len(shape) * cost.size:
        return _local_minima(cost, shape, modes)
    return np.sort(scored[minima_among(cost, shape, modes[-1] == "wrap", scored)])


def _best_minima(scorer: _Scorer, shape: tuple[int, ...], modes: list[str], k_best: int,
                 allowed: NDArray[np.bool_] | None) -> tuple[NDArray[np.intp], FloatArray]:
    r"""The ``k_best`` lowest local minima of the grid's cost (flat indices, best first) and their costs.

    Exactly those of the whole grid scored on every measurement, without
    scoring all of it.  The cost is a sum of non-negative terms, so its sum
    :math:`b_i` over part of the measurements (:meth:`_Scorer.parts`) bounds it
    from below.  The candidates with the lowest bounds are scored in full
    (:data:`PRUNE_FIRST_SHARE` of the grid); with :math:`\tau` the lowest bound
    of those not scored, every unscored candidate costs at least
    :math:`\tau`.  Giving them an infinite cost changes no comparison
    with a candidate of cost below :math:`\tau`, and every candidate of cost
    below :math:`\tau` has been scored: so the local minima below
    :math:`\tau` (less :data:`PRUNE_MARGIN` for rounding) are exactly the
    whole grid's.  When fewer than ``k_best`` lie below it, the bounds are
    tightened (:func:`_tighten`): with :math:`T` the ``k_best``-th lowest
    minimum found so far, each unscored candidate with :math:`b_i < T` adds
    the next part's sum, part after part, while :math:`b_i < T` — the sum
    over more of the data bounds the cost as well, and far more closely
    where a few large residuals (outliers) fall outside the first part — and
    the next batch, of the same size, is taken by the tightened bounds; when
    no bound changes, the batch doubles, up to the whole grid.  On the
    paper's windows and the trackers' restart checks 0.0-1.8 % of the
    candidates have a first-part bound below the ``k_best``-th minimum's
    cost; on a restart check's window with 5 % outliers of 100 σ under the
    Huber loss up to 98 %, and only a few hundred after tightening.  The
    local minima among the scored candidates are found by their neighbours
    alone (:func:`_scored_minima`).
    """
    n = int(np.prod(shape))
    parts = scorer.parts()
    if parts is None:
        cost = scorer.all()
        if allowed is not None:
            cost[~allowed] = np.inf
        return _lowest(_local_minima(cost, shape, modes), cost, k_best)
    bound = parts[0].all()
    if allowed is not None:
        bound[~allowed] = np.inf
    rest = np.flatnonzero(np.isfinite(bound))  # an infinite bound is an infinite cost: never scored
    cost = np.full(n, np.inf)
    scored = rest[:0]
    batch = max(k_best, int(np.ceil(PRUNE_FIRST_SHARE * n)))
    depth: NDArray[np.intp] | None = None  # how many parts each bound sums, once any is tightened
    while True:
        if batch < rest.size:
            # the batch lowest bounds first, the lowest of the others at the split (no full sort: it costs
            # more than the scoring)
            split = np.argpartition(bound[rest], batch)
            now, rest = rest[split[:batch]], rest[split[batch:]]
            tau = bound[rest[0]] * (1.0 - PRUNE_MARGIN)
        else:
            now, rest, tau = rest, rest[:0], np.inf
        cost[now] = scorer.some(now)
        scored = np.concatenate([scored, now[np.isfinite(cost[now])]])
        flat = _scored_minima(cost, shape, modes, scored)
        below = flat[cost[flat] < tau]
        if below.size >= k_best or rest.size == 0:
            return _lowest(below, cost, k_best)
        limit = float(np.partition(cost[flat], k_best - 1)[k_best - 1]) if flat.size >= k_best else np.inf
        if depth is None:
            depth = np.ones(n, dtype=np.intp)
        if not _tighten(bound, depth, rest, parts, limit):
            batch *= 2


def _tighten(bound: FloatArray, depth: NDArray[np.intp], rest: NDArray[np.intp], parts: list[_Scorer],
             limit: float) -> bool:
    """Add to ``bound`` (in place) the next part's sum, part after part, for the candidates ``rest`` whose bound is
    still below ``limit`` (``depth`` counts the parts each bound sums); whether any bound changed.

    A bound at or above ``limit`` is not tightened: no work is spent where the bound already does its job.
    """
    changed = False
    if not np.isfinite(limit):
        return changed
    for k in range(1, len(parts)):
        live = rest[(depth[rest] == k) & (bound[rest] < limit)]
        if live.size:
            # scoring the whole grid in the product form costs less per candidate than picking
            bound[live] += parts[k].all()[live] if 2 * live.size > bound.size else parts[k].some(live)
            depth[live] = k + 1
            changed = True
    return changed


def _lowest(flat: NDArray[np.intp], cost: FloatArray, k: int) -> tuple[NDArray[np.intp], FloatArray]:
    """The ``k`` of the candidates ``flat`` with the lowest costs, best first (ties: lower index first), and those costs."""
    flat = flat[np.argsort(cost[flat], kind="stable")][:k]
    return flat, cost[flat]
