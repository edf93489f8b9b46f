from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.geometry import resolve_geometry
from fgdoppler.zone import ZoneLimits


def test_paper_table1_positions() -> None:
    a = fd.paper_geometry("a")
    np.testing.assert_array_equal(a.tx, [[50e3, 0], [50e3, 1e3]])
    np.testing.assert_array_equal(a.rx, [[0, 0], [0, 0]])
    b = fd.paper_geometry("B")
    np.testing.assert_array_equal(b.tx, [[50e3, 0], [50e3, 0]])
    np.testing.assert_array_equal(b.rx, [[0, 0], [0, 1e3]])
    with pytest.raises(ValueError, match="unknown paper geometry"):
        fd.paper_geometry("c")


@pytest.mark.parametrize(
    ("tx", "rx", "msg"),
    [((np.nan, 0), (1, 0), "finite"), ((0, 0, 0, 0), (1, 0), "2- or 3-vector")],
)
def test_pair_validation(tx: tuple, rx: tuple, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        fd.BistaticPair(tx=tx, rx=rx)


def test_a_monostatic_radar_is_a_pair_and_one_site_alone_is_refused() -> None:
    """Tx and Rx at one place: a monostatic radar, whose bistatic range is twice its range.

    Its Doppler is 2 r' (r the distance to the radar), checked against the
    closed form at random states; its ellipses are circles about the radar.
    A geometry whose sensors are all at one place is refused: the data
    would not change under a rotation of the track about that place.
    """
    mono = fd.BistaticPair(tx=(3e3, -2e3), rx=(3e3, -2e3))
    assert mono.monostatic and mono.baseline == 0.0
    assert not fd.BistaticPair(tx=(3e3, -2e3), rx=(3e3, -1e3)).monostatic
    g = fd.Geometry(pairs=(mono, fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3))))
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.uniform(-40e3, 40e3, (500, 2)), rng.uniform(-200, 200, (500, 2))])
    rel = x[:, :2] - np.array(mono.tx)
    np.testing.assert_allclose(fd.bistatic_doppler(x, g)[:, 0],
                               2.0 * np.einsum("ij,ij->i", rel, x[:, 2:]) / np.linalg.norm(rel, axis=1), rtol=1e-12)
    np.testing.assert_allclose(fd.bistatic_range(x[:, :2], g)[:, 0], 2.0 * np.linalg.norm(rel, axis=1), rtol=1e-12)
    tangent = fd.ellipse_tangent(x[:, :2], g)[:, 0]
    np.testing.assert_allclose(np.einsum("ij,ij->i", tangent, rel), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(tangent, axis=1), 1.0)
    for pairs in [(mono,), (mono, mono), (mono, fd.BistaticPair(tx=(3e3, -2e3, 0.0), rx=(3e3, -2e3)))]:
        with pytest.raises(ValueError, match="every sensor is at one place"):
            fd.Geometry(pairs=pairs)


def test_the_radars_are_the_pairs_whose_tx_and_rx_are_at_one_place_at_the_layouts_scale() -> None:
    """A pair is a radar where its baseline is at most 1 % of the largest distance between two sensors (the rule
    that keeps it from setting the frame): a monostatic pair and one with its antennas 50 m apart in a 60 km
    layout are, a 1 km baseline (1.4 %) is not; the paper's pairs are none.  The rule scales with the layout
    (the same pairs in kilometres) and does not depend on where the layout is or how it is turned."""
    P = fd.BistaticPair
    layout = [P(tx=(0.0, 0.0), rx=(0.0, 0.0)), P(tx=(40e3, 0.0), rx=(-20e3, 30e3)),
              P(tx=(10e3, 20e3), rx=(10e3, 20.05e3)), P(tx=(-30e3, -10e3), rx=(-29e3, -10e3))]
    g = fd.Geometry(pairs=tuple(layout))
    assert g.radars == (0, 2)
    assert fd.paper_geometry("a").radars == () and fd.paper_geometry("b").radars == ()
    angle, shift = 1.1, np.array([5e5, -3e5])
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    for f in (lambda p: np.asarray(p) / 1e3, lambda p: rot @ np.asarray(p) + shift):
        assert fd.Geometry(pairs=tuple(P(tx=f(p.tx), rx=f(p.rx)) for p in layout)).radars == (0, 2)


