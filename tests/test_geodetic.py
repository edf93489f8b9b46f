"""Sensors given as latitude, longitude and height: the local east-north-up frame, the file, the track's columns."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.cli import main
from fgdoppler.geodetic import GeodeticOrigin
from fgdoppler.zone import ZoneLimits

# WGS84, for the independent Earth-centred positions below
A, F = 6378137.0, 1 / 298.257223563
E2 = F * (2 - F)

SITES = """\
name = "fm site"
[geodetic]
{origin}
[[pair]]
tx = [51.95, 0.25{h_tx}]
rx = [51.50, -0.12{h_rx}]
[[pair]]
tx = [51.95, 0.25{h_tx}]
rx = [51.52, 0.30]
"""


def _ecef(lat: float, lon: float, h: float) -> np.ndarray:
    """The Earth-centred position of a geodetic point (the standard closed form)."""
    p, q = np.radians(lat), np.radians(lon)
    n = A / np.sqrt(1 - E2 * np.sin(p) ** 2)
    return np.array([(n + h) * np.cos(p) * np.cos(q), (n + h) * np.cos(p) * np.sin(q), (n * (1 - E2) + h) * np.sin(p)])


def _write(tmp_path: Path, origin: str = "", h_tx: str = "", h_rx: str = "") -> Path:
    path = tmp_path / "sites.toml"
    path.write_text(SITES.format(origin=origin, h_tx=h_tx, h_rx=h_rx))
    return path


def test_the_local_frame_keeps_every_distance_of_the_earth_centred_one() -> None:
    """East-north-up is a rigid motion of the Earth-centred frame: the distances between points 1-200 km apart at
    heights 0-10 km are the Earth-centred ones (closed form above) to 1e-6 m; a point straight above the origin is
    (0, 0, h), one due north on its meridian has no east component, and the inverse returns the points."""
    rng = np.random.default_rng(2)
    origin = GeodeticOrigin(latitude=-33.9, longitude=151.2, height=40.0)
    lat = origin.latitude + rng.uniform(-1, 1, 12)
    lon = origin.longitude + rng.uniform(-1.2, 1.2, 12)
    h = rng.uniform(0, 1e4, 12)
    e, n, u = origin.to_local(lat, lon, h)
    local = np.column_stack([e, n, u])
    ecef = np.array([_ecef(*p) for p in zip(lat, lon, h, strict=True)])
    for i in range(12):
        np.testing.assert_allclose(np.linalg.norm(local - local[i], axis=1), np.linalg.norm(ecef - ecef[i], axis=1),
                                   rtol=0, atol=1e-6)
    np.testing.assert_allclose(origin.to_local(-33.9, 151.2, 1040.0), (0.0, 0.0, 1000.0), atol=1e-6)
    east, north, _ = origin.to_local(-33.0, 151.2, 40.0)
    assert abs(east) < 1e-6 and north > 99e3
    back = origin.to_geodetic(e, n, u)
    np.testing.assert_allclose(back[0], lat, atol=1e-10)
    np.testing.assert_allclose(back[1], lon, atol=1e-10)
    np.testing.assert_allclose(back[2], h, atol=1e-6)


def test_a_file_of_latitudes_and_longitudes_is_read_in_the_local_frame(tmp_path: Path) -> None:
    """Latitude and longitude alone: a 2-D geometry of east and north about pair 0's receiver (or the origin given);
    a height anywhere: 3-D, sensors without one at height 0.  Written back, the file holds the local positions
    and their origin, and reads back exactly; a change of frame or scale drops the origin, a new zone keeps it."""
    flat = fd.Geometry.from_toml(_write(tmp_path))
    assert flat.dim == 2 and flat.geodetic_origin == GeodeticOrigin(latitude=51.5, longitude=-0.12)
    np.testing.assert_array_equal(flat.rx[0], [0.0, 0.0])
    e, n, _ = flat.geodetic_origin.to_local([51.95, 51.52], [0.25, 0.30])
    np.testing.assert_allclose(flat.tx[0], [e[0], n[0]], rtol=1e-15)
    np.testing.assert_allclose(flat.rx[1], [e[1], n[1]], rtol=1e-15)
    assert flat.extent > 50e3
    lifted = fd.Geometry.from_toml(_write(tmp_path, origin="origin = [51.6, 0.0, 15.0]", h_tx=", 300.0",
                                          h_rx=", 20.0"))
    assert lifted.dim == 3 and lifted.geodetic_origin == GeodeticOrigin(latitude=51.6, longitude=0.0, height=15.0)
    tx = _ecef(51.95, 0.25, 300.0)
    for i, sensor in enumerate((_ecef(51.50, -0.12, 20.0), _ecef(51.52, 0.30, 0.0))):  # the two receivers
        assert np.linalg.norm(lifted.tx[i] - lifted.rx[i]) == pytest.approx(np.linalg.norm(tx - sensor), abs=1e-6)
    for g in (flat, lifted):
        g.to_toml(tmp_path / "back.toml")
        assert "positions = \"enu\"" in (tmp_path / "back.toml").read_text()
        assert fd.Geometry.from_toml(tmp_path / "back.toml") == g
        assert g.with_zone(ZoneLimits(speed_max=300.0)).geodetic_origin == g.geodetic_origin
        for moved in (g.in_frame(g.frame), g.scaled(2.0)):
            assert moved.geodetic_origin is None
    assert flat.in_3d().geodetic_origin == flat.geodetic_origin
    assert flat.mirrored_x(0.0).geodetic_origin is None


@pytest.mark.parametrize(
    ("text", "msg", "line"),
    [
        ("[geodetic]\n[[pair]]\ntx = [51.9, 0.2]\nrx = [95.0, 0.1]\n", "pair 0: rx: latitude 95 is outside", 4),
        ("[geodetic]\n[[pair]]\ntx = [51.9, 400.0]\nrx = [51.5, 0.1]\n", "pair 0: tx: longitude 400 is outside", 3),
        ("[geodetic]\n[[pair]]\ntx = [51.9, 0.2, 2e6]\nrx = [51.5, 0.1]\n", "height 2e\\+06 m is beyond", 3),
        ('[geodetic]\n[[pair]]\ntx = ["51.9", 0.2]\nrx = [51.5, 0.1]\n', "tx must be two or three finite numbers", 3),
        ("[geodetic]\n[[pair]]\ntx = [50000.0, 0.0]\nrx = [0.0, 0.0]\n", "latitude 50000 is outside", 3),
        ("[geodetic]\norigin = [51.5]\n[[pair]]\ntx = [51.9, 0.2]\nrx = [51.5, 0.1]\n", "origin must be two", 2),
        ("[geodetic]\npositions = \"utm\"\n[[pair]]\ntx = [51.9, 0.2]\nrx = [51.5, 0.1]\n", "positions must be", 2),
        ("[geodetic]\npositions = \"enu\"\n[[pair]]\ntx = [5e4, 0.0]\nrx = [0.0, 0.0]\n", "needs the origin", None),
        ("[geodetic]\norign = [51.5, 0.1]\n[[pair]]\ntx = [51.9, 0.2]\nrx = [51.5, 0.1]\n", "unknown key 'orign'", 2),
        ("geodetic = 1\n[[pair]]\ntx = [51.9, 0.2]\nrx = [51.5, 0.1]\n", "geodetic must be a table", 1),
    ],
)
def test_a_bad_geodetic_file_is_refused_with_its_line(tmp_path: Path, text: str, msg: str, line: int | None) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=msg) as info:
        fd.Geometry.from_toml(path)
    assert str(info.value).startswith(f"{path}:{line}:" if line else f"{path}:"), str(info.value)


def test_a_track_of_sensors_given_by_latitude_and_longitude_gives_each_states_latitude_and_longitude(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """simulate writes the local positions and their origin; track's CSV and JSON carry each state's latitude and
    longitude (the inverse of the local frame, checked against its states), the CSV still reads back as the
    track, and the summary says what the positions are."""
    folder = tmp_path / "site"
    folder.mkdir()
    _write(folder).rename(folder / "geometry.toml")
    assert main(["simulate", "--geometry", str(folder / "geometry.toml"), "--start-x", "20000", "--start-y", "15000",
                 "--velocity", "60", "-90", "--out", str(folder / "sim")]) == 0
    capsys.readouterr()
    out = tmp_path / "track.csv"
    assert main(["track", str(folder / "sim" / "measurements.csv"), "--estimator", "ekf", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "positions in metres east, north of latitude 51.500000, longitude -0.120000" in printed
    origin = fd.Geometry.from_toml(folder / "sim" / "geometry.toml").geodetic_origin
    assert origin == GeodeticOrigin(latitude=51.5, longitude=-0.12)
    rows = [r for r in out.read_text().splitlines() if not r.startswith("#")]
    assert rows[0].endswith(",P33,latitude,longitude")
    table = np.array([[float(v) for v in r.split(",")] for r in rows[1:]])
    track = fd.TrackResult.read_csv(out, kind="filtered")
    np.testing.assert_array_equal(track.states, table[:, 1:5])
    assert track.cov_ok.all()
    lat, lon, _ = origin.to_geodetic(track.states[:, 0], track.states[:, 1])
    np.testing.assert_array_equal(table[:, -2], lat)
    np.testing.assert_array_equal(table[:, -1], lon)
    assert f"last position: latitude {lat[-1]:.6f}°, longitude {lon[-1]:.6f}° (WGS84)" in printed
    saved = json.loads(out.with_suffix(".json").read_text())
    assert saved["geometry"]["geodetic_origin"] == [51.5, -0.12, 0.0]
    np.testing.assert_array_equal(saved["geodetic"]["latitude"], lat)
    assert "height" not in saved["geodetic"]


def test_simulate_starts_a_target_at_a_latitude_and_longitude(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``--start-lat-lon``: the truth starts east and north of the origin where that latitude and longitude lie on
    the ellipsoid (below the origin's horizontal plane by d^2 / 2R, 57 m at 27 km; with that drop the inverse
    gives them back to 1e-9 degrees); refused for a metric geometry or a latitude out of range."""
    folder = tmp_path / "site"
    folder.mkdir()
    _write(folder).rename(folder / "geometry.toml")
    assert main(["simulate", "--geometry", str(folder / "geometry.toml"), "--start-lat-lon", "51.7", "0.1",
                 "--out", str(folder / "sim")]) == 0
    origin = GeodeticOrigin(latitude=51.5, longitude=-0.12)
    start = fd.Trajectory.from_csv(folder / "sim" / "truth.csv").states[0]
    east, north, up = origin.to_local(51.7, 0.1, 0.0)
    np.testing.assert_allclose(start[:2], [east, north], rtol=0, atol=1e-6)
    lat, lon, _ = origin.to_geodetic(start[0], start[1], up)  # the point on the ellipsoid below the start
    assert abs(lat - 51.7) < 1e-9 and abs(lon - 0.1) < 1e-9
    assert up == pytest.approx(-np.hypot(east, north) ** 2 / (2 * 6.371e6), rel=0.02)  # the drop d^2 / 2R
    capsys.readouterr()
    assert main(["simulate", "--start-lat-lon", "51.7", "0.1", "--out", str(tmp_path / "x")]) == 2
    assert "needs a geometry whose sites are given by latitude and longitude" in capsys.readouterr().err
    assert main(["simulate", "--geometry", str(folder / "geometry.toml"), "--start-lat-lon", "95", "0.1",
                 "--out", str(tmp_path / "x")]) == 2
    assert "latitude 95 is outside" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()



