"""``fgdoppler track``: initiate and track or smooth a recorded measurement CSV."""

from __future__ import annotations

import argparse
import functools
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fgdoppler._text import pairs_text, plain_number, time_text
from fgdoppler.cli.common import (
    CLIError,
    add_huber_option,
    add_zone_options,
    emit_json,
    geometry_with_zone,
    grid_spec,
    huber,
    motion,
    offset_sigma_error,
    one_or_each,
    per_pair,
    taking,
)
from fgdoppler.estimators.names import ALIASES, METHODS, SUMMARIES
from fgdoppler.geometry import Geometry, principal_line
from fgdoppler.zone import ZoneBox

__all__ = ["add_track"]


def add_track(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "track",
        help="initiate and track/smooth a recorded measurement CSV",
        description="Read FILE (CSV time,pair,doppler,sigma in m/s, or time,pair,doppler_hz,sigma_hz in Hz with "
        "each pair's wavelength in the geometry file), initiate from the first --init-per-pair "
        "measurements of each pair and the first --init-seconds (multi-start grid + refinement), then run the chosen estimator.  The "
        "geometry is never assumed: give --geometry, or keep a geometry.toml beside FILE (as simulate writes).",
    )
    p.add_argument("file", type=Path, metavar="FILE", help="measurement CSV")
    p.add_argument("--geometry", default=None,
                   help="the paper's a or b, or a geometry TOML file (default: geometry.toml beside FILE)")
    # the offline smoother by default: a track of the whole recording, the most accurate and consistent
    # answer (README "Results"); the initiation alone is asked for by name
    p.add_argument("--estimator", choices=("init", *SUMMARIES, *ALIASES), default="smoother",
                   help="what to run: init (initiation only), " + ", ".join(
                       f"{k} ({v})" for k, v in SUMMARIES.items())
                   + "; batch is the old name of smoother (default smoother)")
    p.add_argument("--sigma", type=float, default=None,
                   help="default Doppler sigma when FILE has no sigma column, in its Doppler column's unit (m/s; Hz "
                        "for doppler_hz)")
    p.add_argument("--ignore-column", action="append", default=[], metavar="NAME",
                   help="skip this column of FILE where present (another tool's extra, e.g. snr; repeat for more); "
                        "any other unknown column is refused")
    p.add_argument("--init-method", choices=METHODS, default="lm", help="initiation refinement (default lm)")
    p.add_argument("--init-per-pair", type=int, default=10,
                   help="initiation window: at least this many measurements per pair (default 10)")
    p.add_argument("--init-seconds", type=float, default=4.5,
                   help="initiation window: and every measurement of the first S seconds (default 4.5, the same "
                        "window as 10 per pair at 2 scans/s; faster data need the time, not the count)")
    p.add_argument("--k-best", type=int, default=5, help="grid candidates to refine (default 5)")
    p.add_argument("--no-weak-prior", action="store_true", help="no weak zone prior on the first state")
    p.add_argument("--no-region-bound", action="store_true",
                   help="let the initiation's start state leave the zone (detectable zone)")
    p.add_argument("--half-plane", type=float, nargs=4, metavar=("PX", "PY", "NX", "NY"), default=None,
                   help="target known to satisfy (NX, NY) . (p - (PX, PY)) >= 0, e.g. 0 0 0 1 for y >= 0 "
                   "(2-D problems; in 3-D the altitude band bounds the height)")
    p.add_argument("--q", type=float, default=None, help="process noise PSD in m^2/s^3 (default 1e-3)")
    _add_estimator_options(p)
    p.add_argument("--bias-sigma", type=float, nargs="+", default=None, metavar="M/S",
                   help="each pair's Doppler calibration uncertainty in m/s (1 sigma; one value or one per pair): "
                        "the smoother's, ekf's, isam2's and fixed-lag's covariances include what constant offsets "
                        "of that size would do to the track; particle and map integrate such offsets out of their "
                        "likelihood (default 0)")
    p.add_argument("--clock-sigma", type=float, nargs="+", default=None, metavar="S",
                   help="each pair's clock uncertainty in s (1 sigma; one value or one per pair): every "
                        "estimator's covariances include what a pair's measurement times all late or early by that "
                        "much would do to the track (default 0: every pair's times from one clock)")
    p.add_argument("--site-sigma", type=float, nargs="+", default=None, metavar="M",
                   help="each sensor site's position uncertainty in m (1 sigma in every coordinate; one value, or one "
                        "per site in the order the pairs first name them: pair 0's tx, its rx, pair 1's tx, ..., a "
                        "shared or monostatic site once): every estimator's covariances include what sites that "
                        "far off would do to the track (default 0: the geometry's positions exact)")
    p.add_argument("--estimate-offsets", action="store_true",
                   help="smoother, with --bias-sigma: estimate each pair's offset with the track (the track moves, "
                        "the offsets are reported) instead of only widening the covariances")
    add_huber_option(p)
    p.add_argument("--drop-repeats", action="store_true",
                   help="leave out the repeats of every pair found repeating its Doppler more often than noise allows "
                        "(a receiver that holds its last value, or writes a fixed one, without a detection: the data "
                        "finding): the first measurement of each run stays, every measurement of a fixed value goes")
    p.add_argument("--truth", type=Path, default=None, help="truth CSV (time,x,y,vx,vy; 3-D time,x,y,z,vx,vy,vz) for --plot and errors")
    p.add_argument("--out", type=Path, default=None, help="write the track as CSV (and .json beside it)")
    p.add_argument("--json", action="store_true", help="machine-readable result on stdout")
    p.add_argument("--plot", type=Path, default=None, metavar="PATH", help="write a figure (format from the suffix)")
    p.add_argument("--allow-failed", action="store_true",
                   help=f"exit 0 even when the verdict is 'failed' (default: exit status {3})")
    add_zone_options(p)
    p.set_defaults(handler=_run)