def test_geometry_validation() -> None:
    with pytest.raises(ValueError, match="at least one"):
        fd.Geometry(pairs=())
    with pytest.raises(TypeError):
        fd.Geometry(pairs=((0, 0),))  # type: ignore[arg-type]


def test_bistatic_range_and_tangent_closed_form() -> None:
    g = fd.paper_geometry("a")
    # A point above Rx at height 3 km: r_R = 3 km, r_T = sqrt(50^2 + 3^2) km.
    p = np.array([0.0, 3e3])
    r = fd.bistatic_range(p, g)
    assert r[0] == pytest.approx(3e3 + np.hypot(50e3, 3e3), rel=1e-14)
    # The tangent is orthogonal to the gradient u_T + u_R and has unit length.
    t = fd.ellipse_tangent(p, g)
    grad = (p - g.tx) / np.linalg.norm(p - g.tx, axis=1)[:, None] + (p - g.rx) / np.linalg.norm(p - g.rx, axis=1)[:, None]
    np.testing.assert_allclose(np.einsum("ij,ij->i", t, grad), 0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1, rtol=1e-12)
    # Moving along the tangent leaves the bistatic range unchanged to first order.
    eps = 1.0
    dr = fd.bistatic_range(p + eps * t[0], g)[0] - fd.bistatic_range(p - eps * t[0], g)[0]
    assert abs(dr) < 1e-6


def test_tangent_on_baseline_is_along_baseline() -> None:
    g = fd.paper_geometry("a")
    t = fd.ellipse_tangent(np.array([20e3, 0.0]), g)
    assert abs(t[0] @ np.array([1.0, 0.0])) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="sensor"):
        fd.ellipse_tangent(np.array([0.0, 0.0]), g)


def test_toml_round_trip(tmp_path) -> None:
    g = fd.paper_geometry("b")
    path = tmp_path / "g.toml"
    g.to_toml(path)
    back = fd.Geometry.from_toml(path)
    assert back == g
    assert resolve_geometry(str(path)) == g
    assert resolve_geometry("a") == fd.paper_geometry("a")


def test_a_written_geometry_gives_each_position_on_one_line_and_reads_back_exactly(tmp_path) -> None:
    """The file reads as the documentation's example (``tx = [50000.0, 0.0]``, not one number a line), for 2-D,
    3-D and awkward values (a round-off tail, a tiny exponent, negatives), a zone and a geodetic origin, and reads
    back exactly."""
    from fgdoppler.geodetic import GeodeticOrigin

    flat = fd.Geometry(pairs=(fd.BistaticPair(tx=(0.1 + 0.2, -1e-17), rx=(-3.5e4, 12.0)),
                              fd.BistaticPair(tx=(5e4, 0.0), rx=(0.0, 1e3))))
    tall = fd.Geometry(pairs=(fd.BistaticPair(tx=(5e4, 0.0, 120.5), rx=(0.0, 0.0, 30.0)),
                              fd.BistaticPair(tx=(5e4, 0.0, 120.5), rx=(0.0, 2e3, -4.25))),
                       zone_limits=ZoneLimits(along=(1e3, 4.9e4), altitude=(0.0, 9e3)))
    site = replace(flat, geodetic_origin=GeodeticOrigin(latitude=51.5, longitude=-0.12, height=35.0))
    for g in (flat, tall, site):
        path = tmp_path / "g.toml"
        g.to_toml(path)
        text = path.read_text()
        assert "[\n" not in text
        assert f"tx = [{', '.join(map(repr, g.pairs[0].tx))}]" in text.splitlines()
        assert fd.Geometry.from_toml(path) == g


def test_toml_round_trip_with_a_zone_table(tmp_path) -> None:
    from fgdoppler.zone import ZoneLimits

    g = fd.paper_geometry("a").with_zone(ZoneLimits(across=(-5e3, 12e3), speed_max=350.0))
    path = tmp_path / "g.toml"
    g.to_toml(path)
    assert "[zone]" in path.read_text()
    back = fd.Geometry.from_toml(path)
    assert back == g
    assert back.zone.across == (-5e3, 12e3) and back.zone.along == (2e3, 48e3) and back.zone.speed_max == 350.0


PAIR = "[[pair]]\ntx = [50000.0, 0.0]\nrx = [0.0, 0.0]\n"


