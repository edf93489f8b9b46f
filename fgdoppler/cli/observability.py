"""``fgdoppler observability``: maps, the speed table, x-slices and the marginal-covariance report."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fgdoppler.cli.common import (
    SCENARIO_OPTIONS,
    CLIError,
    add_scenario_options,
    east_north_of,
    emit_json,
    progress_bar,
    scenario,
)

if TYPE_CHECKING:
    from fgdoppler.analysis.observability import SamplingPattern

__all__ = ["add_observability"]


def add_observability(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "observability",
        help="observability maps (x × heading), O vs x slices, the speed table, a scenario report",
        description="The paper's observability measure O = log10 det(J'J) (floor -40). By default a "
        "map over initial x (1-49 km, 500 m) × heading (0-350 deg, 10 deg) for the paper's group 2 "
        "(case a, 2 km off the baseline) at 100 m/s with the sampling that reproduces Table 2.  With "
        "--geometry every mode works on that geometry, in its own frame (x along the first pair's baseline "
        "from its receiver, y across it, heading clockwise from the y axis; the paper's axes for a and b).",
    )
    p.add_argument("--group", type=int, choices=(1, 2, 3, 4), default=None,
                   help="paper evaluation group (sets --geometry and --offset)")
    p.add_argument("--geometry", "--case", dest="geometry", default=None,
                   help="geometry: the paper's a or b, or a TOML file (default: a; the paper's groups 2 and 4 "
                   "for --table and --slice; --case is the old name)")
    p.add_argument("--offset", type=float, default=2e3,
                   help="y of the evaluation points in the sensors' frame (across the first baseline), and the "
                   "start y of --report in the geometry's own coordinates, as simulate's --start-y (the two are one "
                   "for the paper's geometries), in m (default 2000)")
    p.add_argument("--speed", type=float, default=100.0, help="target speed in m/s (default 100)")
    p.add_argument("--speeds", type=float, nargs="+", default=[100.0, 75.0, 50.0, 25.0], metavar="M/S",
                   help="speeds of --table (default 100 75 50 25)")
    p.add_argument("--headings", type=float, nargs=3, metavar=("START", "STOP", "STEP"), default=None,
                   help="heading grid in degrees (default 0 350 10)")
    p.add_argument("--x", type=float, nargs=3, metavar=("START", "STOP", "STEP"), default=None,
                   help="initial x grid in metres (default: the sensors' extent D, D/50 to D - D/50 every "
                   "D/100; 1000 49000 500 for the paper)")
    p.add_argument("--samples", type=int, default=None, help="samples per pair of the sampling pattern (default 2)")
    p.add_argument("--interval", type=float, default=None, help="sampling interval in s (default 1)")
    p.add_argument("--pair-offsets", type=float, nargs="+", default=None, metavar="S",
                   help="sampling time offset of each pair in s (default 0)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--table", action="store_true", help="the speed table (paper Table 2)")
    mode.add_argument("--slice", type=float, default=None, metavar="HEADING",
                      help="O vs x at one heading for groups 2 and 4 (paper Fig. 8 uses 180)")
    mode.add_argument("--report", type=float, default=None, metavar="START_X",
                      help="marginal-covariance report of a target starting at (START_X, --offset) with the "
                      "scenario options, in the geometry's own coordinates as simulate's --start-x, --start-y and "
                      "--velocity (not the maps' frame); --process-noise Q also puts Q in the graph (default 0: "
                      "deterministic CV)")
    mode.add_argument("--report-lat-lon", type=float, nargs=2, default=None, metavar=("LAT", "LON"),
                      help="--report for a target starting at a WGS84 latitude and longitude in degrees instead of "
                           "(START_X, --offset) (the geometry must give its sites so: a [geodetic] table)")
    p.add_argument("--start-z", type=float, default=None, metavar="M",
                   help="--report only: start height of a 3-D target (the geometry must be 3-D)")
    add_scenario_options(p)
    p.add_argument("--json", action="store_true", help="machine-readable output on stdout")
    p.add_argument("--plot", type=Path, default=None, metavar="PATH", help="write a figure")
    p.set_defaults(handler=_run, defaults={n: p.get_default(n) for n in _CHECKED})


#: The options each mode reads (their ``dest``), besides ``--geometry``, ``--json`` and ``--plot``; any other option
#: given is refused, never dropped.
MODE_OPTIONS: dict[str, frozenset[str]] = {
    "map": frozenset({"group", "offset", "speed", "headings", "x", "samples", "interval", "pair_offsets"}),
    # the table and the slices show the paper's groups 2 and 4 themselves (--geometry and --offset for others)
    "table": frozenset({"offset", "speeds", "headings", "x", "samples", "interval", "pair_offsets"}),
    "slice": frozenset({"offset", "speed", "x", "samples", "interval", "pair_offsets"}),
    # the report is the information of the declared sites: a site error would change nothing it shows
    "report": frozenset({"group", "offset", "start_z", *SCENARIO_OPTIONS} - {"site_error"}),
    "report-lat-lon": frozenset({"start_z", *SCENARIO_OPTIONS} - {"site_error"}),
}

#: Each option's name on the command line, for the messages.
_FLAGS = {"pair_offsets": "--pair-offsets", "start_z": "--start-z", "process_noise": "--process-noise",
          "turn_rate": "--turn-rate", "manoeuvre_onset": "--manoeuvre-onset", "clock_error": "--clock-error",
          "site_error": "--site-error"}


#: The options whose use is checked against the mode (``dest`` names).
_CHECKED = ("group", "offset", "speed", "speeds", "headings", "x", "samples", "interval", "pair_offsets", "start_z",
            *SCENARIO_OPTIONS)


def _mode(args: argparse.Namespace) -> str:
    if args.table:
        return "table"
    if args.slice is not None:
        return "slice"
    if args.report is not None:
        return "report"
    return "report-lat-lon" if args.report_lat_lon is not None else "map"


def _check_options(args: argparse.Namespace) -> None:
    """Refuse options the chosen mode does not read; resolve ``--group`` into ``--geometry`` and ``--offset``."""
    mode = _mode(args)
    given = [n for n in _CHECKED if getattr(args, n) != args.defaults[n]]
    unused = [n for n in given if n not in MODE_OPTIONS[mode]]
    if unused:
        flags = ", ".join(_FLAGS.get(n, "--" + n) for n in unused)
        shown = {"map": "the map (the default mode)", "report-lat-lon": "--report-lat-lon"}.get(mode, "--" + mode)
        raise CLIError(f"{flags} {'does' if len(unused) == 1 else 'do'} not apply to {shown}")
    if mode in ("table", "slice") and args.geometry is None and "offset" in given:
        raise CLIError(f"--offset applies to --{mode} with --geometry (without it, it shows the paper's groups 2 and 4 "
                       "at their own offsets)")
    if args.group is not None:
        from fgdoppler.analysis.observability import PAPER_GROUPS

        if args.geometry is not None or "offset" in given:
            raise CLIError("--group sets --geometry and --offset: give either the group or those two")
        args.geometry, args.offset = PAPER_GROUPS[args.group]


def _grid(spec: Sequence[float] | None, default: np.ndarray | None) -> np.ndarray | None:
    if spec is None:
        return default
    start, stop, step = spec
    if step <= 0 or stop < start:
        raise CLIError(f"bad grid {start} {stop} {step}: need START <= STOP and STEP > 0")
    return np.arange(start, stop + step * 1e-9, step)


def _run(args: argparse.Namespace) -> int:
    from fgdoppler.analysis import observability as ob

    _check_options(args)
    sampling = ob.SamplingPattern(
        samples_per_pair=args.samples if args.samples is not None else ob.TABLE2_SAMPLING.samples_per_pair,
        interval=args.interval if args.interval is not None else ob.TABLE2_SAMPLING.interval,
        offsets=tuple(args.pair_offsets) if args.pair_offsets else None,
    )
    xs = _grid(args.x, None)
    hs = _grid(args.headings, ob.DEFAULT_HEADINGS_DEG)
    assert hs is not None
    reporting = args.report is not None or args.report_lat_lon is not None
    if not reporting and args.geometry is not None:
        from fgdoppler.geometry import resolve_geometry

        if resolve_geometry(args.geometry).dim == 3:
            raise CLIError("the maps, slices and speed table are 2-D (x x heading in the sensors' plane); for a 3-D "
                           "geometry use --report START_X --start-z Z, or the altitude study "
                           "(studies/altitude_study.py)")
    if args.table:
        return _table(args, sampling, xs, hs)
    if args.slice is not None:
        return _slice(args, sampling, xs)
    if reporting:
        return _report(args)
    return _map(args, sampling, xs, hs)


def _table(args: argparse.Namespace, sampling: SamplingPattern, xs: np.ndarray | None, hs: np.ndarray) -> int:
    from fgdoppler import plotting
    from fgdoppler.analysis import observability as ob
    from fgdoppler.geometry import resolve_geometry

    if args.geometry is None:
        table = ob.speed_table(sampling=sampling, speeds=args.speeds,
                               x=ob.DEFAULT_X if xs is None else xs, heading_deg=hs)
    else:
        table = ob.geometry_speed_table(resolve_geometry(args.geometry), y=args.offset, speeds=args.speeds,
                                        sampling=sampling, x=xs, heading_deg=hs, label=str(args.geometry))
    if args.json:
        emit_json({"sampling": table.sampling.describe(), "rows": table.compare()})
    else:
        print(table.to_markdown())
    if args.plot:
        plotting.save(plotting.plot_speed_table(table), args.plot)
    return 0


def _slice(args: argparse.Namespace, sampling: SamplingPattern, xs: np.ndarray | None) -> int:
    from fgdoppler import plotting
    from fgdoppler.analysis import observability as ob
    from fgdoppler.geometry import resolve_geometry

    todo = ([(f"group {g}", *ob.PAPER_GROUPS[g]) for g in (2, 4)] if args.geometry is None
            else [(str(args.geometry), args.geometry, args.offset)])
    curves = {}
    for label, case, y in todo:
        m = ob.observability_map(resolve_geometry(case), y=y, speed=args.speed, x=xs,
                                 heading_deg=[args.slice], sampling=sampling)
        curves[label] = (m.x, m.O[:, 0])
    if args.json:
        emit_json({"heading_deg": args.slice, "sampling": sampling.describe(),
                   "curves": {k: {"x": v[0].tolist(), "O": v[1].tolist()} for k, v in curves.items()}})
    else:
        for k, (x, O) in curves.items():
            i = int(np.argmin(O))
            print(f"{k}: O from {O.min():.2f} (x = {x[i] / 1e3:g} km) to {O.max():.2f}")
    if args.plot:
        plotting.save(plotting.plot_observability_slice(curves, heading_deg=args.slice), args.plot)
    return 0


def _map(args: argparse.Namespace, sampling: SamplingPattern, xs: np.ndarray | None, hs: np.ndarray) -> int:
    from fgdoppler import plotting
    from fgdoppler.analysis import observability as ob
    from fgdoppler.geometry import resolve_geometry

    case, y = args.geometry or "a", args.offset
    geom = resolve_geometry(case)
    n_x = ob.default_along(geom).size if xs is None else xs.size
    with progress_bar(n_x * hs.size, "observability map") as bar:
        m = ob.observability_map(geom, y=y, speed=args.speed, x=xs, heading_deg=hs, sampling=sampling,
                                 progress=bar.update)
    if args.json:
        emit_json(m.to_dict())
    else:
        i, j = (int(v) for v in np.unravel_index(np.argmin(m.O), m.O.shape))
        print(f"geometry {geom.name or case}, y = {y:g} m, speed {args.speed:g} m/s; sampling: {sampling.describe()}")
        print(f"O: max {m.O.max():.2f}, min {m.O.min():.2f} (x = {m.x[i] / 1e3:g} km, heading "
              f"{m.heading_deg[j]:g} deg); {int(m.unobservable.sum())} of {m.O.size} cells at the -40 floor")
    if args.plot:
        plotting.save(plotting.plot_observability_map(m), args.plot)
    return 0


def _report(args: argparse.Namespace) -> int:
    from fgdoppler import plotting
    from fgdoppler.analysis.observability import observability_report
    from fgdoppler.geometry import resolve_geometry
    from fgdoppler.models.motion import ConstantVelocity
    from fgdoppler.simulation import simulate

    geom = resolve_geometry(args.geometry or "a")
    if args.report_lat_lon is None:
        x, y = args.report, args.offset
        where = f"({x / 1e3:g}, {y / 1e3:g}) km" + ("" if geom.frame.is_identity else " in the geometry's x, y")
    else:
        lat, lon = args.report_lat_lon
        x, y = east_north_of(geom, lat, lon, "--report-lat-lon")
        where = f"latitude {lat:g}, longitude {lon:g}"
    start = (x, y) if args.start_z is None else (x, y, args.start_z)
    scen = scenario(args, geom, start, f"{args.geometry or 'a'}, start {where}")
    sim = simulate(scen, np.random.default_rng(0))
    motion = ConstantVelocity(q=args.process_noise) if args.process_noise > 0 else None
    rep = observability_report(scen.geometry, sim.truth, sim.measurements, motion=motion)
    if args.json:
        emit_json({"scenario": scen.name, **rep.to_dict()})
    else:
        print(f"{scen.name}: status {rep.status}{' (' + rep.message + ')' if rep.message else ''}")
        print(f"O(x0) = {rep.O_x0:.2f}, cond(J'J) = {rep.cond_JtJ:.3g}")
        ang = rep.tangent_angle_deg
        print("heading vs ellipse tangent (deg), first/last: "
              + ", ".join(f"pair {scen.geometry.pair_label(i)}: {ang[0, i]:.1f}/{ang[-1, i]:.1f}"
                          for i in range(ang.shape[1])))
        if rep.pos_std is not None and rep.weakest_std is not None:
            print("  time   sigma_x  sigma_y  sigma_weakest (m)")
            for k in np.unique(np.linspace(0, rep.times.size - 1, 7).astype(int)):
                print(f"{rep.times[k]:6.2f} {rep.pos_std[k, 0]:8.1f} {rep.pos_std[k, 1]:8.1f} {rep.weakest_std[k]:10.1f}"
                      + (f"  sigma_z {rep.pos_std[k, 2]:.1f}" if rep.pos_std.shape[1] == 3 else ""))
    if args.plot:
        plotting.save(plotting.plot_report_std(rep), args.plot)
    return 0
