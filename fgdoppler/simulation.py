"""Scenarios and measurement simulation, including the paper's six test trajectories.

The paper (Section 5) simulates targets starting at (5 | 25 | 45 km, 2 km) with
velocity (10, -100) m/s for 30 s, sampled every 0.5 s, with Doppler noise
σ = 1 m/s for both pairs.  In case (a) one receiver serves both pairs, so the
two pairs are synchronous.  In case (b) the two receivers are "not necessarily
time synchronized"; the paper gives no offset, so :func:`paper_scenario` uses
half a sampling interval (0.25 s) for pair 2 — the largest possible stagger,
which makes every measurement time distinct.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._io import atomic_write_text
from fgdoppler._text import time_text
from fgdoppler.geometry import Geometry, paper_geometry
from fgdoppler.measurements import MeasurementError, Measurements
from fgdoppler.models.doppler import bistatic_doppler
from fgdoppler.models.motion import ConstantVelocity

__all__ = [
    "PAPER_CASE_B_OFFSET",
    "PAPER_START_X",
    "Manoeuvre",
    "Scenario",
    "Simulation",
    "Trajectory",
    "paper_scenario",
    "paper_scenarios",
    "simulate",
]

#: Truth CSV header per spatial dimension.
TRUTH_HEADERS: dict[int, tuple[str, ...]] = {2: ("time", "x", "y", "vx", "vy"),
                                             3: ("time", "x", "y", "z", "vx", "vy", "vz")}

#: Start x-positions (m) of the paper's three trajectories per case.
PAPER_START_X: tuple[float, float, float] = (5e3, 25e3, 45e3)
#: Time offset (s) of pair 2 in case (b), our choice (the paper gives none).
PAPER_CASE_B_OFFSET = 0.25


@dataclass(frozen=True, kw_only=True)
class Trajectory:
    """States ``(n, 4)`` (2-D) or ``(n, 6)`` (3-D) at times ``(n,)``: the truth of a simulation or an estimate."""

    times: NDArray[np.float64]
    states: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=float).reshape(-1)
        raw = np.asarray(self.states, dtype=float)
        width = raw.shape[-1] if raw.ndim == 2 else 4
        if width not in (4, 6):
            raise ValueError(f"states must have 4 (2-D) or 6 (3-D) columns, got {width}")
        x = raw.reshape(-1, width) if raw.size else np.zeros((0, width))
        if x.shape[0] != t.size:
            raise ValueError(f"{t.size} times but {x.shape[0]} states")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "states", x)

    def at(self, times: ArrayLike) -> NDArray[np.float64]:
        """States at the given times (which must be among ``self.times``)."""
        idx, on = self._on_grid(times)
        if not np.all(on):
            raise ValueError("requested times are not on the trajectory's time grid")
        return self.states[idx]

    def _on_grid(self, times: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """The index of the truth time nearest to each of ``times``, and whether it is that time.

        The same time to 1 ns, or to a few units in the last place where a clock's
        seconds are large (Unix seconds: one unit is 0.24 µs at 1.7e9 s), so that
        times written by another program with other rounding still match.
        """
        t = np.asarray(times, dtype=float)
        right = np.clip(np.searchsorted(self.times, t), 0, self.times.size - 1)
        left = np.clip(right - 1, 0, self.times.size - 1)
        idx = np.where(np.abs(self.times[left] - t) < np.abs(self.times[right] - t), left, right)
        return idx, np.abs(self.times[idx] - t) <= np.maximum(1e-9, 8.0 * np.spacing(np.abs(t)))

    @property
    def dim(self) -> int:
        """Spatial dimension (2 or 3)."""
        return int(self.states.shape[1]) // 2

    def csv_text(self) -> str:
        """The ``time,x,y,vx,vy`` (3-D: ``time,x,y,z,vx,vy,vz``) CSV as text; values round-trip exactly."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(TRUTH_HEADERS[self.dim])
        for t, s in zip(self.times, self.states, strict=True):
            w.writerow((repr(float(t)), *(repr(float(v)) for v in s)))
        return buf.getvalue()

    def to_csv(self, path: str | Path) -> None:
        """Write :meth:`csv_text` atomically."""
        atomic_write_text(Path(path), self.csv_text())

    @classmethod
    def from_csv(cls, path: str | Path) -> Trajectory:
        """Read a truth CSV ``time,x,y,vx,vy`` or ``time,x,y,z,vx,vy,vz``, columns in any order (strict:
        :mod:`fgdoppler.csvfile`); times strictly increasing.

        Raises
        ------
        MeasurementError
            Naming the file and the line.
        """
        from fgdoppler.csvfile import CSVError, header_names, read_table

        dim = 2
        try:
            dim = 3 if {"z", "vz"} & set(header_names(path)) else 2  # the form the file's columns ask for
            table = read_table(path, header=TRUTH_HEADERS[dim], what="truth file")
        except CSVError as exc:
            other = f" (a {5 - dim}-D truth has {','.join(TRUTH_HEADERS[5 - dim])})" if "bad header" in str(exc) else ""
            raise MeasurementError(f"{exc}{other}") from None
        t = table.values[:, 0]
        back = np.flatnonzero(np.diff(t) <= 0)
        if back.size:
            raise MeasurementError(f"{table.where(int(back[0]) + 1)}: time {t[back[0] + 1]} is not after the "
                                   f"previous row's {t[back[0]]}; truth rows must be in increasing time order")
        return cls(times=t.copy(), states=table.values[:, 1:].copy())

    def check_covers(self, times: ArrayLike, source: str) -> None:
        """Raise :class:`MeasurementError` naming ``source`` unless every one of ``times`` is a truth time."""
        t = np.asarray(times, dtype=float)
        missing = np.flatnonzero(~self._on_grid(t)[1])
        if missing.size:
            raise MeasurementError(f"{source}: no truth at t = {time_text(t[missing[0]])} s ({missing.size} measurement "
                                   "time(s) missing): the truth must have a row at every measurement time")


