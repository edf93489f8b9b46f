"""Shared pieces of the subcommands: user errors, JSON output, progress bars, executors."""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["CLIError", "emit_json", "executor", "progress_bar"]


class CLIError(Exception):
    """A user error: printed without a traceback, exit status 2."""


def emit_json(obj: Any) -> None:
    """Print ``obj`` as JSON on stdout (non-finite numbers as ``null``: strict JSON has no NaN)."""
    from fgdoppler.estimators.results import json_dumps

    sys.stdout.write(json_dumps(obj) + "\n")


def progress_bar(total: int, desc: str, unit: str = "state") -> Any:
    """A tqdm bar on stderr, shown only on a terminal."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not sys.stderr.isatty(), leave=False)


def executor(args: argparse.Namespace) -> tuple[Any, Any]:
    """(executor, client) for ``--scheduler`` (Dask distributed), or (None, None)."""
    if not getattr(args, "scheduler", None):
        return None, None
    try:
        from distributed import Client
    except ImportError as exc:
        raise CLIError("--scheduler needs the optional extra: pip install 'fgdoppler[distributed]'") from exc
    client = Client(args.scheduler)
    return client.get_executor(), client


# -- shared option groups --------------------------------------------------------------
def add_zone_options(p: argparse.ArgumentParser) -> None:
    """``--zone``, ``--speed-max``, ``--speed-step``, ``--grid-step``: the zone and the grid's resolution."""
    g = p.add_argument_group("zone (where a track may start; default: the geometry's rule and [zone] table)")
    g.add_argument("--zone", type=float, nargs=4, metavar=("ALONG_LO", "ALONG_HI", "ACROSS_LO", "ACROSS_HI"),
                   default=None, help="box in the sensors' frame in metres: along the first pair's baseline from "
                   "its receiver, and across it (overrides the geometry file's [zone])")
    g.add_argument("--speed-max", type=float, default=None, metavar="M/S",
                   help="largest target speed in m/s (default: the [zone] table's, else 200)")
    g.add_argument("--speed-step", type=float, default=None, metavar="M/S",
                   help="speed step of the initiation grid (default speed-max / 20)")
    g.add_argument("--grid-step", type=float, default=None, metavar="M",
                   help="position step of the initiation grid (default: the sensors' extent / 50, "
                   "coarsened to at most 2000 nodes)")
    g.add_argument("--altitude", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="height band above the sensors' plane in metres where a track may start; makes the "
                   "problem 3-D (states x, y, z, vx, vy, vz; default: the [zone] table's, else 2-D, or 0 to a "
                   "quarter of the sensors' extent for sensors given with z)")
    g.add_argument("--altitude-levels", type=int, default=4, metavar="N",
                   help="3-D only: heights the initiation grid tries, level flight at each (default 4)")


def zone_limits(args: argparse.Namespace) -> Any:
    """The :class:`~fgdoppler.zone.ZoneLimits` the zone options set (validated: bad values are a CLIError)."""
    from fgdoppler.zone import ZoneLimits

    try:
        return ZoneLimits(along=None if args.zone is None else tuple(args.zone[:2]),
                          across=None if args.zone is None else tuple(args.zone[2:]), speed_max=args.speed_max,
                          altitude=None if getattr(args, "altitude", None) is None else tuple(args.altitude))
    except ValueError as exc:
        raise CLIError(f"--zone/--speed-max/--altitude: {exc}") from None


def grid_spec(args: argparse.Namespace) -> Any:
    """The initiation grid's :class:`~fgdoppler.estimators.grid.GridSpec` from the options."""
    from fgdoppler.estimators.grid import GridSpec

    try:
        return GridSpec(position_step=args.grid_step, speed_step=args.speed_step,
                        altitude_levels=getattr(args, "altitude_levels", 4))
    except ValueError as exc:
        raise CLIError(f"--grid-step/--speed-step/--altitude-levels: {exc}") from None