@pytest.mark.parametrize(
    ("text", "msg", "line"),
    [
        ("not toml [", "not valid TOML", 1),
        ("name = 'x'\n", "one or more", None),
        ("[[pair]]\ntx = [0.0, 0.0]\n", "needs both", None),
        ("[[pair]]\ntx = [0.0, 0.0]\nrx = [0.0, 0.0]\n", "every sensor is at one place", None),
        ('[[pair]]\ntx = ["50000", 0.0]\nrx = [0.0, 0.0]\n', "two or three numbers", 2),
        ("[[pair]]\ntx = [true, 0.0]\nrx = [0.0, 0.0]\n", "two or three numbers", 2),
        ("[[pair]]\ntx = [1.0, 0.0, 0.0, 0.0]\nrx = [0.0, 0.0]\n", "2- or 3-vector", 2),
        ("[[pair]]\ntx = [50000.0, nan]\nrx = [0.0, 0.0]\n", r"finite coordinates, got \(50000.0, nan\)", 2),
        ("[[pair]]\ntX = [50000.0, 0.0]\nrx = [0.0, 0.0]\n", "unknown key 'tX' in pair 0", 2),
        ("nmae = 'x'\n" + PAIR, "unknown key 'nmae'", 1),
        (PAIR + "txx = 1.0\n", "unknown key 'txx'", 4),
        ("name = 3\n" + PAIR, "name must be a string", 1),
        ("zone = 5\n" + PAIR, "zone must be a table", 1),
        ("[zone]\nspeed_mx = 3.0\n" + PAIR, "unknown key 'speed_mx'", 2),
        ("[zone]\nalong = [48000.0, 2000.0]\n" + PAIR, "empty or inverted", 2),
        ("[zone]\nalong = [2000.0, 2000.0]\n" + PAIR, "empty or inverted", 2),
        ("[zone]\nacross = [0.0, inf]\n" + PAIR, "finite", 2),
        ('[zone]\nacross = ["0", "5"]\n' + PAIR, "two numbers", 2),
        ("[zone]\nacross = [0.0]\n" + PAIR, "two numbers", 2),
        ("[zone]\nspeed_max = -1.0\n" + PAIR, "speed_max", 2),
        ("[zone]\nspeed_max = true\n" + PAIR, "speed_max", 2),
        ("[zone]\nalong = [5e7, 6e7]\n" + PAIR, "from the nearest sensor", None),
        (PAIR + "name = 3\n", "pair 0: name must be a string", 4),
        (PAIR + "name = 'north'\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3"), "pair 1 has no name", None),
        (PAIR + "name = 'n'\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3") + "name = '1'\n", "is a number", 8),
        (PAIR + "name = 'n'\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3") + "name = 'a,b'\n", "commas", 8),
        (PAIR + "name = ' n'\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3") + "name = 'm'\n", "spaces", 4),
        (PAIR + "name = 'n'\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3") + "name = 'n'\n", "unique", None),
        (PAIR + "wavelength = '3'\n", "pair 0: wavelength must be a number", 4),
        (PAIR + "wavelength = true\n", "pair 0: wavelength must be a number", 4),
        (PAIR + "wavelength = 3.0\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3"), "pair 1 has no wavelength",
         None),
        (PAIR + "wavelength = 3.0\n" + PAIR.replace("50000.0, 0.0", "50000.0, 1e3") + "wavelength = 0.0\n",
         r"pair 1's wavelength 0 m is outside", 8),
        (PAIR + "wavelength = 98.3e6\n", r"the carrier frequency in Hz, the wavelength is 3.04977 m", 4),
        (PAIR + "wavelength = nan\n", r"pair 0's wavelength nan m is outside", 4),
    ],
)
def test_toml_errors_name_the_file_and_line(tmp_path, text: str, msg: str, line: int | None) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=msg) as info:
        fd.Geometry.from_toml(path)
    text = str(info.value)
    assert text.startswith(f"{path}:{line}:" if line else f"{path}:"), text
    assert "\n" not in text