def _add_estimator_options(p: argparse.ArgumentParser) -> None:
    """The options that one estimator or a few take (each refused by the others, :func:`_tracker_settings`)."""
    p.add_argument("--lag", type=float, default=None, help="fixed-lag smoother lag in s (default 5)")
    p.add_argument("--particles", type=int, default=None, metavar="N",
                   help="particle and map estimators: number of particles (default 4096 for particle; for map 2048 in the "
                        "plane, 8192 in space)")
    p.add_argument("--seed", "--particle-seed", dest="seed", type=int, default=None, metavar="S",
                   help="seed of the estimator's random numbers (default 0): the particle estimators' particles, the "
                        "sampled posteriors behind the filters' Gaussian sums and every sampled covariance, the "
                        "reference smoother's included; the same seed gives the same answer, another shows its Monte "
                        "Carlo spread (--particle-seed: its old name)")
    p.add_argument("--most-likely", action="store_true",
                   help="smoother, map: always report the most likely track or state (by default, where the "
                        "posterior is skewed about it, the posterior mean, which is closer to the truth on average)")
    p.add_argument("--no-rescue", action="store_true",
                   help="map, particle: never sample the particles again about the posterior's mode where the best "
                        "of them falls further below it than a sample of the posterior would (by default map does, "
                        "and particle in 3-D, and each says so in an event)")
    p.add_argument("--check-every", action=argparse.BooleanOptionalAction, default=None,
                   help="map, particle: make the restart test (a fresh fit of all the data so far) at every "
                        "checkpoint, not only where the data surprise them; by default map does in 3-D, where it "
                        "finds wrong basins the data leave slowly at about 3 times the CPU time, and particle "
                        "never (--no-check-every: only where surprised)")
    p.add_argument("--mode-candidates", type=int, default=None, metavar="N",
                   help="smoother: grid candidates its whole-recording mode search refines (default 20; 0 turns "
                        "the search off: faster, but a track in a wrong mode of the likelihood can be reported ok)")


def _geometry_spec(args: argparse.Namespace) -> str:
    """The geometry to use: --geometry, else geometry.toml beside FILE; never a silent default."""
    if args.geometry is not None:
        return str(args.geometry)
    beside = args.file.parent / "geometry.toml"
    if beside.is_file():
        return str(beside)
    raise CLIError(f"no geometry for {args.file}: pass --geometry a|b|FILE.toml, or put a geometry.toml "
                   "beside it (fgdoppler simulate writes one)")


def _describe(geometry: Any, spec: str) -> dict[str, Any]:
    """The geometry and its zone as recorded in every output."""
    return {"geometry": {"source": spec, "name": geometry.name,
                         "pairs": [{"tx": list(p.tx), "rx": list(p.rx),
                                    **({"name": geometry.pair_names[i]} if geometry.pair_names else {}),
                                    **({"wavelength": geometry.wavelengths[i]} if geometry.wavelengths else {})}
                                   for i, p in enumerate(geometry.pairs)],
                         **({"geodetic_origin": geometry.geodetic_origin.to_list()}
                            if geometry.geodetic_origin is not None else {})},
            "zone": geometry.zone.to_dict()}


def _sigma_note(args: argparse.Namespace, names: tuple[str, ...]) -> None:
    """Say on stderr that ``--sigma`` went unused where the file's header ``names`` give every measurement's own
    sigma."""
    if args.sigma is None:
        return
    column = next((c for c in ("sigma", "sigma_hz") if c in names), None)
    if column is not None:
        print(f"note: --sigma {args.sigma:g} is not used: {args.file} gives each measurement's sigma (its {column} "
              "column)", file=sys.stderr)