@dataclass(frozen=True, kw_only=True)
class Manoeuvre:
    r"""A deterministic manoeuvre of the simulated target: from ``onset`` on it turns and changes speed.

    Before ``onset`` the target moves at constant velocity; from it on, with
    :math:`\tau = t - t_{on}`, its (horizontal) speed and heading are

    .. math:: v(\tau) = v_0 + a\tau, \qquad h(\tau) = h_0 + \omega\tau,

    heading clockwise from +y as everywhere (:math:`\dot x = v \sin h`,
    :math:`\dot y = v \cos h`), so a positive ``turn_rate_deg`` turns right
    seen from above.  The position is the integral in closed form: with
    :math:`\theta = \omega\tau`,

    .. math:: \begin{aligned}
              x(\tau) - x_0 &= v_0\tau\,(g_0 \sin h_0 + g_1 \cos h_0)
                             + a\tau^2 (f_1 \sin h_0 + f_2 \cos h_0),\\
              y(\tau) - y_0 &= v_0\tau\,(g_0 \cos h_0 - g_1 \sin h_0)
                             + a\tau^2 (f_1 \cos h_0 - f_2 \sin h_0),
              \end{aligned}

    where :math:`g_0 = \sin\theta/\theta`, :math:`g_1 = (1 - \cos\theta)/\theta`,
    :math:`f_1 = (\theta\sin\theta + \cos\theta - 1)/\theta^2` and
    :math:`f_2 = (\sin\theta - \theta\cos\theta)/\theta^2` (the integrals of
    :math:`\cos\omega u`, :math:`\sin\omega u`, :math:`u\cos\omega u`,
    :math:`u\sin\omega u` over :math:`[0, \tau]`, scaled); below
    :math:`|\theta| = 10^{-2}` their Taylor series replace them, so a
    straight line (:math:`\omega = 0`: :math:`g_0 = 1`, :math:`f_1 = 1/2`,
    :math:`g_1 = f_2 = 0`) and a barely turning target agree without
    cancellation.  In 3-D the horizontal velocity turns and changes speed;
    the vertical velocity stays.

    Parameters
    ----------
    onset
        When the manoeuvre starts (s).
    turn_rate_deg
        Turn rate (degrees per second, positive clockwise seen from above).
    acceleration
        Rate of change of the horizontal speed (m/s²; negative slows down).
    """

    onset: float = 0.0
    turn_rate_deg: float = 0.0
    acceleration: float = 0.0

    def __post_init__(self) -> None:
        for name in ("onset", "turn_rate_deg", "acceleration"):
            v = float(getattr(self, name))
            if not np.isfinite(v):
                raise ValueError(f"Manoeuvre.{name} must be finite, got {v}")
            object.__setattr__(self, name, v)
        if self.onset < 0:
            raise ValueError(f"Manoeuvre.onset must be >= 0 (s after the start), got {self.onset}")

    def states(self, x0: ArrayLike, times: ArrayLike) -> NDArray[np.float64]:
        """True states ``(n, 2d)`` at ``times`` from the start state ``x0`` at time 0.

        Raises
        ------
        ValueError
            If the target is stopped at the onset while it should turn or
            change speed, or its speed would fall to zero before the last
            time (a negative ``acceleration`` too strong for the duration).
        """
        x = np.asarray(x0, dtype=float).reshape(-1)
        t = np.asarray(times, dtype=float).reshape(-1)
        d = x.size // 2
        out = np.concatenate([x[:d] + t[:, None] * x[d:], np.broadcast_to(x[d:], (t.size, d))], axis=1)
        tau = t - self.onset
        on = tau > 0
        if not np.any(on) or (self.turn_rate_deg == 0.0 and self.acceleration == 0.0):
            return out
        p0 = x[:2] + self.onset * x[d:d + 2]
        v0 = float(np.hypot(x[d], x[d + 1]))
        if v0 == 0.0:
            raise ValueError("a stopped target cannot turn or change speed along its heading")
        h0 = float(np.arctan2(x[d], x[d + 1]))
        tau = tau[on]
        v = v0 + self.acceleration * tau
        if np.any(v <= 0.0):
            raise ValueError(f"the manoeuvre's acceleration {self.acceleration:g} m/s^2 stops the target "
                             f"{v0 / -self.acceleration:g} s after its onset, before the last time")
        w = np.deg2rad(self.turn_rate_deg)
        h = h0 + w * tau
        g0, g1, f1, f2 = _turn_integrals(w * tau)
        sin0, cos0 = np.sin(h0), np.cos(h0)
        a = self.acceleration
        pos = np.column_stack([
            p0[0] + v0 * tau * (g0 * sin0 + g1 * cos0) + a * tau**2 * (f1 * sin0 + f2 * cos0),
            p0[1] + v0 * tau * (g0 * cos0 - g1 * sin0) + a * tau**2 * (f1 * cos0 - f2 * sin0)])
        out[on, 0:2] = pos
        out[on, d:d + 2] = np.column_stack([v * np.sin(h), v * np.cos(h)])
        if d == 3:
            out[on, 2] = x[2] + t[on] * x[5]
        return out


