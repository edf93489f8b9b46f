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
    summary: dict[str, Any] = {
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
        i, j = (int(v) for v in np.unravel_index(np.argmin(m.O), m.O.shape))
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


# -- track --------------------------------------------------------------------------
ESTIMATORS = ("init", "ekf", "isam2", "fixed-lag", "batch")


def _add_track(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "track",
        help="initiate and track/smooth a recorded measurement CSV",
        description="Read FILE (CSV time,pair,doppler,sigma), initiate from the first --init-per-pair "
        "measurements of each pair (multi-start grid + refinement), then run the chosen estimator.",
    )
    p.add_argument("file", type=Path, metavar="FILE", help="measurement CSV")
    p.add_argument("--geometry", default="a", help="a, b or a geometry TOML file (default a)")
    p.add_argument("--estimator", choices=ESTIMATORS, default="init", help="what to run (default init)")
    p.add_argument("--sigma", type=float, default=None, help="default Doppler sigma when FILE has no sigma column")
    p.add_argument("--init-method", choices=("lm", "ils", "grid"), default="lm", help="initiation refinement (default lm)")
    p.add_argument("--init-per-pair", type=int, default=10, help="initiation window: measurements per pair (default 10)")
    p.add_argument("--k-best", type=int, default=5, help="grid candidates to refine (default 5)")
    p.add_argument("--no-weak-prior", action="store_true", help="initiation without the weak search-region prior")
    p.add_argument("--no-region-bound", action="store_true",
                   help="let the initiation's start state leave the search region (detectable zone)")
    p.add_argument("--half-plane", type=float, nargs=4, metavar=("PX", "PY", "NX", "NY"), default=None,
                   help="target known to satisfy (NX, NY) . (p - (PX, PY)) >= 0, e.g. 0 0 0 1 for y >= 0")
    p.add_argument("--q", type=float, default=None, help="process noise PSD in m^2/s^3 (default 1e-3)")
    p.add_argument("--lag", type=float, default=5.0, help="fixed-lag smoother lag in s (default 5)")
    p.add_argument("--truth", type=Path, default=None, help="truth CSV (time,x,y,vx,vy) for --plot and errors")
    p.add_argument("--out", type=Path, default=None, help="write the track as CSV (and .json beside it)")
    p.add_argument("--json", action="store_true", help="machine-readable result on stdout")
    p.add_argument("--plot", type=Path, default=None, metavar="PATH", help="write a figure")
    p.set_defaults(handler=_run_track)


def _initiation_settings(args: argparse.Namespace) -> Any:
    from fgdoppler.estimators.grid import HalfPlane
    from fgdoppler.estimators.initiation import InitiationSettings
    from fgdoppler.models.motion import ConstantVelocity

    hp = None
    if args.half_plane is not None:
        px, py, nx, ny = args.half_plane
        hp = HalfPlane(point=(px, py), normal=(nx, ny))
    kw: dict[str, Any] = {}
    if args.q is not None:
        kw["motion"] = ConstantVelocity(q=args.q)
    return InitiationSettings(method=args.init_method, k_best=args.k_best, weak_prior=not args.no_weak_prior,
                              region_bound=not args.no_region_bound, half_plane=hp, **kw)


def _run_track(args: argparse.Namespace) -> int:
    from fgdoppler.estimators.initiation import initiate
    from fgdoppler.geometry import resolve_geometry
    from fgdoppler.measurements import Measurements
    from fgdoppler.simulation import Trajectory

    geom = resolve_geometry(args.geometry)
    meas = Measurements.from_csv(args.file, geometry=geom, default_sigma=args.sigma)
    truth = Trajectory.from_csv(args.truth) if args.truth else None
    if args.init_per_pair < 3:
        raise CLIError("--init-per-pair must be >= 3")
    window = meas.first_per_pair(args.init_per_pair)
    init = initiate(window, geom, _initiation_settings(args))
    if args.estimator == "init":
        return _report_initiation(args, init, window, geom, truth)
    return _run_tracker(args, init, meas, geom, truth)


def _report_initiation(args: argparse.Namespace, init: Any, window: Any, geom: Any, truth: Any) -> int:
    if args.out is not None:
        from fgdoppler._io import atomic_write_text

        atomic_write_text(args.out, json.dumps(init.to_dict(), indent=1))
    if args.json:
        _emit_json(init.to_dict())
    else:
        print(f"initiation ({init.method}) from {init.n_measurements} measurements, "
              f"t = {init.t_start:g}..{init.t_end:g} s, {init.wall_time * 1e3:.0f} ms")
        print(f"  state at t_end: x = {init.x_end[0]:.1f} m, y = {init.x_end[1]:.1f} m, "
              f"vx = {init.x_end[2]:.2f} m/s, vy = {init.x_end[3]:.2f} m/s")
        if init.P_end is not None:
            sd = np.sqrt(np.diag(init.P_end))
            print(f"  std: {sd[0]:.1f} m, {sd[1]:.1f} m, {sd[2]:.2f} m/s, {sd[3]:.2f} m/s")
        else:
            print(f"  covariance indeterminate: {init.covariance_message}")
        verdict = "passes" if init.passes_chi2 else "FAILS"
        print(f"  cost {init.cost:.2f} {verdict} the chi-square test ({init.chi2_threshold:.2f}, {init.dof} dof); "
              f"objective with prior and region terms {init.objective:.2f}")
        if init.ambiguous:
            print(f"  AMBIGUOUS: {len(init.alternatives)} other solution(s) pass the test:")
            for a in init.alternatives:
                print(f"    x0 = {np.round(a.state, 1).tolist()} cost {a.cost:.2f}")
        for n in init.notes:
            print(f"  note: {n}")
        if truth is not None:
            err = init.x_end - truth.at([init.t_end])[0]
            print(f"  error at t_end: position {np.hypot(err[0], err[1]):.1f} m, velocity {np.hypot(err[2], err[3]):.2f} m/s")
    if args.plot:
        from fgdoppler import plotting
        from fgdoppler.estimators.initiation import residual_landscape

        xs = np.arange(1e3, 49e3 + 1, 250.0)
        hs = np.arange(0.0, 360.0, 2.0)
        speed = float(np.hypot(*init.x_start[2:]))
        cost = residual_landscape(window, geom, x=xs, heading_deg=hs, y0=float(init.x_start[1]), speed=speed)
        others = [c.state for c in init.candidates[1:]] + [a.state for a in init.alternatives]
        t0 = truth.at([init.t_start])[0] if truth is not None else None
        ax = plotting.plot_landscape(xs, hs, cost, best=init.x_start, others=others, truth=t0)
        ax.set_title(f"residual over x0 x heading at y0 = {init.x_start[1] / 1e3:.2f} km, speed {speed:.0f} m/s",
                     fontsize="small")
        plotting.save(ax, args.plot)
    return 0


def _run_tracker(args: argparse.Namespace, init: Any, meas: Any, geom: Any, truth: Any) -> int:
    from fgdoppler.estimators import run_estimator
    from fgdoppler.estimators.common import TrackerSettings
    from fgdoppler.models.measurement import DopplerModel
    from fgdoppler.models.motion import ConstantVelocity

    kw: dict[str, Any] = {"lag": args.lag, "weak_prior": not args.no_weak_prior}
    if args.q is not None:
        kw["motion"] = ConstantVelocity(q=args.q)
    settings = TrackerSettings(**kw)
    result = run_estimator(args.estimator, meas, DopplerModel(geometry=geom), init, settings)
    if args.out is not None:
        result.to_csv(args.out)
        result.to_json(args.out.with_suffix(".json"))
    if args.json:
        _emit_json(result.to_dict(all_estimates=False))
    else:
        e = result.main
        print(f"{args.estimator}: {len(e)} states ({result.primary}), t = {e.times[0]:g}..{e.times[-1]:g} s, "
              f"{result.wall_time * 1e3:.0f} ms; {len(result.warnings)} warning(s)")
        print(f"  last state: x = {e.states[-1, 0]:.1f} m, y = {e.states[-1, 1]:.1f} m, "
              f"vx = {e.states[-1, 2]:.2f} m/s, vy = {e.states[-1, 3]:.2f} m/s")
        for t, w in result.warnings[:10]:
            print(f"  warning at t = {t:g}: {w}")
        if truth is not None:
            err = e.states - truth.at(e.times)
            rmse = float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))))
            print(f"  position RMSE vs truth: {rmse:.1f} m; final error {np.hypot(*err[-1, :2]):.1f} m")
        if args.out is not None:
            print(f"  wrote {args.out} and {args.out.with_suffix('.json')}")
    if args.plot:
        from fgdoppler import plotting

        e = result.main
        ax = plotting.plot_track(e.times, e.states, geom, covariances=e.covariances, cov_ok=e.cov_ok,
                                 truth=None if truth is None else truth.states, label=f"{args.estimator} ({result.primary})")
        plotting.save(ax, args.plot)
    return 0