def geometry_with_zone(spec: str, args: argparse.Namespace) -> Any:
    """A preset or TOML geometry with the zone options applied on top of its ``[zone]`` table."""
    from fgdoppler.geometry import resolve_geometry

    geometry = resolve_geometry(spec)
    limits = zone_limits(args)
    if limits.empty:
        return geometry
    moved = geometry.with_zone(geometry.zone_limits.merged(limits))
    try:
        moved.check_zone()
    except ValueError as exc:
        raise CLIError(f"--zone: {exc}") from None
    return moved


def zone_holding_start(geom: Any, start: Any) -> str | None:
    """The zone options (:meth:`~fgdoppler.zone.Zone.reaching`) that hold the simulated ``start`` state, where the
    geometry's zone (every tracker's prior) does not; ``None`` where it does.

    The zone is the trackers' only knowledge of where a track begins.  Far from the sensors a start outside it
    can fit the Doppler as well as one inside (range is weakly observed there), so `track` cannot see the mistake
    in the data: it is said where the truth is known (simulate, montecarlo).
    """
    zone = geom.zone
    if bool(zone.contains(start)):
        return None
    return str(zone.reaching(start).options())


#: The ``dest`` of every option :func:`add_scenario_options` adds.
SCENARIO_OPTIONS = ("velocity", "duration", "dt", "offsets", "sigma", "process_noise", "turn_rate", "acceleration",
                    "manoeuvre_onset", "bias", "clock_error", "site_error")