def _dropped_repeats(args: argparse.Namespace, meas: Any, geom: Geometry) -> tuple[Any, dict[str, Any]]:
    """``meas`` without the repeats of the pairs found repeating (``--drop-repeats``; the verdict's level), said
    on stderr, and the JSON's ``dropped_repeats`` entry (pair index -> repeats left out); as read otherwise."""
    from fgdoppler.estimators.judge import LEVEL
    from fgdoppler.repeats import drop_repeats, find_repeats

    if not args.drop_repeats:
        return meas, {}
    found = find_repeats(meas, level=LEVEL)
    if not found:
        print("--drop-repeats: no pair repeats its values more often than noise allows; every measurement kept",
              file=sys.stderr)
    for r in found:
        what = ("each equal to the one before" if r.fixed is None else
                f"the repeats and every {r.fixed:g} m/s (a fixed value)")
        print(f"--drop-repeats: left out {r.rows.size} of pair {geom.pair_label(r.pair)}'s {r.measurements} "
              f"measurements, {what}", file=sys.stderr)
    return drop_repeats(meas, found), {"dropped_repeats": {str(r.pair): int(r.rows.size) for r in found}}


def _model(args: argparse.Namespace, geometry: Any) -> Any:
    from fgdoppler.models.tracking import TrackingModel

    kw: dict[str, Any] = {"weak_prior": not args.no_weak_prior}
    if args.q is not None:
        kw["motion"] = motion(args.q)
    return TrackingModel.of(geometry, **kw)