# -- montecarlo / reproduce ------------------------------------------------------------
def _executor(args: argparse.Namespace) -> tuple[Any, Any]:
    """(executor, client) for ``--scheduler`` (Dask distributed), or (None, None)."""
    if not getattr(args, "scheduler", None):
        return None, None
    try:
        from distributed import Client
    except ImportError as exc:
        raise CLIError("--scheduler needs the optional extra: pip install 'fgdoppler[distributed]'") from exc
    client = Client(args.scheduler)
    return client.get_executor(), client


def _add_montecarlo(sub: argparse._SubParsersAction) -> None:
    from fgdoppler.analysis.montecarlo import DEFAULT_ESTIMATORS

    p = sub.add_parser(
        "montecarlo",
        help="Monte Carlo RMSE / NEES study of paper scenarios",
        description="Simulate paper scenarios --runs times each and run every estimator; writes "
        "OUT.npz and OUT.json (reloadable) and prints time-averaged RMSE.",
    )
    p.add_argument("--case", choices=("a", "b", "all"), default="all", help="paper geometry (default all)")
    p.add_argument("--start-x", type=float, nargs="+", default=None, metavar="M",
                   help="start x positions in m (default 5000 25000 45000)")
    p.add_argument("--estimators", nargs="+", default=list(DEFAULT_ESTIMATORS),
                   help=f"estimators (default: {' '.join(DEFAULT_ESTIMATORS)}; also lag:SECONDS)")
    p.add_argument("--runs", type=int, default=100, help="runs per scenario (default 100)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=2026, help="root seed (default 2026)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler address (optional extra)")
    p.add_argument("--out", type=Path, default=Path("output/montecarlo/montecarlo"), help="output path stem")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--plot", type=Path, default=None, metavar="PATH", help="RMSE-vs-time figure of the first scenario")
    p.set_defaults(handler=_run_montecarlo)


def _run_montecarlo(args: argparse.Namespace) -> int:
    from fgdoppler.analysis.montecarlo import MonteCarloSpec, run_monte_carlo
    from fgdoppler.simulation import PAPER_START_X, paper_scenario

    cases = ("a", "b") if args.case == "all" else (args.case,)
    starts = tuple(args.start_x) if args.start_x else PAPER_START_X
    scen = tuple(paper_scenario(c, x) for c in cases for x in starts)
    try:
        spec = MonteCarloSpec(scenarios=scen, estimators=tuple(args.estimators), runs=args.runs, seed=args.seed)
    except ValueError as exc:
        raise CLIError(str(exc)) from exc
    executor, client = _executor(args)
    try:
        res = run_monte_carlo(spec, executor=executor, workers=args.workers)
    finally:
        if client is not None:
            client.close()
    npz, js = res.save(args.out)
    summ = res.summary()
    if args.json:
        _emit_json(summ)
    else:
        print(f"{res.runs} runs x {len(scen)} scenarios in {res.wall_time:.1f} s; wrote {npz} and {js}")
        print(f"{'scenario':22s} " + " ".join(f"{e:>10s}" for e in res.estimators))
        for name in res.scenario_names:
            vals = [r["pos_rmse_mean"] for r in summ["rows"] if r["scenario"] == name]
            print(f"{name:22s} " + " ".join(f"{v:10.1f}" if v is not None else f"{'-':>10s}" for v in vals))
    if args.plot:
        from fgdoppler import plotting

        ax = plotting.plot_rmse(res.times[0], {e: res.pos_rmse(0, e) for e in res.estimators},
                                title=res.scenario_names[0])
        plotting.save(ax, args.plot)
    return 0


def _add_reproduce(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="every table and figure of the paper plus the new studies, with report.md",
        description="Reproduce Table 2, Figs 3-8 and 10-11 of the paper, the lag sweep, NEES and "
        "observability reports into --out, with report.md comparing the paper's values and ours.",
    )
    p.add_argument("--quick", action="store_true", help="few runs (5 per scenario): under a minute")
    p.add_argument("--runs", type=int, default=None, help="runs per scenario (default 100; 5 with --quick)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=2026, help="root seed (default 2026)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler address (optional extra)")
    p.add_argument("--out", type=Path, default=Path("output/reproduce"), help="output folder (default output/reproduce)")
    p.add_argument("--json", action="store_true", help="print the claims as JSON")
    p.set_defaults(handler=_run_reproduce)


def _run_reproduce(args: argparse.Namespace) -> int:
    import os

    from fgdoppler.analysis.reproduce import ReproduceSettings, reproduce

    os.environ.setdefault("MPLBACKEND", "Agg")
    runs = args.runs if args.runs is not None else (5 if args.quick else 100)
    if runs < 1:
        raise CLIError("--runs must be >= 1")
    executor, client = _executor(args)
    try:
        report = reproduce(args.out, ReproduceSettings(runs=runs, workers=args.workers, seed=args.seed),
                           executor=executor)
    finally:
        if client is not None:
            client.close()
    claims = json.loads((args.out / "claims.json").read_text())
    if args.json:
        _emit_json(claims)
    else:
        n_ok = sum(claims["claims"].values())
        print(f"wrote {report} ({runs} runs per scenario, {claims['wall_time']:.1f} s)")
        print(f"{n_ok} of {len(claims['claims'])} claims reproduced:")
        for c, ok in claims["claims"].items():
            print(f"  [{'yes' if ok else 'NO '}] {c}")
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


_SUBCOMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_simulate, _add_observability, _add_track, _add_montecarlo, _add_reproduce]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler = args.handler
    try:
        return handler(args)
    except BrokenPipeError:  # e.g. piped into `head`
        sys.stderr.close()
        return 0
    except (CLIError, ValueError, OSError) as exc:
        print(f"fgdoppler {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