def _turn_integrals(theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """:math:`g_0, g_1, f_1, f_2` of :class:`Manoeuvre` at ``theta``, by their Taylor series where it is small."""
    th = np.asarray(theta, dtype=float)
    small = np.abs(th) < 1e-2
    t = np.where(small, 1.0, th)  # the closed forms only where they do not cancel
    s, c = np.sin(t), np.cos(t)
    t2 = th * th
    g0 = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, s / t)
    g1 = np.where(small, th * (0.5 - t2 / 24.0 + t2 * t2 / 720.0), (1.0 - c) / t)
    f1 = np.where(small, 0.5 - t2 / 8.0 + t2 * t2 / 144.0, (t * s + c - 1.0) / (t * t))
    f2 = np.where(small, th * (1.0 / 3.0 - t2 / 30.0 + t2 * t2 / 840.0), (s - t * c) / (t * t))
    return g0, g1, f1, f2


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """A simulated encounter: geometry, initial truth, sampling and noise.

    Parameters
    ----------
    geometry
        Sensor pairs.
    x0
        True state at time 0: ``[x, y, vx, vy]``, or ``[x, y, z, vx, vy, vz]``
        for a 3-D geometry (:attr:`~fgdoppler.geometry.Geometry.dim`).
    duration, dt
        Pair ``i`` measures at ``offset_i + k dt`` for all ``k >= 0`` up to ``duration``.
    sigma
        Doppler noise standard deviation (m/s), one value or one per pair.
    time_offsets
        Per-pair time offsets (s) for asynchronous receivers; default all 0.
    process_noise
        If given, the truth follows this NCV model with random accelerations;
        otherwise it moves at exactly constant velocity (the paper's truth).
    manoeuvre
        If given, the truth turns and changes speed from its onset on
        (:class:`Manoeuvre`; not together with ``process_noise``).
    bias
        Constant offset (m/s) added to every measurement of a pair — an
        uncalibrated frequency offset — one value or one per pair; the
        declared ``sigma`` does not include it (default 0: none).  The
        ``bias_sigma`` of the smoother's, the EKF's, iSAM2's and the
        fixed-lag smoother's settings accounts for offsets of unknown size
        in their covariances; that of the particle estimators' integrates
        them out of their likelihood.
    clock_error
        Per-pair clock error (s): pair ``i``'s measurement of true time
        ``t`` is recorded at time ``t + clock_error_i`` (a receiver whose
        clock runs late, or stamps its values differently), one value or one
        per pair; default 0: every pair on the one true clock, which the
        trackers assume.  The ``clock_sigma`` of the smoother's, the EKF's,
        iSAM2's and the fixed-lag smoother's settings accounts for errors of
        unknown size in their covariances.
    site_error
        Where the sensors truly are: site ``s``
        (:meth:`~fgdoppler.geometry.Geometry.sites`, the order the pairs
        first name them) sits ``site_error[s]`` metres off the geometry's
        position, ``dim`` numbers per site (``(n_sites, dim)`` or flat,
        site-major); ``()`` (default): every site where the geometry puts
        it, which the trackers assume.  The measurements are those of the
        moved sites; the scenario's geometry stays the declared one.  The
        ``site_sigma`` of every estimator's settings accounts for errors of
        unknown size in their covariances.
    name
        Label used in reports.
    """

    geometry: Geometry
    x0: tuple[float, ...]
    duration: float = 30.0
    dt: float = 0.5
    sigma: float | tuple[float, ...] = 1.0
    time_offsets: tuple[float, ...] | None = None
    process_noise: ConstantVelocity | None = None
    manoeuvre: Manoeuvre | None = None
    bias: float | tuple[float, ...] = 0.0
    clock_error: float | tuple[float, ...] = 0.0
    site_error: tuple[float, ...] | tuple[tuple[float, ...], ...] = ()
    name: str = ""
    _sigmas: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _biases: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _clock_errors: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _offsets: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        x0 = tuple(float(v) for v in np.asarray(self.x0, dtype=float).reshape(-1))
        want = self.geometry.state_dim
        if len(x0) not in (4, 6) or not np.all(np.isfinite(x0)):
            raise ValueError(f"x0 must be 4 finite numbers [x, y, vx, vy] or 6 [x, y, z, vx, vy, vz], got {self.x0}")
        if len(x0) != want:
            hint = ("give the geometry an altitude band (TOML [zone] altitude, --altitude) or sensors with z"
                    if want == 4 else "give a 3-D start [x, y, z, vx, vy, vz] (--start-z, --velocity VX VY VZ)")
            raise ValueError(f"x0 is {len(x0) // 2}-D but the geometry is {want // 2}-D: {hint}")
        object.__setattr__(self, "x0", x0)
        if not (self.dt > 0 and np.isfinite(self.dt)):
            raise ValueError(f"dt must be > 0, got {self.dt}")
        if not (self.duration >= 0 and np.isfinite(self.duration)):
            raise ValueError(f"duration must be >= 0, got {self.duration}")
        n = self.geometry.n_pairs
        sig_in = np.asarray(self.sigma, dtype=float).reshape(-1)
        if sig_in.size not in (1, n):
            raise ValueError(f"sigma must be one value or one per pair ({n}), got {sig_in.size} values")
        sig = np.broadcast_to(sig_in, (n,)).copy()
        if not np.all(np.isfinite(sig) & (sig > 0)):
            raise ValueError(f"sigma must be > 0, got {self.sigma}")
        off = np.zeros(n) if self.time_offsets is None else np.asarray(self.time_offsets, dtype=float)
        if off.shape != (n,) or not np.all(np.isfinite(off)) or np.any(off < 0):
            raise ValueError(f"time_offsets must be {n} finite non-negative numbers, got {self.time_offsets}")
        bias = np.asarray(self.bias, dtype=float).reshape(-1)
        if bias.size not in (1, n) or not np.all(np.isfinite(bias)):
            raise ValueError(f"bias must be one finite value or one per pair ({n}) in m/s, got {self.bias}")
        object.__setattr__(self, "_biases", np.broadcast_to(bias, (n,)).copy())
        clock = np.asarray(self.clock_error, dtype=float).reshape(-1)
        if clock.size not in (1, n) or not np.all(np.isfinite(clock)):
            raise ValueError(f"clock_error must be one finite value or one per pair ({n}) in s, got {self.clock_error}")
        object.__setattr__(self, "_clock_errors", np.broadcast_to(clock, (n,)).copy())
        sites = np.asarray(self.site_error, dtype=float)
        if sites.size:
            self.geometry.with_sites_moved(sites)  # the count and finiteness are said now, in its words
            object.__setattr__(self, "site_error", tuple(float(v) for v in sites.reshape(-1)))
        else:
            object.__setattr__(self, "site_error", ())
        if self.manoeuvre is not None and self.process_noise is not None and self.process_noise.q > 0:
            raise ValueError("a scenario takes a manoeuvre or process noise, not both")
        if self.manoeuvre is not None:
            self.manoeuvre.states(x0, [self.duration])  # a deceleration that stops the target: said now
        object.__setattr__(self, "_sigmas", sig)
        object.__setattr__(self, "_offsets", off)

    @property
    def sigmas(self) -> NDArray[np.float64]:
        """Noise standard deviation per pair, shape ``(n_pairs,)``."""
        return self._sigmas.copy()

    @property
    def biases(self) -> NDArray[np.float64]:
        """Constant Doppler offset per pair (m/s), shape ``(n_pairs,)``."""
        return self._biases.copy()

    @property
    def site_errors(self) -> NDArray[np.float64]:
        """How far each site truly is from the geometry's position (m), shape ``(n_sites, dim)`` (zeros without
        ``site_error``)."""
        positions = self.geometry.sites()[0]
        return (np.asarray(self.site_error, dtype=float).reshape(positions.shape) if self.site_error
                else np.zeros(positions.shape))

    @property
    def true_geometry(self) -> Geometry:
        """The geometry with every site where it truly is (``site_error``; the geometry itself without it)."""
        return self.geometry.with_sites_moved(self.site_errors) if self.site_error else self.geometry

    @property
    def clock_errors(self) -> NDArray[np.float64]:
        """Clock error per pair (s; recorded time less true time), shape ``(n_pairs,)``."""
        return self._clock_errors.copy()

    def measurement_times(self) -> list[NDArray[np.float64]]:
        """Measurement times of each pair."""
        out = []
        for off in self._offsets:
            k = np.arange(int(np.floor((self.duration - off) / self.dt + 1e-9)) + 1)
            out.append(off + k * self.dt)
        return out

    def truth_times(self) -> NDArray[np.float64]:
        """All distinct measurement times, true and as recorded (``clock_error``), sorted (where the truth is
        reported)."""
        taken = self.measurement_times()
        return np.unique(np.concatenate([*taken, *(t + c for t, c in zip(taken, self._clock_errors, strict=True))]))