def test_toml_reads_are_bounded(tmp_path) -> None:
    from fgdoppler.geometry_file import MAX_GEOMETRY_BYTES

    big = tmp_path / "big.toml"
    big.write_text(PAIR + "#" * (MAX_GEOMETRY_BYTES + 10))
    with pytest.raises(ValueError, match="larger than"):
        fd.Geometry.from_toml(big)
    with pytest.raises(ValueError, match="larger than"):
        fd.Geometry.from_toml("/dev/zero")  # an endless device: refused at the bound, not read to the end
    nul = tmp_path / "nul.toml"
    nul.write_bytes(PAIR.encode() + b"\x00")
    with pytest.raises(ValueError, match="NUL"):
        fd.Geometry.from_toml(nul)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe" + PAIR.encode())
    with pytest.raises(ValueError, match="UTF-8"):
        fd.Geometry.from_toml(binary)


def test_resolve_geometry_unknown() -> None:
    with pytest.raises(ValueError, match="neither a preset"):
        resolve_geometry("no-such-file.toml")


def test_design_contract_names_import_from_the_package() -> None:
    # ../shared/DESIGN.md "Public contract"
    geom = fd.paper_geometry("a")
    assert isinstance(fd.BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)), fd.BistaticPair)
    states = np.array([[25e3, 2e3, 10.0, -100.0]])
    assert fd.bistatic_doppler(states, geom).shape == (1, 2)
    assert fd.bistatic_doppler_jacobian(states, geom).shape == (1, 2, 4)
    assert isinstance(fd.observability_measure(states[0], geom, [np.arange(3.0), np.arange(3.0)]), float)


def test_a_mirror_image_is_recognised_within_a_quarter_of_the_distance() -> None:
    """``is_mirror_image``: the reflection of a point across the sensors' least-squares line is its image (the
    Doppler of the reflected state equals the original's when the sensors lie on the line), a point nearer the
    image than a quarter of the two points' distance is too, one farther off is not; the same after moving
    and turning the whole layout."""
    from fgdoppler.geometry import is_mirror_image, mirrored

    rng = np.random.default_rng(4)
    on_line = fd.Geometry(pairs=(fd.BistaticPair(tx=(0.0, 0.0), rx=(30e3, 0.0)),
                                 fd.BistaticPair(tx=(10e3, 0.0), rx=(45e3, 0.0))))
    x = np.array([[20e3, 6e3, 40.0, -90.0]])
    np.testing.assert_allclose(fd.bistatic_doppler(mirrored(x, on_line), on_line), fd.bistatic_doppler(x, on_line),
                               rtol=0, atol=1e-9)
    for _ in range(5):
        angle, shift = rng.uniform(0, 2 * np.pi), rng.uniform(-1e5, 1e5, 2)
        rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        g = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=rot @ p.tx + shift, rx=rot @ p.rx + shift)
                                    for p in on_line.pairs))
        p = rot @ x[0, :2] + shift
        image = mirrored(np.r_[p, 0.0, 0.0][None], g)[0, :2]
        apart = np.linalg.norm(image - p)
        np.testing.assert_allclose(apart, 12e3, rtol=1e-9)
        side = rot @ np.array([1.0, 0.0])  # along the line: keeps the distance to p about the same
        assert is_mirror_image(p, image, g) and is_mirror_image(image, p, g)
        assert is_mirror_image(p, image + 0.2 * apart * side, g)
        assert not is_mirror_image(p, image + 0.3 * apart * side, g)
        assert not is_mirror_image(p, p, g) and not is_mirror_image(p, p + 0.2 * apart * side, g)


def test_pair_names_round_trip_and_survive_the_frames(tmp_path) -> None:
    """Named pairs: the file writes and reads them back, and a change of frame or zone keeps them; names for some
    pairs only are refused (the measurement file's use of them: ``tests/test_measurements.py``)."""
    from fgdoppler.zone import ZoneLimits

    g = fd.Geometry(pairs=fd.paper_geometry("b").pairs, pair_names=("north site", "south"))
    path = tmp_path / "g.toml"
    g.to_toml(path)
    back = fd.Geometry.from_toml(path)
    assert back == g and back.pair_names == ("north site", "south")
    assert g.in_frame(g.frame).pair_names == g.pair_names
    assert g.with_zone(ZoneLimits(speed_max=300.0)).pair_names == g.pair_names
    assert g.mirrored_x(1e3).pair_names == g.pair_names
    with pytest.raises(ValueError, match="name every pair or none"):
        fd.Geometry(pairs=g.pairs, pair_names=("north",))


