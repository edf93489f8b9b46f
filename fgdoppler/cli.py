"""The ``fgdoppler`` command line.

Every subcommand has ``--help``; ``--json`` prints machine-readable output on
stdout; figures are written only where asked (``--plot PATH``).  Errors in the
input end the command with exit status 2 and a message naming the file and
line; nothing is written then.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fgdoppler import __version__

__all__ = ["main"]

Handler = Callable[[argparse.Namespace], int]


class CLIError(Exception):
    """A user error: printed without a traceback, exit status 2."""


def _emit_json(obj: Any) -> None:
    json.dump(obj, sys.stdout, indent=2, allow_nan=False)
    sys.stdout.write("\n")


# -- simulate -------------------------------------------------------------------
def _add_simulate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate a scenario and write measurements.csv, truth.csv, geometry.toml",
        description="Simulate one of the paper's scenarios (or a custom start) and write "
        "measurements.csv, truth.csv and geometry.toml into --out.",
    )
    p.add_argument("--case", default="a", help="paper geometry: a or b, or a geometry TOML file (default a)")
    p.add_argument("--start-x", type=float, default=25e3, help="initial x in metres (default 25000)")
    p.add_argument("--start-y", type=float, default=2e3, help="initial y in metres (default 2000)")
    p.add_argument("--velocity", type=float, nargs=2, default=(10.0, -100.0), metavar=("VX", "VY"),
                   help="velocity in m/s (default 10 -100)")
    p.add_argument("--duration", type=float, default=30.0, help="seconds (default 30)")
    p.add_argument("--dt", type=float, default=0.5, help="sampling interval in seconds (default 0.5)")
    p.add_argument("--sigma", type=float, default=1.0, help="Doppler noise std in m/s (default 1)")
    p.add_argument("--offsets", type=float, nargs="+", default=None, metavar="S",
                   help="per-pair time offsets in s (default: 0 for case a, 0 0.25 for case b)")
    p.add_argument("--process-noise", type=float, default=0.0, metavar="Q",
                   help="truth process noise PSD in m^2/s^3 (default 0: constant velocity)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--out", type=Path, default=Path("output/simulation"), help="output folder")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(handler=_run_simulate)


def _run_simulate(args: argparse.Namespace) -> int:
    from fgdoppler.geometry import resolve_geometry
    from fgdoppler.models.motion import ConstantVelocity
    from fgdoppler.simulation import PAPER_CASE_B_OFFSET, Scenario, simulate

    geom = resolve_geometry(args.case)
    if args.offsets is not None:
        offsets = tuple(args.offsets)
    elif geom.name == "b":
        offsets = (0.0, PAPER_CASE_B_OFFSET)
    else:
        offsets = tuple(0.0 for _ in geom.pairs)
    scen = Scenario(
        geometry=geom,
        x0=(args.start_x, args.start_y, *args.velocity),
        duration=args.duration,
        dt=args.dt,
        sigma=args.sigma,
        time_offsets=offsets,
        process_noise=ConstantVelocity(q=args.process_noise) if args.process_noise > 0 else None,
        name=f"case {geom.name or 'custom'}, start {args.start_x / 1e3:g} km",
    )
    sim = simulate(scen, np.random.default_rng(args.seed))
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    sim.measurements.to_csv(out / "measurements.csv")
    sim.truth.to_csv(out / "truth.csv")
    geom.to_toml(out / "geometry.toml")
    summary = {
        "scenario": scen.name,
        "measurements": len(sim.measurements),
        "states": int(sim.truth.times.size),
        "files": [str(out / f) for f in ("measurements.csv", "truth.csv", "geometry.toml")],
    }
    if args.json:
        _emit_json(summary)
    else:
        print(f"{scen.name}: {summary['measurements']} measurements, {summary['states']} truth states")
        for f in summary["files"]:
            print(f"  wrote {f}")
    return 0


# -- observability ----------------------------------------------------------------
def _grid(spec: Sequence[float] | None, default: np.ndarray) -> np.ndarray:
    if spec is None:
        return default
    start, stop, step = spec
    if step <= 0 or stop < start:
        raise CLIError(f"bad grid {start} {stop} {step}: need START <= STOP and STEP > 0")
    return np.arange(start, stop + step * 1e-9, step)


def _progress_bar(total: int, desc: str) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="state", disable=not sys.stderr.isatty(), leave=False)


def _add_observability(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "observability",
        help="observability maps (x × heading), O vs x slices, the speed table, a scenario report",
        description="The paper's observability measure O = log10 det(J'J) (floor -40). By default a "
        "map over initial x (1-49 km, 500 m) × heading (0-350 deg, 10 deg) for the paper's group 2 "
        "(case a, 2 km off the baseline) at 100 m/s with the batch that reproduces Table 2.",
    )
    p.add_argument("--group", type=int, choices=(1, 2, 3, 4), default=None,
                   help="paper evaluation group (sets --case and --offset)")
    p.add_argument("--case", default="a", help="geometry: a, b or a TOML file (default a)")
    p.add_argument("--offset", type=float, default=2e3, help="y of the evaluation points in m (default 2000)")
    p.add_argument("--speed", type=float, default=100.0, help="target speed in m/s (default 100)")
    p.add_argument("--headings", type=float, nargs=3, metavar=("START", "STOP", "STEP"), default=None,
                   help="heading grid in degrees (default 0 350 10)")
    p.add_argument("--x", type=float, nargs=3, metavar=("START", "STOP", "STEP"), default=None,
                   help="initial x grid in metres (default 1000 49000 500)")
    p.add_argument("--samples", type=int, default=None, help="batch samples per pair (default 2)")
    p.add_argument("--interval", type=float, default=None, help="batch sampling interval in s (default 1)")
    p.add_argument("--pair-offsets", type=float, nargs="+", default=None, metavar="S",
                   help="batch time offset of each pair in s (default 0)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--table", action="store_true", help="the speed table (paper Table 2)")
    mode.add_argument("--slice", type=float, default=None, metavar="HEADING",
                      help="O vs x at one heading for groups 2 and 4 (paper Fig. 8 uses 180)")
    mode.add_argument("--report", type=float, default=None, metavar="START_X",
                      help="marginal-covariance report of the paper scenario of --case starting at START_X m")
    p.add_argument("--process-noise", type=float, default=0.0, metavar="Q",
                   help="for --report: NCV process noise PSD (default 0: deterministic CV)")
    p.add_argument("--json", action="store_true", help="machine-readable output on stdout")
    p.add_argument("--plot", type=Path, default=None, metavar="PATH", help="write a figure")
    p.set_defaults(handler=_run_observability)


def _run_observability(args: argparse.Namespace) -> int:
    from fgdoppler.analysis import observability as ob
    from fgdoppler.geometry import resolve_geometry

    batch = ob.Batch(
        samples_per_pair=args.samples if args.samples is not None else ob.TABLE2_BATCH.samples_per_pair,
        interval=args.interval if args.interval is not None else ob.TABLE2_BATCH.interval,
        offsets=tuple(args.pair_offsets) if args.pair_offsets else None,
    )
    xs = _grid(args.x, ob.DEFAULT_X)
    hs = _grid(args.headings, ob.DEFAULT_HEADINGS_DEG)
    if args.table:
        table = ob.speed_table(batch=batch, x=xs, heading_deg=hs)
        if args.json:
            _emit_json({"batch": table.batch.describe(), "rows": table.compare()})
        else:
            print(table.to_markdown())
        if args.plot:
            from fgdoppler import plotting

            ax = plotting._axes(None)
            for g in table.groups:
                ax.plot(table.speeds, [table.values[g][s][0] for s in table.speeds], "-o", label=f"group {g} max")
                ax.plot(table.speeds, [table.values[g][s][1] for s in table.speeds], "--o", label=f"group {g} min")
            ax.set_xlabel("speed (m/s)")
            ax.set_ylabel("O")
            ax.legend(fontsize="small")
            plotting.save(ax, args.plot)
        return 0
    if args.slice is not None:
        curves = {}
        for g in (2, 4):
            case, y = ob.PAPER_GROUPS[g]
            m = ob.observability_map(resolve_geometry(case), y=y, speed=args.speed, x=xs,
                                     heading_deg=[args.slice], batch=batch)
            curves[f"group {g}"] = (m.x, m.O[:, 0])
        if args.json:
            _emit_json({"heading_deg": args.slice, "batch": batch.describe(),
                        "curves": {k: {"x": v[0].tolist(), "O": v[1].tolist()} for k, v in curves.items()}})
        else:
            for k, (x, O) in curves.items():
                i = int(np.argmin(O))
                print(f"{k}: O from {O.min():.2f} (x = {x[i] / 1e3:g} km) to {O.max():.2f}")
        if args.plot:
            from fgdoppler import plotting

            plotting.save(plotting.plot_observability_slice(curves, heading_deg=args.slice), args.plot)
        return 0
    if args.report is not None:
        return _observability_report(args)
    case, y = (ob.PAPER_GROUPS[args.group] if args.group else (args.case, args.offset))
    geom = resolve_geometry(case)
    with _progress_bar(xs.size * hs.size, "observability map") as bar:
        m = ob.observability_map(geom, y=y, speed=args.speed, x=xs, heading_deg=hs, batch=batch,
                                 progress=bar.update)
    if args.json:
        _emit_json(m.to_dict())
    else:
        i, j = np.unravel_index(np.argmin(m.O), m.O.shape)
        print(f"geometry {geom.name or case}, y = {y:g} m, speed {args.speed:g} m/s; batch: {batch.describe()}")
        print(f"O: max {m.O.max():.2f}, min {m.O.min():.2f} (x = {m.x[i] / 1e3:g} km, heading "
              f"{m.heading_deg[j]:g} deg); {int(m.unobservable.sum())} of {m.O.size} cells at the -40 floor")
    if args.plot:
        from fgdoppler import plotting

        plotting.save(plotting.plot_observability_map(m), args.plot)
    return 0


def _observability_report(args: argparse.Namespace) -> int:
    from fgdoppler.analysis.observability import observability_report
    from fgdoppler.models.motion import ConstantVelocity
    from fgdoppler.simulation import paper_scenario, simulate

    scen = paper_scenario(args.case, args.report)
    sim = simulate(scen, np.random.default_rng(0))
    motion = ConstantVelocity(q=args.process_noise) if args.process_noise > 0 else None
    rep = observability_report(scen.geometry, sim.truth, sim.measurements, motion=motion)
    if args.json:
        _emit_json({"scenario": scen.name, **rep.to_dict()})
    else:
        print(f"{scen.name}: status {rep.status}{' (' + rep.message + ')' if rep.message else ''}")
        print(f"O(x0) = {rep.O_x0:.2f}, cond(J'J) = {rep.cond_JtJ:.3g}")
        ang = rep.tangent_angle_deg
        print("heading vs ellipse tangent (deg), first/last: "
              + ", ".join(f"pair {i + 1}: {ang[0, i]:.1f}/{ang[-1, i]:.1f}" for i in range(ang.shape[1])))
        if rep.pos_std is not None and rep.weakest_std is not None:
            print("  time   sigma_x  sigma_y  sigma_weakest (m)")
            for k in np.unique(np.linspace(0, rep.times.size - 1, 7).astype(int)):
                print(f"{rep.times[k]:6.2f} {rep.pos_std[k, 0]:8.1f} {rep.pos_std[k, 1]:8.1f} {rep.weakest_std[k]:10.1f}")
    if args.plot:
        from fgdoppler import plotting

        plotting.save(plotting.plot_report_std(rep), args.plot)
    return 0


# -- entry point ----------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="fgdoppler",
        description="Doppler-only multistatic tracking near the Tx-Rx baseline "
        "(factor graphs, EKF, observability, Monte Carlo).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


_SUBCOMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_simulate, _add_observability]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler = args.handler
    try:
        return handler(args)
    except (CLIError, ValueError, OSError) as exc:
        print(f"fgdoppler {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