@dataclass(frozen=True, kw_only=True)
class Simulation:
    """Output of :func:`simulate`: noisy measurements and the true trajectory."""

    scenario: Scenario
    measurements: Measurements
    truth: Trajectory


def simulate(scenario: Scenario, rng: np.random.Generator) -> Simulation:
    """Simulate the truth and noisy Doppler measurements of a scenario.

    Parameters
    ----------
    scenario
        What to simulate.
    rng
        The only source of randomness.

    Returns
    -------
    Simulation
        Measurements ``z = h(x(t)) + b_i + w``, ``w ~ N(0, sigma_i^2)`` (``b_i``
        the scenario's ``bias`` of pair ``i``; ``h`` of the sites where they
        truly are, its ``site_error``), recorded at ``t + c_i`` (``c_i`` its
        ``clock_error``), and the truth at every true and every recorded
        measurement time.
    """
    times = scenario.truth_times()
    x0 = np.asarray(scenario.x0)
    d = x0.size // 2
    if scenario.process_noise is None or scenario.process_noise.q == 0:
        # constant velocity is the manoeuvre that never turns or changes speed
        states = (scenario.manoeuvre or Manoeuvre()).states(x0, times)
    else:
        # before t = 0 (a clock running early) the truth has no noise
        states = replace(scenario.process_noise, dim=d).sample_track(x0, times, rng)
    truth = Trajectory(times=times, states=states)
    per_pair = scenario.measurement_times()
    t_all = np.concatenate(per_pair)
    p_all = np.concatenate([np.full(t.size, i, dtype=np.intp) for i, t in enumerate(per_pair)])
    order = np.lexsort((p_all, t_all))
    t_all, p_all = t_all[order], p_all[order]
    idx = np.searchsorted(times, t_all)
    clean = bistatic_doppler(states[idx], scenario.true_geometry)[np.arange(t_all.size), p_all]
    sig = scenario.sigmas[p_all]
    z = clean + sig * rng.standard_normal(t_all.size) + scenario.biases[p_all]
    recorded = t_all + scenario.clock_errors[p_all]
    order = np.lexsort((p_all, recorded))  # the identity without clock errors
    meas = Measurements(time=recorded[order], pair=p_all[order], doppler=z[order], sigma=sig[order])
    return Simulation(scenario=scenario, measurements=meas, truth=truth)