def test_montecarlo_starts_targets_at_latitudes_and_longitudes(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """``montecarlo --start-lat-lon``: one scenario per latitude-longitude pair, each the scenario of
    ``--start-x/--start-y`` at that point's metres east and north of the origin (the same runs, to the bit: a
    scenario's random streams follow its position, so each point is compared where it comes first); refused with
    a metric geometry, an odd count or beside ``--start-x``.  The initiation alone (``lm``) is enough to compare:
    its rows are the RMSE and NEES of each run's window, so another start or another draw changes them."""
    site = _write(tmp_path)
    origin = GeodeticOrigin(latitude=51.5, longitude=-0.12)
    points = [(51.7, 0.1), (51.62, -0.05)]
    common = ["montecarlo", "--geometry", str(site), "--velocity", "-60", "40", "--runs", "2", "--workers", "1",
              "--estimators", "lm", "--json"]

    def rows(args: list[str]) -> tuple[list[str], list[dict]]:
        assert main([*common, *args, "--out", str(tmp_path / "mc")]) == 0
        out = json.loads(capsys.readouterr().out)
        first = [{k: v for k, v in r.items() if k != "scenario" and "time" not in k}
                 for r in out["rows"] if r["scenario"] == out["scenarios"][0]]
        return out["scenarios"], first

    names, _ = rows(["--start-lat-lon", *(str(v) for p in points for v in p)])
    assert names == [f"{site}, start latitude {lat:g}, longitude {lon:g}" for lat, lon in points]
    for lat, lon in points:
        east, north, _ = origin.to_local(lat, lon, 0.0)
        by_lat_lon = rows(["--start-lat-lon", str(lat), str(lon)])[1]
        assert by_lat_lon == rows(["--start-x", repr(float(east)), "--start-y", repr(float(north))])[1]
    for bad, message in [(["--start-lat-lon", "51.7", "0.1", "51.6"], "takes a latitude and a longitude for each"),
                         (["--start-lat-lon", "51.7", "0.1", "--start-x", "20000"], "give one or the other"),
                         (["--start-lat-lon", "95", "0.1"], "latitude 95 is outside")]:
        assert main([*common, *bad, "--out", str(tmp_path / "x")]) == 2
        assert message in capsys.readouterr().err
    assert main(["montecarlo", "--case", "a", "--start-lat-lon", "51.7", "0.1", "--runs", "1", "--out",
                 str(tmp_path / "x")]) == 2
    assert "needs a geometry whose sites are given by latitude and longitude" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()


def test_observability_reports_on_a_target_at_a_latitude_and_longitude(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """``observability --report-lat-lon``: the report of ``--report X --offset Y`` at that point's metres east and
    north of the origin, to the bit; refused with a metric geometry and beside ``--report``."""
    site = _write(tmp_path)
    east, north, _ = GeodeticOrigin(latitude=51.5, longitude=-0.12).to_local(51.7, 0.1, 0.0)
    common = ["observability", "--geometry", str(site), "--velocity", "-60", "40", "--json"]
    assert main([*common, "--report-lat-lon", "51.7", "0.1"]) == 0
    by_lat_lon = json.loads(capsys.readouterr().out)
    assert by_lat_lon["scenario"] == f"{site}, start latitude 51.7, longitude 0.1"
    assert main([*common, "--report", repr(float(east)), "--offset", repr(float(north))]) == 0
    metric = json.loads(capsys.readouterr().out)
    assert {k: v for k, v in by_lat_lon.items() if k != "scenario"} == {k: v for k, v in metric.items()
                                                                         if k != "scenario"}
    assert main(["observability", "--report-lat-lon", "51.7", "0.1"]) == 2
    assert "needs a geometry whose sites are given by latitude and longitude" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: the modes exclude each other
        main([*common, "--report-lat-lon", "51.7", "0.1", "--report", "20000"])


def test_a_plot_of_sensors_given_by_latitude_and_longitude_names_east_and_north(tmp_path: Path) -> None:
    """The plan view of a geodetic geometry is in metres east and north of the origin, and its axes say so; a metric
    geometry's keep x and y."""
    import matplotlib.pyplot as plt

    from fgdoppler import plotting

    for geometry, x, y in ((fd.Geometry.from_toml(_write(tmp_path)), "x, east (km)", "y, north (km)"),
                           (fd.paper_geometry("a"), "x (km)", "y (km)")):
        ax = plotting.plot_geometry(geometry)
        assert (ax.get_xlabel(), ax.get_ylabel()) == (x, y)
        plt.close(ax.figure)