def add_scenario_options(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The options of a simulated target (velocity, duration, sampling, offsets, noise); returns the group.

    The start position is each command's own (one start, or several for Monte Carlo).
    """
    g = p.add_argument_group("scenario (the simulated target)")
    g.add_argument("--velocity", type=float, nargs="+", default=None, metavar="V",
                   help="velocity VX VY (2-D) or VX VY VZ (3-D) in m/s (default 10 -100, and 0 for VZ)")
    g.add_argument("--duration", type=float, default=30.0, help="seconds (default 30)")
    g.add_argument("--dt", type=float, default=0.5, help="sampling interval of each pair in seconds (default 0.5)")
    g.add_argument("--offsets", type=float, nargs="+", default=None, metavar="S",
                   help="per-pair time offsets in s (default: 0 for every pair; 0 0.25 for the paper's case b)")
    g.add_argument("--sigma", type=float, nargs="+", default=[1.0], metavar="M/S",
                   help="Doppler noise std in m/s, one value or one per pair (default 1)")
    g.add_argument("--process-noise", type=float, default=0.0, metavar="Q",
                   help="truth process noise PSD in m^2/s^3 (default 0: constant velocity)")
    g.add_argument("--turn-rate", type=float, default=0.0, metavar="DEG/S",
                   help="the target turns at this rate from --manoeuvre-onset on (degrees per second, positive "
                   "clockwise seen from above; default 0)")
    g.add_argument("--acceleration", type=float, default=0.0, metavar="M/S2",
                   help="the target's speed changes at this rate from --manoeuvre-onset on (m/s^2, negative "
                   "slows it; default 0)")
    g.add_argument("--manoeuvre-onset", type=float, default=0.0, metavar="S",
                   help="when the manoeuvre of --turn-rate and --acceleration starts (s; default 0)")
    g.add_argument("--bias", type=float, nargs="+", default=[0.0], metavar="M/S",
                   help="constant Doppler offset in m/s added to every measurement of a pair (an uncalibrated "
                   "frequency offset), one value or one per pair (default 0)")
    g.add_argument("--clock-error", type=float, nargs="+", default=[0.0], metavar="S",
                   help="each pair's clock error in s: its measurements are recorded this much after they were "
                   "taken (a receiver's clock running late; negative: early), one value or one per pair (default 0)")
    g.add_argument("--site-error", type=float, nargs="+", default=None, metavar="M",
                   help="where the sensors truly are: each site's displacement from the geometry's position in m, "
                   "DX DY (3-D: DX DY DZ) for every site in the order the pairs first name them (pair 0's tx, its "
                   "rx, pair 1's tx, ...; a shared or monostatic site once); the measurements are those of the "
                   "moved sites, the geometry written and tracked with the declared one (default: none)")
    return g


#: The most samples a simulated scenario may have (guards against --dt 1e-9 and the like).
MAX_SAMPLES = 10_000_000


def scenario(args: argparse.Namespace, geometry: Any, start: tuple[float, ...], name: str) -> Any:
    """A :class:`~fgdoppler.simulation.Scenario` from the scenario options (every value checked first).

    ``start`` is ``(x, y)`` or ``(x, y, z)``; for a 3-D geometry a 2-D start and velocity are
    refused with a message naming the missing option.
    """
    from fgdoppler.models.motion import ConstantVelocity
    from fgdoppler.simulation import PAPER_CASE_B_OFFSET, Manoeuvre, Scenario

    if not (args.dt > 0 and args.duration >= 0) or not all(map(_finite, (args.dt, args.duration))):
        raise CLIError(f"--dt must be > 0 and --duration >= 0, got {args.dt} and {args.duration}")
    if (args.duration / args.dt + 1) * geometry.n_pairs > MAX_SAMPLES:
        raise CLIError(f"--duration {args.duration:g} s at --dt {args.dt:g} s gives more than {MAX_SAMPLES:,} "
                       "samples: lengthen --dt or shorten --duration")
    velocity = tuple(args.velocity) if args.velocity is not None else (10.0, -100.0)
    if len(velocity) not in (2, 3):
        raise CLIError(f"--velocity takes VX VY (2-D) or VX VY VZ (3-D), got {len(velocity)} numbers")
    dim = geometry.dim
    if dim == 3 and len(velocity) == 2 and args.velocity is None:
        velocity = (*velocity, 0.0)
    if len(start) != dim or len(velocity) != dim:
        # name only what is wrong: a default velocity the user never gave is not theirs to fix
        fixes = [f for f, bad in ((("give --start-z, the start's height" if dim == 3 else "drop --start-z"),
                                   len(start) != dim),
                                  (f"give --velocity {'VX VY VZ' if dim == 3 else 'VX VY'}", len(velocity) != dim))
                 if bad]
        why = "an altitude band or sensors with z make it 3-D" if dim == 3 else "make it 3-D with --altitude LO HI"
        raise CLIError(f"the geometry is {dim}-D ({why}) but the start has {len(start)} coordinates and the "
                       f"velocity {len(velocity)}: " + " and ".join(fixes))
    if not all(map(_finite, (*start, *velocity))):
        raise CLIError(f"the start and --velocity must be finite, got {start} and {velocity}")
    if not (args.process_noise >= 0 and _finite(args.process_noise)):
        raise CLIError(f"--process-noise must be a finite number >= 0, got {args.process_noise}")
    if args.offsets is not None:
        offsets = tuple(args.offsets)
    else:
        offsets = (0.0, PAPER_CASE_B_OFFSET) if geometry.name == "b" else (0.0,) * geometry.n_pairs
    sigma = one_or_each(args.sigma)
    bias = one_or_each(args.bias)
    clock = one_or_each(args.clock_error)
    manoeuvring = args.turn_rate != 0.0 or args.acceleration != 0.0
    try:
        manoeuvre = Manoeuvre(onset=args.manoeuvre_onset, turn_rate_deg=args.turn_rate,
                              acceleration=args.acceleration)  # checked even where it does nothing
        return Scenario(geometry=geometry, x0=(*start, *velocity), duration=args.duration, dt=args.dt,
                        sigma=sigma, time_offsets=offsets, name=name, bias=bias, clock_error=clock,
                        site_error=() if args.site_error is None else tuple(args.site_error),
                        manoeuvre=manoeuvre if manoeuvring else None,
                        process_noise=ConstantVelocity(q=args.process_noise) if args.process_noise > 0 else None)
    except ValueError as exc:
        msg = str(exc).replace("a scenario takes a manoeuvre or process noise, not both",
                               "--turn-rate/--acceleration and --process-noise cannot be combined")
        msg = msg.replace("bias must be", "--bias must be").replace("clock_error must be", "--clock-error must be")
        msg = msg.replace("a site displacement needs", "--site-error needs")
        for field, option in _MANOEUVRE_OPTIONS.items():
            msg = msg.replace(f"Manoeuvre.{field}", option)
        raise CLIError(msg) from None


#: The command-line option of each :class:`~fgdoppler.simulation.Manoeuvre` field, for its error messages.
_MANOEUVRE_OPTIONS = {"onset": "--manoeuvre-onset", "turn_rate_deg": "--turn-rate", "acceleration": "--acceleration"}


def one_or_each(values: list[float]) -> float | tuple[float, ...]:
    """An option's values as one number (one given) or a tuple (one each, of whatever it counts)."""
    return values[0] if len(values) == 1 else tuple(values)


def per_pair(values: list[float], n_pairs: int, option: str, where: str = "") -> float | tuple[float, ...]:
    """An option's values as one number or a tuple of one per pair (a CLIError for another count)."""
    if len(values) not in (1, n_pairs):
        raise CLIError(f"{option} takes one value or one per pair ({n_pairs}{where}), got {len(values)}")
    return one_or_each(values)


def east_north_of(geometry: Any, lat: float, lon: float, option: str) -> tuple[float, float]:
    """A start given as WGS84 latitude and longitude (degrees) as metres east and north of the geometry's origin,
    on the origin's horizontal plane (a CLIError for a metric geometry or a value out of range)."""
    if geometry.geodetic_origin is None:
        raise CLIError(f"{option} needs a geometry whose sites are given by latitude and longitude (a [geodetic] "
                       "table): this one's positions are metres in a frame of its own")
    from fgdoppler.geodetic import check_geodetic

    try:
        lat, lon = check_geodetic([lat, lon], option)
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    origin = geometry.geodetic_origin
    east, north, _ = origin.to_local(lat, lon, origin.height)
    return float(east), float(north)


def offset_sigma_error(exc: ValueError) -> CLIError:
    """A tracker settings' refusal of ``bias_sigma``, ``clock_sigma`` or ``site_sigma``, in the command line's
    words."""
    text = str(exc).replace("(huber_k=None)", "(no --huber)")
    option = next((o for f, o in (("clock_sigma", "--clock-sigma"), ("site_sigma", "--site-sigma"))
                   if text.startswith(f)), "--bias-sigma")
    return CLIError(f"{option}: {text}")


def taking(setting: str) -> list[str]:
    """The estimators whose settings have the field ``setting`` (e.g. ``"clock_sigma"``)."""
    from dataclasses import fields

    from fgdoppler.estimators.registry import ESTIMATORS

    return [n for n, i in ESTIMATORS.items() if setting in {f.name for f in fields(i.settings)}]


def motion(q: float) -> Any:
    """The estimators' :class:`~fgdoppler.models.motion.ConstantVelocity` of a given ``--q`` (without the option
    the models' own default, :func:`~fgdoppler.models.tracking.default_motion`).

    Raises
    ------
    CLIError
        Unless ``q`` is a finite number > 0: the smoothers' motion factors (and the verdict's reference
        smoother, which every command runs) need a full-rank process noise.
    """
    from fgdoppler.models.motion import ConstantVelocity

    if not (_finite(q) and q > 0):
        raise CLIError(f"--q must be a finite number > 0 (m^2/s^3), got {q:g}: every track is checked by a "
                       "smoother whose motion factors need some process noise (1e-6 is a nearly constant velocity)")
    return ConstantVelocity(q=q)


def _finite(v: float) -> bool:
    import math

    return math.isfinite(v)


def add_huber_option(p: argparse.ArgumentParser) -> None:
    """``--huber [K]``: the robust loss in the initiation and every estimator."""
    from fgdoppler.models.robust import EFFICIENT_K

    p.add_argument("--huber", type=float, nargs="?", const=EFFICIENT_K, default=None, metavar="K",
                   help=f"Huber loss with threshold K (whitened units; K = {EFFICIENT_K} when given alone) on every "
                   "Doppler residual, in the initiation and every estimator: a few gross outliers cannot drag "
                   "the track (default: Gaussian loss)")


def huber(args: argparse.Namespace) -> float | None:
    """The ``--huber`` threshold, checked."""
    k = args.huber
    if k is not None and not (_finite(k) and k > 0):
        raise CLIError(f"--huber must be a positive number, got {k}")
    return k