def paper_scenario(case: str, start_x: float, *, sigma: float = 1.0, altitude: float | None = None) -> Scenario:
    """One of the paper's six test trajectories (Section 5, Fig. 9).

    Start ``(start_x, 2 km)``, velocity ``(10, -100)`` m/s, 30 s sampled every
    0.5 s, σ = 1 m/s.  Case (b) staggers pair 2 by :data:`PAPER_CASE_B_OFFSET`.
    With ``altitude`` (m) the same track is flown level at that height over
    the same ground sensors: a 3-D problem (:meth:`~fgdoppler.geometry.Geometry.in_3d`,
    the default altitude band).
    """
    geom = paper_geometry(case)
    offsets = (0.0, PAPER_CASE_B_OFFSET) if geom.name == "b" else (0.0, 0.0)
    x0: tuple[float, ...] = (float(start_x), 2e3, 10.0, -100.0)
    name = f"case {geom.name}, start {start_x / 1e3:g} km"
    if altitude is not None:
        geom = geom.in_3d()
        x0 = (float(start_x), 2e3, float(altitude), 10.0, -100.0, 0.0)
        name += f", altitude {altitude / 1e3:g} km"
    return Scenario(
        geometry=geom,
        x0=x0,
        duration=30.0,
        dt=0.5,
        sigma=sigma,
        time_offsets=offsets,
        name=name,
    )


def paper_scenarios() -> list[Scenario]:
    """All six paper scenarios: cases (a), (b) × starts 5, 25, 45 km."""
    return [paper_scenario(c, x) for c in ("a", "b") for x in PAPER_START_X]