def test_a_pair_is_labelled_as_the_measurement_file_names_it() -> None:
    """Outputs (the observability report, plot legends) name pair ``i`` by its 0-based index, as the measurement
    file's ``pair`` column does, with its name where the geometry gives one."""
    import matplotlib.pyplot as plt

    from fgdoppler import plotting

    plain = fd.paper_geometry("b")
    named = fd.Geometry(pairs=plain.pairs, pair_names=("north site", "south"))
    assert [plain.pair_label(i) for i in range(2)] == ["0", "1"]
    assert [named.pair_label(i) for i in range(2)] == ["0 (north site)", "1 (south)"]
    ax = plotting.plot_geometry(named, ellipse_through=(20e3, 2e3))
    assert [line.get_label() for line in ax.lines][:4] == ["pair 0 (north site)", "ellipse of pair 0 (north site)",
                                                          "pair 1 (south)", "ellipse of pair 1 (south)"]
    plt.close(ax.figure)


def test_wavelengths_round_trip_and_survive_the_frames(tmp_path) -> None:
    """Carrier wavelengths: the file writes and reads them back, a change of frame, zone or scale keeps them (a
    wavelength is the carrier's, not a length of the layout); one per pair or none, each positive and finite,
    and a frequency given for a wavelength is refused with the wavelength it would be (c / f_c)."""
    from fgdoppler.geometry import SPEED_OF_LIGHT

    g = fd.Geometry(pairs=fd.paper_geometry("a").pairs, wavelengths=(3.05, 0.5))
    path = tmp_path / "g.toml"
    g.to_toml(path)
    back = fd.Geometry.from_toml(path)
    assert back == g and back.wavelengths == (3.05, 0.5)
    for moved in (g.in_frame(g.frame), g.with_zone(ZoneLimits(speed_max=300.0)), g.mirrored_x(1e3), g.scaled(1e3),
                  g.in_3d()):
        assert moved.wavelengths == g.wavelengths
    assert fd.paper_geometry("a").wavelengths == ()
    with pytest.raises(ValueError, match="give every pair's wavelength or none"):
        fd.Geometry(pairs=g.pairs, wavelengths=(3.0,))
    with pytest.raises(TypeError, match="sequence of numbers"):
        fd.Geometry(pairs=g.pairs, wavelengths=("3", 0.5))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=rf"wavelength is {SPEED_OF_LIGHT / 600e6:.6g} m"):
        fd.Geometry(pairs=g.pairs, wavelengths=(3.0, 600e6))
    for bad in (-1.0, 0.0, np.inf, 1e-5):
        with pytest.raises(ValueError, match="pair 1's wavelength"):
            fd.Geometry(pairs=g.pairs, wavelengths=(3.0, bad))


def test_a_geometry_in_other_units_gives_the_doppler_of_the_scaled_target() -> None:
    """The bistatic Doppler v . (u_T + u_R) depends on positions only through the unit vectors to the sensors, so
    sensors and target positions scaled together by s (velocities kept) give the same Doppler; scaling by s then
    1/s is the geometry again; the zone's lengths scale and its speed bound does not; s <= 0 is refused."""
    rng = np.random.default_rng(3)
    g = fd.Geometry(pairs=fd.paper_geometry("b").pairs, pair_names=("east", "west"),
                    zone_limits=ZoneLimits(along=(-5e3, 60e3), across=(0.0, 30e3), speed_max=250.0,
                                           altitude=(0.0, 10e3)))
    states = np.column_stack([rng.uniform(-2e4, 6e4, 50), rng.uniform(1e3, 3e4, 50), rng.uniform(0, 8e3, 50),
                              rng.normal(0, 100, (50, 3))])
    for s in (1e-3, 0.37, 1e3):
        k = g.scaled(s)
        assert k.pair_names == g.pair_names and k.zone_limits.speed_max == 250.0
        assert k.extent == pytest.approx(s * g.extent, rel=1e-12)
        assert k.zone_limits.along == pytest.approx((-5e3 * s, 60e3 * s))
        assert k.zone_limits.altitude == pytest.approx((0.0, 10e3 * s))
        moved = np.column_stack([states[:, :3] * s, states[:, 3:]])
        np.testing.assert_allclose(fd.bistatic_doppler(moved, k), fd.bistatic_doppler(states, g), rtol=1e-9,
                                   atol=1e-9)
        np.testing.assert_allclose(k.scaled(1 / s).tx, g.tx, rtol=1e-12, atol=1e-9)
    for bad in (0.0, -2.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="positive and finite"):
            g.scaled(bad)
