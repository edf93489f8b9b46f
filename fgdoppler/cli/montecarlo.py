"""``fgdoppler montecarlo``: an RMSE / NEES study over simulated runs."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from fgdoppler.cli.common import (
    CLIError,
    add_huber_option,
    add_scenario_options,
    add_zone_options,
    east_north_of,
    emit_json,
    executor,
    geometry_with_zone,
    grid_spec,
    huber,
    motion,
    offset_sigma_error,
    one_or_each,
    per_pair,
    scenario,
    zone_holding_start,
)
from fgdoppler.estimators.names import DEFAULT_ESTIMATORS

__all__ = ["add_montecarlo"]


def add_montecarlo(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "montecarlo",
        help="Monte Carlo RMSE / NEES study of the paper's scenarios or your own",
        description="Simulate scenarios --runs times each and run every estimator; writes OUT.npz and "
        "OUT.json (reloadable) and prints per scenario and estimator the time-averaged position RMSE, the NEES "
        "against its 95 % band and the verdict counts.  By default the paper's six scenarios; with "
        "--geometry, targets starting at each --start-x (or --start-lat-lon) on that geometry, with the scenario "
        "options.",
    )
    p.add_argument("--case", choices=("a", "b", "all"), default="all", help="paper geometry (default all)")
    p.add_argument("--geometry", default=None, help="a geometry TOML file (or a, b) instead of --case")
    p.add_argument("--start-x", type=float, nargs="+", default=None, metavar="M",
                   help="start x positions in m (default 5000 25000 45000)")
    p.add_argument("--start-y", type=float, default=None, help="start y in m (default 2000)")
    p.add_argument("--start-lat-lon", type=float, nargs="+", default=None, metavar="DEG",
                   help="start positions as WGS84 latitude and longitude in degrees, LAT LON for each, instead of "
                        "--start-x/--start-y (the geometry must give its sites so: a [geodetic] table)")
    p.add_argument("--start-z", type=float, default=None,
                   help="start height in m: 3-D targets (the geometry must be 3-D: --altitude or sensors with z)")
    p.add_argument("--q", type=float, default=None, help="estimators' process noise PSD in m^2/s^3 (default 1e-3)")
    add_huber_option(p)
    p.add_argument("--bias-sigma", type=float, nargs="+", default=None, metavar="M/S",
                   help="Doppler calibration uncertainty per pair in m/s (1 sigma; one value or one per pair): the "
                        "covariances of the smoother, ekf, isam2 and fixed-lag include what constant offsets of that "
                        "size would do; particle and map integrate such offsets out (default 0; simulate offsets "
                        "with --bias)")
    p.add_argument("--clock-sigma", type=float, nargs="+", default=None, metavar="S",
                   help="clock uncertainty per pair in s (1 sigma; one value or one per pair): every estimator's "
                        "covariances include what a pair's times all off by that much would do (default 0; "
                        "simulate errors with --clock-error)")
    p.add_argument("--site-sigma", type=float, nargs="+", default=None, metavar="M",
                   help="sensor site position uncertainty in m (1 sigma in every coordinate; one value or one per "
                        "site, in the order the pairs first name them): every estimator's covariances include what "
                        "sites that far off would do (default 0; simulate errors with --site-error)")
    p.add_argument("--estimate-offsets", action="store_true",
                   help="with --bias-sigma: the smoother estimates each pair's offset with the track instead")
    p.add_argument("--draw-bias", type=float, nargs="+", default=None, metavar="M/S",
                   help="each run draws each pair's constant Doppler offset afresh from N(0, M/S^2) (one value or "
                        "one per pair), added to --bias: to check --bias-sigma on average (default: none drawn)")
    p.add_argument("--draw-site-error", type=float, nargs="+", default=None, metavar="M",
                   help="each run draws each sensor site's displacement afresh from N(0, M^2) in every coordinate "
                        "(one value or one per site, in the order the pairs first name them), added to "
                        "--site-error: to check --site-sigma on average (default: none drawn)")
    p.add_argument("--estimators", nargs="+", default=list(DEFAULT_ESTIMATORS),
                   help=f"estimators (default: {' '.join(DEFAULT_ESTIMATORS)}; also lag:SECONDS)")
    p.add_argument("--runs", type=int, default=100, help="runs per scenario (default 100)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=2026, help="root seed (default 2026)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler address (optional extra)")
    p.add_argument("--out", type=Path, default=Path("output/montecarlo/montecarlo"), help="output path stem")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--plot", type=Path, default=None, metavar="PATH", help="RMSE-vs-time figure of the first scenario")
    add_scenario_options(p)
    add_zone_options(p)
    p.set_defaults(handler=_run)


def _starts(args: argparse.Namespace, geometry: Any,
            paper_x: tuple[float, ...]) -> list[tuple[float, float, str]]:
    """Each start's x and y in metres and how a scenario's name gives it: ``--start-x`` with ``--start-y``, or
    ``--start-lat-lon`` (metres east and north of the geometry's origin), or the paper's starts."""
    if args.start_lat_lon is None:
        y = 2e3 if args.start_y is None else args.start_y
        y_note = "" if y == 2e3 else f", y {y / 1e3:g} km"
        return [(x, y, f"{x / 1e3:g} km{y_note}") for x in (tuple(args.start_x) if args.start_x else paper_x)]
    if args.start_x is not None or args.start_y is not None:
        raise CLIError("--start-lat-lon gives the starts instead of --start-x and --start-y: give one or the other")
    values = args.start_lat_lon
    if len(values) % 2:
        raise CLIError(f"--start-lat-lon takes a latitude and a longitude for each start, got {len(values)} "
                       "numbers")
    out = []
    for lat, lon in zip(values[::2], values[1::2], strict=True):
        east, north = east_north_of(geometry, lat, lon, "--start-lat-lon")
        out.append((east, north, f"latitude {lat:g}, longitude {lon:g}"))
    return out


def _run(args: argparse.Namespace) -> int:
    from fgdoppler.analysis.montecarlo import MonteCarloSpec, run_monte_carlo
    from fgdoppler.estimators.initiation import InitiationSettings
    from fgdoppler.estimators.settings import SmootherSettings
    from fgdoppler.simulation import PAPER_START_X

    if args.runs < 1 or args.workers < 1:
        raise CLIError(f"--runs and --workers must be >= 1, got {args.runs} and {args.workers}")
    specs = [args.geometry] if args.geometry else (["a", "b"] if args.case == "all" else [args.case])
    scen = []
    for g in specs:
        geom = geometry_with_zone(g, args)
        label = f"case {geom.name}" if geom.name in ("a", "b") and not args.geometry else str(g)
        z = () if args.start_z is None else (args.start_z,)
        z_note = "" if args.start_z is None else f", altitude {args.start_z / 1e3:g} km"
        scen += [scenario(args, geom, (x, y, *z), f"{label}, start {where}{z_note}")
                 for x, y, where in _starts(args, geom, PAPER_START_X)]
    for sc in scen:  # the study runs as asked; the user learns that its trackers assume otherwise
        outside = zone_holding_start(sc.geometry, sc.x0)
        if outside is not None:
            print(f"note: {sc.name}: the start lies outside the zone the trackers assume "
                  f"({sc.geometry.zone.options()}), and a track starting inside it may be called ok; {outside} "
                  "gives one that holds it", file=sys.stderr)
    from fgdoppler.estimators.registry import ESTIMATORS

    k = huber(args)
    settings = {n: e.settings(huber_k=k) for n, e in ESTIMATORS.items()}
    if args.estimate_offsets and args.bias_sigma is None:
        raise CLIError("--estimate-offsets needs --bias-sigma (each pair's offset prior)")
    if args.estimate_offsets and "smoother" not in args.estimators:
        raise CLIError("--estimate-offsets applies to the smoother, which is not among --estimators")
    settings = _with_per_pair_sigma(args, scen, settings, "bias_sigma", args.bias_sigma)
    settings = _with_per_pair_sigma(args, scen, settings, "clock_sigma", args.clock_sigma)
    settings = _with_per_pair_sigma(args, scen, settings, "site_sigma", args.site_sigma)
    smoother = settings["smoother"]
    if args.estimate_offsets and isinstance(smoother, SmootherSettings):
        try:
            settings["smoother"] = replace(smoother, estimate_offsets=True)
        except ValueError as exc:
            raise offset_sigma_error(exc) from None
    try:
        spec = MonteCarloSpec(scenarios=tuple(scen), estimators=tuple(args.estimators), runs=args.runs, seed=args.seed,
                              initiation=InitiationSettings(grid=grid_spec(args), huber_k=k), settings=settings,
                              error_draws=_error_draws(args),
                              **({} if args.q is None else {"motion": motion(args.q)}))
    except ValueError as exc:
        raise CLIError(_in_option_words(str(exc))) from exc
    pool, client = executor(args)
    try:
        res = run_monte_carlo(spec, executor=pool, workers=args.workers)
    finally:
        if client is not None:
            client.close()
    npz, js = res.save(args.out)
    summ = res.summary()
    draws = spec.error_draws
    if args.json:
        emit_json(summ)
    else:
        print(f"{res.runs} runs x {len(scen)} scenarios in {res.wall_time:.1f} s; wrote {npz} and {js}")
        if draws is not None:
            drawn = [f"offsets N(0, sigma^2) with sigma {draws.bias_sigma} m/s" if args.draw_bias else "",
                     f"sites N(0, sigma^2) in every coordinate with sigma {draws.site_sigma} m"
                     if args.draw_site_error else ""]
            print("sensor errors drawn afresh for each run: " + ", ".join(d for d in drawn if d))
        _print_summary(summ)
    if args.plot:
        from fgdoppler import plotting

        ax = plotting.plot_rmse(res.times[0], {e: res.pos_rmse(0, e) for e in res.estimators},
                                title=res.scenario_names[0])
        plotting.save(ax, args.plot)
    return 0


def _error_draws(args: argparse.Namespace) -> Any:
    """The study's :class:`~fgdoppler.error_draws.ErrorDraws` of ``--draw-bias`` and ``--draw-site-error``
    (``None`` without either)."""
    if args.draw_bias is None and args.draw_site_error is None:
        return None
    from fgdoppler.error_draws import ErrorDraws

    try:
        return ErrorDraws(bias_sigma=0.0 if args.draw_bias is None else one_or_each(args.draw_bias),
                          site_sigma=0.0 if args.draw_site_error is None else one_or_each(args.draw_site_error))
    except ValueError as exc:
        raise CLIError(_in_option_words(str(exc))) from None


def _in_option_words(message: str) -> str:
    """An :class:`~fgdoppler.error_draws.ErrorDraws` refusal in the options' names (``bias_sigma`` is
    ``--draw-bias``, ``site_sigma`` ``--draw-site-error``); any other message as it is."""
    head = "error_draws in "
    for field, option in (("bias_sigma", "--draw-bias"), ("site_sigma", "--draw-site-error")):
        if message.startswith(f"{field} must"):
            return f"{option}: it must{message[len(field) + len(' must'):]}"
        if message.startswith(head) and f": {field} must" in message:
            where, rest = message[len(head):].split(f": {field} must", 1)
            return f"{option} in {where}: it must{rest}"
    return message


def _with_per_pair_sigma(args: argparse.Namespace, scen: list[Any], settings: dict[str, Any], field: str,
                         values: list[float] | None) -> dict[str, Any]:
    """``settings`` with ``field`` (``bias_sigma``, ``clock_sigma`` or ``site_sigma``, every estimator's) set to
    ``values`` in those of the study's estimators (``settings`` itself where ``values`` is ``None``)."""
    if values is None:
        return settings
    option = "--" + field.replace("_", "-")
    for sc in scen:  # every geometry of the study must take the count given
        if field == "site_sigma":
            from fgdoppler.estimators.site_offsets import site_sigmas

            try:
                site_sigmas(one_or_each(values), sc.geometry)
            except ValueError as exc:
                raise CLIError(f"{option} in {sc.name}: {exc}") from None
            sigma = one_or_each(values)
        else:
            sigma = per_pair(values, sc.geometry.n_pairs, option, f" in {sc.name}")
    # the study's estimators only (lag:S is the fixed-lag smoother): another's refusal must not stop it
    chosen = {"fixed-lag" if e.startswith("lag:") else e for e in args.estimators}
    try:
        return {n: replace(s, **{field: sigma}) if n in chosen else s for n, s in settings.items()}
    except ValueError as exc:
        raise offset_sigma_error(exc) from None


def _print_summary(summ: dict[str, Any]) -> None:
    """Three tables of a Monte Carlo summary (:meth:`~fgdoppler.analysis.montecarlo.MonteCarloResult.summary`),
    a row per scenario and a column per estimator: the time-averaged position RMSE, the NEES against its band,
    and the verdict counts."""
    lo, hi = summ["nees_band"]
    width = max(22, *(len(n) for n in summ["scenarios"]))
    tables = (
        ("position RMSE (m), averaged over time", lambda r: f"{v:.1f}" if (v := r["pos_rmse_mean"]) is not None else "-"),
        (f"NEES averaged over runs and t >= {summ['nees_from']:g} s (95 % band for {summ['runs']} runs: "
         f"{lo:.2f}-{hi:.2f}; * above it, ~ below it)",
         lambda r: "-" if (v := r["nees_mean"]) is None else f"{v:.3g}" + ("*" if v > hi else "~" if v < lo else "")),
        ("verdicts ok/doubtful/failed", lambda r: "/".join(str(r["verdicts"][k]) for k in ("ok", "doubtful", "failed"))),
    )
    for title, cell in tables:
        print(title)
        print(f"  {'scenario':{width}s} " + " ".join(f"{e:>12s}" for e in summ["estimators"]))
        for name in summ["scenarios"]:
            cells = [cell(r) for r in summ["rows"] if r["scenario"] == name]
            print(f"  {name:{width}s} " + " ".join(f"{c:>12s}" for c in cells))