def _initiation_settings(args: argparse.Namespace) -> Any:
    from fgdoppler.estimators.grid import HalfPlane
    from fgdoppler.estimators.initiation import InitiationSettings

    hp = None
    if args.half_plane is not None:
        px, py, nx, ny = args.half_plane
        hp = HalfPlane(point=(px, py), normal=(nx, ny))
    return InitiationSettings(method=args.init_method, k_best=args.k_best, region_bound=not args.no_region_bound,
                              half_plane=hp, grid=grid_spec(args), huber_k=huber(args))


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse output paths that cannot be written as asked, before anything runs."""
    from fgdoppler import plotting

    if args.out is not None and args.out.suffix.lower() != ".csv":
        raise CLIError(f"--out {args.out}: give a .csv path (the JSON is written beside it, with .json)")
    if args.plot is not None:
        fmt = args.plot.suffix.lower().lstrip(".")
        if fmt not in plotting.figure_formats():
            raise CLIError(f"--plot {args.plot}: unknown figure format {fmt!r} (use one of "
                           f"{', '.join(sorted(plotting.figure_formats()))})")


def _refuse_tracker_options(args: argparse.Namespace) -> None:
    """A CLIError for the first option given that only a tracker takes, with ``--estimator init``."""
    if args.particles is not None:
        raise CLIError("--particles applies to --estimator particle or map, not to init")
    if args.seed is not None:
        raise CLIError("--seed applies to the trackers, not to init (the initiation draws no random numbers)")
    if args.lag is not None:
        raise CLIError("--lag applies to fixed-lag, not to init")
    if args.most_likely:
        raise CLIError("--most-likely applies to the smoother and map, not to init")
    if args.no_rescue:
        raise CLIError("--no-rescue applies to --estimator particle or map, not to init")
    if args.check_every is not None:
        raise CLIError("--check-every applies to --estimator particle or map, not to init")
    if args.mode_candidates is not None or args.estimate_offsets:
        option = "--mode-candidates" if args.mode_candidates is not None else "--estimate-offsets"
        raise CLIError(f"{option} applies to the smoother, not to init")
    for values, option, field in ((args.bias_sigma, "--bias-sigma", "bias_sigma"),
                                  (args.clock_sigma, "--clock-sigma", "clock_sigma"),
                                  (args.site_sigma, "--site-sigma", "site_sigma")):
        if values is not None:
            raise CLIError(f"{option} applies to {', '.join(taking(field))}, not to init")


def _check_declared_counts(args: argparse.Namespace, geom: Geometry) -> None:
    """A CLIError where ``--bias-sigma`` or ``--clock-sigma`` has neither one value nor one per pair of ``geom``,
    or ``--site-sigma`` neither one value nor one per site."""
    if args.bias_sigma is not None:
        per_pair(args.bias_sigma, geom.n_pairs, "--bias-sigma")
    if args.clock_sigma is not None:
        per_pair(args.clock_sigma, geom.n_pairs, "--clock-sigma")
    if args.site_sigma is not None:
        from fgdoppler.estimators.site_offsets import site_sigmas

        try:
            site_sigmas(one_or_each(args.site_sigma), geom)
        except ValueError as exc:
            raise CLIError(f"--site-sigma: {exc}") from None


def _check_readable(path: Path) -> None:
    """Refuse a FILE that cannot be opened, in the CSV reader's words.

    It comes first, before the estimators are imported (a second or more): a mistyped name is the mistake to
    report, at once, and not the missing geometry it implies.  The contents wait for the geometry (pairs may be
    named in it).  A pipe is not opened here: opening a named one twice could lose what its writer sent between.
    """
    try:
        if path.is_dir() or path.is_file() or not path.exists():
            path.open("rb").close()
    except OSError as exc:
        raise CLIError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _run(args: argparse.Namespace) -> int:
    _check_readable(args.file)
    from fgdoppler.csvfile import header_names
    from fgdoppler.estimators.initiation import initiate
    from fgdoppler.estimators.judge import repeat_reasons
    from fgdoppler.measurements import Measurements
    from fgdoppler.simulation import Trajectory

    _check_outputs(args)
    tracker = None
    if args.estimator != "init":  # bad tracker options are reported before any work
        tracker = _tracker_settings(args, ALIASES.get(args.estimator, args.estimator))
    else:
        _refuse_tracker_options(args)
    if args.init_per_pair < 3:
        raise CLIError("--init-per-pair must be >= 3")
    if not (math.isfinite(args.init_seconds) and args.init_seconds >= 0):
        raise CLIError(f"--init-seconds must be a finite number >= 0, got {args.init_seconds:g}")
    spec = _geometry_spec(args)
    geom = geometry_with_zone(spec, args)
    meas = Measurements.from_csv(args.file, geometry=geom, default_sigma=args.sigma,
                                 ignore_columns=tuple(args.ignore_column))
    names = header_names(args.file) if args.file.is_file() else ()  # a pipe was read once already
    _sigma_note(args, names)
    meas, dropped = _dropped_repeats(args, meas, geom)
    truth = None
    if args.truth:
        truth = Trajectory.from_csv(args.truth)
        if truth.dim != geom.dim:
            hint = ("give the geometry an altitude band (--altitude LO HI or [zone] altitude) or sensors with z"
                    if truth.dim == 3 else "the geometry is 3-D (an altitude band or sensors with z)")
            raise CLIError(f"{args.truth}: the truth is {truth.dim}-D but the problem is {geom.dim}-D: {hint}")
        truth.check_covers(meas.scans().times, str(args.truth))
    model = _model(args, geom)
    _check_declared_counts(args, geom)
    settings = _initiation_settings(args)
    window = meas.initiation_window(args.init_per_pair, args.init_seconds)
    try:
        init = initiate(window, model, settings)
    except ValueError as exc:  # e.g. the data need a speed above the zone's bound
        raise CLIError(f"{args.file}: {exc}") from None
    where = {**_describe(geom, spec), **dropped}
    if not args.json:
        z = geom.zone
        height = "" if z.altitude is None else f", height {z.altitude[0]:g}..{z.altitude[1]:g} m (3-D)"
        # the zone is every estimator's prior: a default one is an assumption the user has not made yet
        rule = " (the default rule's; every verdict assumes the target starts in it: --zone if it may not)" \
            if geom.zone_limits.empty else ""
        print(f"geometry {spec} ({geom.n_pairs} pair(s)); zone along {z.along[0]:g}..{z.along[1]:g} m, across "
              f"{z.across[0]:g}..{z.across[1]:g} m{height} in the sensors' frame, speed up to {z.speed_max:g} m/s"
              f"{rule}")
        if geom.geodetic_origin is not None:
            o = geom.geodetic_origin
            print(f"positions in metres east, north{' and up' if geom.dim == 3 else ''} of latitude {o.latitude:.6f}, "
                  f"longitude {o.longitude:.6f}, height {o.height:g} m (WGS84); --out and --json add each state's "
                  "latitude and longitude")
        if "doppler_hz" in names:
            print("doppler_hz read as the bistatic range rate -wavelength * doppler_hz, with wavelengths "
                  + ", ".join(f"{v:g}" for v in geom.wavelengths) + " m (every result is in m and m/s)")
    if args.estimator == "init":
        # a track's verdict tests the whole recording for repeats; the window's is tested here
        init = replace(init, reasons=(*init.reasons, *repeat_reasons(window, model)))
        status = _report_initiation(args, init, window, geom, truth, where)
    else:
        status = _run_tracker(args, tracker, init, meas, model, truth, where)
    return _exit_status(status, args)


#: Exit status of ``track`` when the verdict is ``failed`` (without ``--allow-failed``).
EXIT_FAILED = 3


def _exit_status(status: str, args: argparse.Namespace) -> int:
    if status == "failed" and not args.allow_failed:
        print(f"fgdoppler track: the verdict is 'failed' (exit status {EXIT_FAILED}; --allow-failed to exit 0)",
              file=sys.stderr)
        return EXIT_FAILED
    return 0


def _print_verdict(status: str, reasons: Any) -> None:
    """The verdict, on stderr (also with --json)."""
    print(f"fgdoppler track: status {status}", file=sys.stderr)
    for r in reasons:
        print(f"  {r.status}: {r.message}", file=sys.stderr)


def _print_half_plane_hint(reasons: Any, geom: Geometry, args: argparse.Namespace, pairs: Any) -> None:
    """Where a finding says a mirror image fits the data (:attr:`~fgdoppler.estimators.verdict.Reason.mirror`),
    the ``--half-plane`` options of either side of the line it is taken across, in the user's coordinates: the
    least-squares line of every sensor (the smoother's mirror rival, the initiation's mirror start), the line
    the sensors of the reporting ``pairs`` lie on (the ``data`` finding), or the one the finding's own pairs lie
    on (a side that few measurements of the other pairs settle)."""
    if args.half_plane is not None or geom.dim != 2:
        return
    # a settled ambiguity (the filters' hypotheses) needs none
    mirrored = {r.mirror: r for r in reversed(list(reasons)) if r.status != "ok" and r.mirror is not None}
    line = "the sensors' line"
    if "reporting" in mirrored:
        used = np.unique(np.asarray(pairs, dtype=int))
        sensors = np.vstack([geom.tx[used], geom.rx[used]])
    elif "pairs" in mirrored:  # the side rests on few measurements of the other pairs
        on = list(mirrored["pairs"].pairs or ())
        sensors = np.vstack([geom.tx[on], geom.rx[on]])
        line = f"the line of the sensors of {pairs_text(on, geom.pair_label)}"
    elif "sensors" in mirrored:  # a mirror rival: competing, ambiguous
        sensors = np.vstack([geom.tx, geom.rx])
    else:
        return
    c, u, _ = principal_line(sensors[:, :2])
    c, u = c + 0.0, u + 0.0  # no "-0" printed
    n = np.array([-u[1], u[0]]) + 0.0
    # the point to the millimetre in full (a UTM northing with :g is "4.51235e+06"), the directions to 6 digits
    at = [plain_number(v, 3) for v in c]
    side = " ".join([*at, *(f"{v:.6g}" for v in n)])
    other = " ".join([*at, *(f"{v:.6g}" for v in 0.0 - n)])
    print(f"  hint: {line} passes through ({at[0]}, {at[1]}) along ({u[0]:.6g}, {u[1]:.6g}); "
          f"--half-plane {side} puts the target on one side of it, --half-plane {other} on the other",
          file=sys.stderr)


def zone_hint(reasons: Any) -> str | None:
    """The options of the smallest zone holding every zone the ``doubtful``/``failed`` findings advise
    (:attr:`~fgdoppler.estimators.verdict.Reason.zone`), where they advise more than one (e.g. the
    initiation's, for its window's start alone, and the offline smoother's, for the whole recording's start
    and its mirror image's); ``None`` otherwise.  Each advised zone holds the given one, so their union box is
    one a user can give and every start they name lies in it."""
    advised = {r.zone.options(): r.zone for r in reasons if r.status != "ok" and r.zone is not None}
    if len(advised) < 2:
        return None
    return functools.reduce(ZoneBox.union, advised.values()).options()


def mistake_hint(reasons: Any) -> str | None:
    """The hint to correct a likely mistake in the file or the geometry first, where a finding names one (a
    ``sign``, ``swapped`` or ``radial`` change of the data, the geometry in kilometres or the times in another
    unit) and another advises a zone or a half plane: that advice reads the mistaken data or units as given.
    Likewise to track with the Huber loss first where the initiation window or the whole recording fits without a
    few outliers (an ``outliers`` finding; before the sigma advice too), to give the right sigma first where the
    manoeuvre finding says they look too small, and
    before all of these to leave out repeated values where a ``data`` finding says a pair repeats them (every other
    finding reads them as measurements).  ``None`` otherwise."""
    from fgdoppler.estimators.judge import REPEATS_ADVICE
    from fgdoppler.estimators.later_mistakes import UNCONFIRMED, is_mistake_finding
    from fgdoppler.estimators.manoeuvre import SIGMA_ADVICE
    from fgdoppler.estimators.window_mistakes import (
        IN_KILOMETRES,
        IN_SECONDS,
        OR_OUTSIDE_THE_ZONE,
        WITH_OUTLIERS,
    )

    # a track's findings carry its initiation's under the "initiation-" prefix; both name the mistake alike
    if any(r.status != "ok" and REPEATS_ADVICE in r.message for r in reasons):
        return ("a pair repeats its values (the data finding above): track again with --drop-repeats, or without "
                "the pair, before following any other advice, which reads the repeats as measurements")
    mistakes = [r for r in reasons if r.status != "ok" and is_mistake_finding(
        replace(r, code=r.code.removeprefix("initiation-")))]
    if any(IN_KILOMETRES in r.message for r in mistakes):
        return ("the geometry is likely in kilometres (the units finding above): give it in metres before "
                "following any zone advice, which reads it as metres")
    if any(IN_SECONDS in r.message for r in mistakes):
        return ("the times are likely not in seconds (the units finding above): give them in seconds before "
                "following any zone advice, which reads them as seconds")
    outliers = [r for r in reasons if r.status != "ok" and WITH_OUTLIERS in r.message]
    advised = any(r.status != "ok" and (r.zone is not None or r.mirror is not None) for r in reasons)
    # outliers come before sigma that look too small: with them left out the data fit the sigma as given, and their
    # misfit is what made the recording's halves misfit
    if outliers and any(OR_OUTSIDE_THE_ZONE in r.message for r in outliers):
        return ("an outliers finding above says the initiation window fits without a few measurements, "
                "but it fits as given with a start outside the zone too: check those measurements, and if they are "
                "right, follow the zone advice")
    if outliers and advised:
        window = all(r.code.startswith("initiation-") for r in outliers)
        return (f"an outliers finding above says {'the initiation window fits' if window else 'the data fit'} "
                "without a few measurements: track with the Huber loss (--huber) before following any zone, half-plane or sigma "
                "advice, which reads the outliers as data")
    if advised and any(r.status != "ok" and SIGMA_ADVICE in r.message for r in reasons):
        return ("the manoeuvre finding above says the measurements' sigma look too small: give their right sigma "
                "before following any zone or half-plane advice, which reads the misfit they make as the target's")
    if any(OR_OUTSIDE_THE_ZONE in r.message for r in mistakes):
        return (f"a {mistakes[0].code.removeprefix('initiation-')} finding above names a likely mistake in the "
                "measurement file, but the data fit as given with a start outside the zone too: check the file, and "
                "if it is right, follow the zone advice")
    if mistakes and advised and any(r.code == UNCONFIRMED for r in reasons):
        return (f"a {mistakes[0].code.removeprefix('initiation-')} finding above names a possible mistake in the "
                "measurement file that the whole recording does not confirm (the unconfirmed finding): check the file "
                "and the geometry before following any zone or half-plane advice")
    if mistakes and advised:
        return (f"a {mistakes[0].code.removeprefix('initiation-')} finding above names a likely mistake in the "
                "measurement file: correct it before following any zone or half-plane advice, which reads the data "
                "as given")
    return None


def _print_hints(reasons: Any, geom: Geometry, args: argparse.Namespace, pairs: Any) -> None:
    """The ``hint:`` lines after the verdict: to correct a likely mistake first (:func:`mistake_hint`), or else
    the half planes of a mirror ambiguity and the zone holding every zone the findings advise — also after the
    mistake's hint where the data fit as given with a start outside the zone too."""
    from fgdoppler.estimators.window_mistakes import OR_OUTSIDE_THE_ZONE

    first = mistake_hint(reasons)
    if first is not None:
        print(f"  hint: {first}", file=sys.stderr)
        if not any(OR_OUTSIDE_THE_ZONE in r.message for r in reasons):
            return  # else the zone advice is the other explanation: given below
    _print_half_plane_hint(reasons, geom, args, pairs)
    hint = zone_hint(reasons)
    if hint is not None:
        print(f"  hint: the findings above advise different zones; one holding every start they name: {hint}",
              file=sys.stderr)


def _print_events(events: Any, limit: int = 10) -> None:
    """The first events and, when there are more than ``limit``, the last one too: a run's closing summary."""
    events = list(events)
    shown = events if len(events) <= limit else events[:limit - 1]
    for e in shown:
        print(f"  event at t = {time_text(e.time)}: {e.message}")
    if len(events) > limit:
        print(f"  ... {len(events) - limit} more event(s): all are in the JSON (--json, or --out's .json) ...")
        print(f"  event at t = {time_text(events[-1].time)}: {events[-1].message}")


def _write(args: argparse.Namespace, csv_text: str, json_text: str, figure: bytes | None) -> None:
    """Every output at once: nothing is written unless all of them can be."""
    from fgdoppler._io import write_all

    files: dict[Path, str | bytes] = {}
    if args.out is not None:
        files[args.out] = csv_text
        files[args.out.with_suffix(".json")] = json_text
    if figure is not None:
        files[args.plot] = figure
    write_all(files)


def _report_initiation(args: argparse.Namespace, init: Any, window: Any, geom: Any, truth: Any,
                       where: dict[str, Any]) -> str:
    from fgdoppler.estimators.results import json_dumps

    columns, geodetic = _geodetic(geom, np.array([init.x_start, init.x_end]))
    payload = {**init.to_dict(), **where, **geodetic}
    text = json_dumps(payload)
    figure = _plot_landscape(args, init, window, geom, truth) if args.plot else None
    _write(args, init.csv_text(header=tuple(_csv_header(where)), columns=columns), text, figure)
    _print_verdict(init.status, init.reasons)
    _print_hints(init.reasons, geom, args, window.pair)
    if args.json:
        emit_json(payload)
        return str(init.status)
    print(f"initiation ({init.method}) from {init.n_measurements} measurements, "
          f"t = {time_text(init.t_start)}..{time_text(init.t_end)} s, {init.wall_time * 1e3:.0f} ms")
    print(f"  state at t_end: {_state_text(init.x_end)}")
    if init.P_end is not None:
        print(f"  std: {_state_text(np.sqrt(np.diag(init.P_end)), names=False)}")
    verdict = "passes" if init.passes_chi2 else "FAILS"
    print(f"  cost {init.cost:.2f} {verdict} the chi-square test ({init.chi2_threshold:.2f}, {init.dof} dof); "
          f"objective with prior and zone terms {init.objective:.2f}")
    weights = init.posterior_shares()
    if weights is not None:
        print(f"    this solution holds {weights[0]:.1%} of the window posterior in the zone")
    for i, a in enumerate(init.alternatives):
        share = "" if weights is None else f", {weights[i + 1]:.1%} of the posterior"
        print(f"    alternative x0 = {np.round(a.state, 1).tolist()} cost {a.cost:.2f}{share}")
    _print_events(init.events)
    if truth is not None:
        err = init.x_end - truth.at([init.t_end])[0]
        d = err.size // 2
        print(f"  error at t_end: position {np.linalg.norm(err[:d]):.1f} m, velocity {np.linalg.norm(err[d:]):.2f} m/s")
    if args.out is not None:
        print(f"  wrote {args.out} and {args.out.with_suffix('.json')}")
    return str(init.status)


def _plot_landscape(args: argparse.Namespace, init: Any, window: Any, geom: Any, truth: Any) -> bytes:
    from fgdoppler import plotting
    from fgdoppler.analysis.observability import default_along
    from fgdoppler.estimators.initiation import residual_landscape

    if geom.dim == 3:
        raise CLIError("--plot with --estimator init draws the 2-D residual landscape (x0 x heading), which a 3-D "
                       "problem does not have: plot a tracker's result instead (e.g. --estimator smoother)")
    xs = default_along(geom)
    hs = np.arange(0.0, 360.0, 2.0)
    start = geom.frame.states_to_local(init.x_start)
    speed = float(np.hypot(*start[2:]))
    cost = residual_landscape(window, geom, x=xs, heading_deg=hs, y0=float(start[1]), speed=speed)
    others = [geom.frame.states_to_local(c.state) for c in (*init.candidates[1:], *init.alternatives)]
    t0 = geom.frame.states_to_local(truth.at([init.t_start])[0]) if truth is not None else None
    ax = plotting.plot_landscape(xs, hs, cost, best=start, others=others, truth=t0)
    ax.set_title(f"residual over x0 x heading at y0 = {start[1] / 1e3:.2f} km, speed {speed:.0f} m/s "
                 "(sensors' frame)", fontsize="small")
    return plotting.figure_bytes(ax, args.plot.suffix.lower().lstrip("."))


def _tracker_settings(args: argparse.Namespace, name: str) -> Any:
    """The settings of tracker ``name`` from the options (a CLIError for values it rejects)."""
    from fgdoppler.estimators.registry import ESTIMATORS
    from fgdoppler.estimators.settings import FixedLagSettings, ParticleSettings, SmootherSettings

    k = huber(args)
    particle = {} if args.particles is None else {"n_particles": args.particles}
    sampled = ", ".join(n for n, i in ESTIMATORS.items() if issubclass(i.settings, ParticleSettings))
    for given, option in ((bool(particle), "--particles"), (args.no_rescue, "--no-rescue"),
                          (args.check_every is not None, "--check-every")):
        if given and not issubclass(ESTIMATORS[name].settings, ParticleSettings):
            raise CLIError(f"{option} applies to the particle estimators ({sampled}), not to {name}")
    if args.most_likely and name not in ("smoother", "map"):
        raise CLIError(f"--most-likely applies to the smoother and map, not to {name}")
    for given, option in ((args.mode_candidates is not None, "--mode-candidates"),
                          (args.estimate_offsets, "--estimate-offsets")):
        if given and name != "smoother":
            raise CLIError(f"{option} applies to the smoother, not to {name}")
    if args.lag is not None and name != "fixed-lag":
        raise CLIError(f"--lag applies to fixed-lag, not to {name}")
    if args.estimate_offsets and args.bias_sigma is None:
        raise CLIError("--estimate-offsets needs --bias-sigma (each pair's offset prior)")
    if args.seed is not None and args.seed < 0:
        raise CLIError(f"--seed must be a whole number >= 0, got {args.seed}")
    shared: dict[str, Any] = {} if args.seed is None else {"seed": args.seed}
    for values, option, field in ((args.bias_sigma, "--bias-sigma", "bias_sigma"),
                                  (args.clock_sigma, "--clock-sigma", "clock_sigma"),
                                  (args.site_sigma, "--site-sigma", "site_sigma")):
        if values is not None and name not in taking(field):
            raise CLIError(f"{option} applies to {', '.join(taking(field))}, not to {name}")
        if values is not None:
            shared[field] = one_or_each(values)
    try:
        ESTIMATORS[name].settings(huber_k=k, **shared)
    except ValueError as exc:
        raise offset_sigma_error(exc) from None
    if name == "smoother":
        modes: dict[str, Any] = {}
        if args.mode_candidates is not None:
            if args.mode_candidates < 0:
                raise CLIError(f"--mode-candidates must be >= 0 (0: no mode search), got {args.mode_candidates}")
            modes = {"mode_search": False} if args.mode_candidates == 0 else {"mode_candidates": args.mode_candidates}
        try:
            return SmootherSettings(huber_k=k, posterior_mean=not args.most_likely, estimate_offsets=args.estimate_offsets,
                                    **modes, **shared)
        except ValueError as exc:  # offsets to estimate where every pair's bias_sigma is 0
            raise CLIError(f"--estimate-offsets: {exc}") from None
    try:
        lag = {} if args.lag is None else {"lag": args.lag}
        # --most-likely: map only; --no-rescue: the particle estimators (checked above)
        read_out = {**({"posterior_mean": False} if args.most_likely else {}),
                    **({"mode_rescue": False} if args.no_rescue else {}),
                    **({} if args.check_every is None else {"check_every": args.check_every})}
        return (FixedLagSettings(huber_k=k, **lag, **shared) if name == "fixed-lag"
                else ESTIMATORS[name].settings(huber_k=k, **particle, **read_out, **shared))
    except ValueError as exc:
        raise CLIError(f"--{'lag' if name == 'fixed-lag' else 'particles'}: {exc}") from None


def _run_tracker(args: argparse.Namespace, settings: Any, init: Any, meas: Any, model: Any, truth: Any,
                 where: dict[str, Any]) -> str:
    from fgdoppler import plotting
    from fgdoppler.estimators.registry import run_estimator
    from fgdoppler.progress import TqdmProgress

    name = args.estimator
    if name in ALIASES:
        print(f"note: --estimator {name} is now called {ALIASES[name]}", file=sys.stderr)
        name = ALIASES[name]
    with TqdmProgress() as bar:  # drawn on stderr only when it is a terminal
        result = run_estimator(name, meas, model, init, settings, progress=bar)
    e = result.primary
    figure = None
    if args.plot:
        ax = plotting.plot_track(e.times, e.states, model.geometry, covariances=e.covariances, cov_ok=e.cov_ok,
                                 truth=None if truth is None else truth.states, label=f"{name} ({e.kind})")
        figure = plotting.figure_bytes(ax, args.plot.suffix.lower().lstrip("."))
    columns, geodetic = _geodetic(model.geometry, e.states)
    extra = {**where, **geodetic}
    _write(args, result.csv_text(header=_csv_header(where), columns=columns), result.json_text(extra=extra), figure)
    _print_verdict(result.status, result.reasons)
    _print_hints(result.reasons, model.geometry, args, meas.pair)
    if args.json:
        emit_json({**result.to_dict(all_estimates=False), **extra})
        return str(result.status)
    print(f"{name}: {len(e)} states ({e.kind}), t = {time_text(e.times[0])}..{time_text(e.times[-1])} s, "
          f"{result.wall_time * 1e3:.0f} ms")
    print(f"  last state: {_state_text(e.states[-1])}")
    if columns:
        print("  last position: " + ", ".join(f"{k} {v[-1]:.6f}°" if k != "height" else f"{k} {v[-1]:.0f} m"
                                             for k, v in columns.items()) + " (WGS84)")
    _print_events(result.events)
    if truth is not None:
        err = e.states - truth.at(e.times)
        d = e.dim
        rmse = float(np.sqrt(np.mean(np.sum(err[:, :d] ** 2, axis=1))))
        print(f"  position RMSE vs truth: {rmse:.1f} m; final error {np.linalg.norm(err[-1, :d]):.1f} m")
    if args.out is not None:
        print(f"  wrote {args.out} and {args.out.with_suffix('.json')}")
    return str(result.status)


def _geodetic(geometry: Geometry, states: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """Where the sensors were given as latitude and longitude, each state's latitude, longitude (and height) as
    the track CSV's columns and as the JSON's ``geodetic`` entry; nothing otherwise."""
    if geometry.geodetic_origin is None:
        return {}, {}
    columns = geometry.geodetic_origin.columns(states)
    return columns, {"geodetic": {k: v.tolist() for k, v in columns.items()}}


def _state_text(x: Any, *, names: bool = True) -> str:
    """``x = 1.0 m, y = ..., vx = ... m/s`` for a 2-D or 3-D state (values only with ``names=False``)."""
    from fgdoppler.estimators.results import STATE_NAMES

    labels = STATE_NAMES[len(x)]
    d = len(x) // 2
    parts = [f"{v:.1f} m" if i < d else f"{v:.2f} m/s" for i, v in enumerate(x)]
    return ", ".join(f"{n} = {p}" for n, p in zip(labels, parts, strict=True)) if names else ", ".join(parts)


def _csv_header(where: dict[str, Any]) -> list[str]:
    """Comment lines that record the geometry and the zone in the track CSV."""
    g, z = where["geometry"], where["zone"]
    return [f"geometry: {g['source']} name={g['name'] or '-'} pairs="
            + ";".join(f"tx={p['tx']} rx={p['rx']}" + (f" name={p['name']}" if "name" in p else "")
                       + (f" wavelength={p['wavelength']}" if "wavelength" in p else "") for p in g["pairs"]),
            *([f"geodetic: x, y, z are metres east, north and up of latitude {g['geodetic_origin'][0]!r}, longitude "
               f"{g['geodetic_origin'][1]!r}, height {g['geodetic_origin'][2]!r} m (WGS84); latitude, longitude "
               "(and height) follow the covariance"] if "geodetic_origin" in g else []),
            f"zone: along={z['along']} across={z['across']} "
            + (f"altitude={z['altitude']} " if "altitude" in z else "")
            + f"speed_max={z['speed_max']} "
            f"frame_origin={z['frame']['origin']} frame_basis={z['frame']['basis']}"]
