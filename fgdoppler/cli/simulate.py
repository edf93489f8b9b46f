"""``fgdoppler simulate``: write a scenario's measurements, truth and geometry."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fgdoppler._io import write_all
from fgdoppler.cli.common import (
    CLIError,
    add_scenario_options,
    add_zone_options,
    east_north_of,
    emit_json,
    geometry_with_zone,
    per_pair,
    scenario,
    zone_holding_start,
)

__all__ = ["add_simulate"]


def add_simulate(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "simulate",
        help="simulate a scenario and write measurements.csv, truth.csv, geometry.toml",
        description="Simulate a target seen by any geometry (a paper preset or a TOML file) and write "
        "measurements.csv, truth.csv and geometry.toml (with the zone options as its [zone] table) into --out.  "
        "Where the geometry gives the pairs' carrier wavelengths (its file, or --wavelength), the measurements "
        "are written as Doppler shifts in Hz (columns doppler_hz, sigma_hz), as a receiver reports them.",
    )
    p.add_argument("--geometry", "--case", dest="geometry", default="a",
                   help="geometry: the paper's a or b, or a geometry TOML file (default a; --case is the old name)")
    p.add_argument("--start-x", type=float, default=25e3, help="initial x in metres (default 25000)")
    p.add_argument("--start-y", type=float, default=2e3, help="initial y in metres (default 2000)")
    p.add_argument("--start-lat-lon", type=float, nargs=2, default=None, metavar=("LAT", "LON"),
                   help="initial position as WGS84 latitude and longitude in degrees instead of --start-x/--start-y "
                        "(the geometry must give its sites so: a [geodetic] table)")
    p.add_argument("--start-z", type=float, default=None,
                   help="initial height in metres: a 3-D target (the geometry must be 3-D: --altitude or "
                   "sensors with z)")
    p.add_argument("--wavelength", type=float, nargs="+", default=None, metavar="M",
                   help="each pair's carrier wavelength in metres (one value or one per pair; c / f_c, e.g. 3.05 for "
                        "98.3 MHz): written into geometry.toml, and measurements.csv gives the Doppler in Hz")
    add_scenario_options(p)
    add_zone_options(p)
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--out", type=Path, default=Path("output/simulation"), help="output folder")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from fgdoppler.simulation import simulate

    geom = geometry_with_zone(args.geometry, args)
    if args.wavelength is not None:
        values = per_pair(args.wavelength, geom.n_pairs, "--wavelength")
        before = geom.wavelengths
        try:
            geom = replace(geom, wavelengths=values if isinstance(values, tuple) else (values,) * geom.n_pairs)
        except ValueError as exc:
            raise CLIError(f"--wavelength: {exc}") from None
        if before and before != geom.wavelengths:  # the user's option wins, and the file's values are not lost silently
            print(f"note: --wavelength replaces the geometry's wavelengths ({', '.join(f'{v:g}' for v in before)} m) "
                  f"with {', '.join(f'{v:g}' for v in geom.wavelengths)} m in the files written", file=sys.stderr)
    x, y = _start_xy(args, geom)
    start = (x, y) if args.start_z is None else (x, y, args.start_z)
    height = "" if args.start_z is None else f", height {args.start_z:g} m"
    scen = scenario(args, geom, start,
                    f"{geom.name or 'custom geometry'}, start ({x / 1e3:g}, {y / 1e3:g}) km{height}")
    sim = simulate(scen, np.random.default_rng(args.seed))
    out: Path = args.out
    hz = geom.wavelengths or None  # a receiver's own unit where the geometry gives it
    write_all({out / "measurements.csv": sim.measurements.csv_text(wavelengths=hz),
               out / "truth.csv": sim.truth.csv_text(),
               out / "geometry.toml": geom.toml_text()})
    summary: dict[str, Any] = {
        "scenario": scen.name,
        "measurements": len(sim.measurements),
        "states": int(sim.truth.times.size),
        "files": [str(out / f) for f in ("measurements.csv", "truth.csv", "geometry.toml")],
    }
    if scen.site_error:
        summary["site_error"] = scen.site_errors.tolist()
    outside = zone_holding_start(geom, scen.x0)
    if outside is not None:
        summary["zone_holding_start"] = outside
    if args.json:
        emit_json(summary)
    else:
        print(f"{scen.name}: {summary['measurements']} measurements, {summary['states']} truth states")
        if scen.site_error:
            print("  the measurements are those of the sites moved by --site-error; geometry.toml gives them where "
                  "declared, as a tracker would be told")
        for f in summary["files"]:
            print(f"  wrote {f}")
    if outside is not None:
        print(f"note: the start lies outside the zone the trackers will assume ({geom.zone.options()}): `fgdoppler "
              f"track` may report a track that starts inside it, with status ok.  Give {outside} to simulate "
              f"(geometry.toml keeps it) or to track", file=sys.stderr)
    return 0


def _start_xy(args: argparse.Namespace, geom: Any) -> tuple[float, float]:
    """The start's x and y in metres: as given, or east and north of the geometry's origin for a latitude and
    longitude (on the origin's horizontal plane; ``--start-z`` stays metres up)."""
    if args.start_lat_lon is None:
        return float(args.start_x), float(args.start_y)
    lat, lon = args.start_lat_lon
    return east_north_of(geom, lat, lon, "--start-lat-lon")
