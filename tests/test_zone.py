"""The zone: its default rule, its excess (the wall) and its prior, in any frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.verdict import Reason
from fgdoppler.frames import Frame, sensor_frame
from fgdoppler.zone import ZoneBox, default_zone


def _rotation(angle: float, reflect: bool = False) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s], [s, c]])
    return R @ np.diag([1.0, -1.0]) if reflect else R


@pytest.mark.parametrize("case", ["a", "b"])
def test_default_zone_of_the_paper_geometries_is_the_paper_box(case: str) -> None:
    g = fd.paper_geometry(case)
    z = g.default_zone()
    assert g.frame.is_identity
    assert z.along == (2e3, 48e3) and z.across == (-5e3, 5e3) and z.speed_max == 200.0


@pytest.mark.parametrize(("angle", "reflect"), [(0.3, False), (2.0, True), (-1.1, False)])
def test_default_zone_moves_with_the_sensors(angle: float, reflect: bool) -> None:
    # A rigid motion of the sensors (rotation, translation, reflection) moves the frame with them:
    # the zone's local box is the same and its world corners are the moved corners.
    g = fd.paper_geometry("a")
    R, t = _rotation(angle, reflect), np.array([3.7e5, -8.1e5])
    moved = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=R @ np.array(p.tx) + t, rx=R @ np.array(p.rx) + t)
                                    for p in g.pairs))
    z0, z1 = g.default_zone(), moved.default_zone()
    np.testing.assert_allclose(z1.along, z0.along, atol=1e-6)
    np.testing.assert_allclose(z1.across, z0.across, atol=1e-6)
    np.testing.assert_allclose(z1.corners(), z0.corners() @ R.T + t, atol=1e-6)
    assert moved.frame.proper != reflect


def test_default_zone_reaches_sensors_off_the_first_baseline() -> None:
    # A triangle: the third sensor 40 km off the first baseline is inside the widened box.
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)),
                           fd.BistaticPair(tx=(25e3, 40e3), rx=(0.0, 0.0))))
    z = g.default_zone()
    assert z.along == (2e3, 48e3)
    assert z.across == (-5e3, 42e3)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_quasi_monostatic_first_pair_does_not_turn_the_zone(dim: int) -> None:
    """Antennas 20 m apart in a 30 km network: which way the 20 m point leaves the zone where it is.

    The frame's axis is taken from the first sensor at least
    ``AXIS_MIN_SHARE`` of the network's size from the first receiver — here
    the other receiver, whatever the bearing of the transmitter 20 m away —
    so the zone's world region moves by no more than the 20 m themselves
    (the sensors' extent along the axis changes by at most that).  Taken
    from the 20 m baseline, as for any other first pair, the axis would
    turn with the antennas and the zone (30 km by 6 km) with it.
    """
    from fgdoppler.frames import AXIS_MIN_SHARE

    rx0, rx1 = np.zeros(dim), np.r_[30e3, 5e3, np.zeros(dim - 2)]
    assert 20.0 < AXIS_MIN_SHARE * np.linalg.norm(rx1) < 30e3
    corners = []
    for angle in np.linspace(0.0, 2 * np.pi, 9)[:-1]:
        tx0 = rx0 + 20.0 * np.r_[np.cos(angle), np.sin(angle), np.zeros(dim - 2)]
        g = fd.Geometry(pairs=(fd.BistaticPair(tx=tx0, rx=rx0), fd.BistaticPair(tx=tx0, rx=rx1)))
        np.testing.assert_allclose(g.frame.B[0], rx1 / np.linalg.norm(rx1), atol=1e-12)
        corners.append(np.sort(g.default_zone().corners()[..., :2].reshape(-1, 2), axis=0))
    spread = np.ptp(np.array(corners), axis=0)
    assert float(spread.max()) <= 2 * 20.0
    # the rule for a true bistatic first pair is unchanged: the paper's zone above, and a 1 km first
    # baseline (3 % of this network) still sets the axis
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=np.r_[0.0, 1e3, np.zeros(dim - 2)], rx=rx0),
                           fd.BistaticPair(tx=np.r_[0.0, 1e3, np.zeros(dim - 2)], rx=rx1)))
    np.testing.assert_allclose(g.frame.B[0, :2], [0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize(("angle", "reflect"), [(0.0, False), (0.9, True)])
def test_a_zone_reaching_a_start_holds_it_with_its_margin(angle: float, reflect: bool) -> None:
    """The widened zone of the advice: each missed bound moves past the start by the margin times its distance
    from the far bound, the speed bound to (1 + margin) times the start's speed; a start inside changes nothing."""
    z = _zone(angle, reflect)
    to_world = z.frame.points_to_world
    x = np.r_[to_world([60e3, -9e3]), 150.0, 200.0]  # 250 m/s
    w = z.reaching(x, margin=0.25)
    assert w.along == (2e3, 60e3 + 0.25 * 58e3) and w.across == (-9e3 - 0.25 * 14e3, 5e3)
    assert w.speed_max == pytest.approx(1.25 * 250.0)
    assert w.frame == z.frame and bool(w.contains(x)) and not bool(z.contains(x))
    assert w.options() == "--zone 2000 74500 -12500 5000 --speed-max 313"
    inside = np.r_[to_world([10e3, 1e3]), 10.0, 0.0]
    assert z.reaching(inside) == z
    z3 = fd.Zone(frame=Frame.identity(3), along=(0.0, 1e3), across=(-1e3, 1e3), altitude=(0.0, 500.0))
    w3 = z3.reaching(np.array([500.0, 0.0, 900.0, 0.0, 0.0, 0.0]))
    assert w3.altitude == (0.0, 900.0 + 0.25 * 900.0) and w3.along == z3.along
    assert w3.options() == "--zone 0 1000 -1000 1000 --altitude 0 1125 --speed-max 200"


def _zone(angle: float, reflect: bool) -> fd.Zone:
    R = _rotation(angle, reflect)
    return fd.Zone(frame=Frame(origin=(1e4, -2e4), basis=tuple(map(tuple, R.T))), along=(2e3, 48e3),
                   across=(-5e3, 5e3), speed_max=200.0)


@pytest.mark.parametrize(("angle", "reflect"), [(0.0, False), (0.7, False), (2.5, True)])
@pytest.mark.parametrize(
    "local",
    [[49.3e3, 1.9e3, -80.0, 9.0], [1.0e3, -6.0e3, 30.0, 40.0], [10e3, 7e3, 180.0, 150.0], [20e3, 0.0, 10.0, 5.0]],
)
def test_excess_is_the_local_distance_outside_and_its_jacobian_matches_finite_differences(
        angle: float, reflect: bool, local: list[float]) -> None:
    zone = _zone(angle, reflect)
    x = zone.frame.states_to_world(np.asarray(local))
    e, J = zone.excess(x)
    u = np.asarray(local[:2])
    lo, hi = np.array([2e3, -5e3]), np.array([48e3, 5e3])
    np.testing.assert_allclose(e[:2], np.minimum(0.0, u - lo) + np.maximum(0.0, u - hi), atol=1e-6)
    assert e[2] == pytest.approx(max(0.0, float(np.hypot(*local[2:])) - 200.0))
    h = 1e-3
    fd_J = np.column_stack([(zone.excess(x + h * np.eye(4)[i])[0] - zone.excess(x - h * np.eye(4)[i])[0]) / (2 * h)
                            for i in range(4)])
    np.testing.assert_allclose(J, fd_J, atol=1e-8)
    assert bool(zone.contains(x)) == (not np.any(e))


def test_excess_text_names_each_number_by_its_axis_in_two_and_three_dimensions() -> None:
    """A finding's excess names as many axes as it gives numbers: a 3-D zone's altitude is named, not read as
    the speed (its speed used to be printed under no label)."""
    z2 = _zone(0.7, True)
    x2 = z2.frame.states_to_world(np.array([50e3, 0.0, 250.0, 0.0]))
    assert z2.excess_text(x2) == "excess along, across, speed: 2e+03, 0, 50"
    z3 = fd.Zone(frame=Frame.identity(3), along=(0.0, 1e3), across=(-1e3, 1e3), altitude=(0.0, 500.0))
    x3 = np.array([-30.0, 0.0, 900.0, 0.0, 0.0, 210.0])
    assert z3.excess_text(x3) == "excess along, across, altitude, speed: -30, 0, 400, 10"
    labels, numbers = z3.excess_text(x3).removeprefix("excess ").split(": ")
    assert len(labels.split(", ")) == len(numbers.split(", ")) == len(z3.excess(x3)[0])


def test_prior_spans_the_zone_in_its_frame() -> None:
    zone = _zone(0.7, True)
    mean, cov = zone.prior()
    centre = zone.frame.points_to_world([25e3, 0.0])
    np.testing.assert_allclose(mean, [*centre, 0.0, 0.0], atol=1e-9)
    local = zone.frame.covariances_to_local(cov)
    np.testing.assert_allclose(local, np.diag([23e3**2, 5e3**2, 200.0**2, 200.0**2]), rtol=1e-12, atol=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"along": (5.0, 1.0)}, "empty or inverted"),
        ({"along": (1.0, 1.0)}, "empty or inverted"),
        ({"across": (0.0, float("nan"))}, "finite"),
        ({"across": (0.0, float("inf"))}, "finite"),
        ({"across": "x"}, "two numbers"),
        ({"speed_max": 0.0}, "speed_max"),
        ({"speed_max": -5.0}, "speed_max"),
        ({"speed_max": True}, "speed_max"),
    ],
)
def test_bad_zones_are_refused(kwargs: dict, match: str) -> None:
    args = {"along": (0.0, 1.0), "across": (0.0, 1.0), "speed_max": 10.0} | kwargs
    with pytest.raises(ValueError, match=match):
        fd.Zone(**args)


def test_frame_round_trips_and_rejects_non_orthonormal_bases() -> None:
    f = Frame(origin=(5.0, -3.0), basis=tuple(map(tuple, _rotation(1.2, True))))
    x = np.array([[1.0, 2.0, 3.0, 4.0], [-7.0, 0.5, -1.0, 2.0]])
    np.testing.assert_allclose(f.states_to_world(f.states_to_local(x)), x, atol=1e-12)
    P = np.diag([1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(f.covariances_to_local(f.covariances_to_world(P)), P, atol=1e-12)
    with pytest.raises(ValueError, match="orthonormal"):
        Frame(origin=(0.0, 0.0), basis=((1.0, 0.0), (1.0, 1.0)))
    assert sensor_frame(np.array([[50e3, 0.0]]), np.array([[0.0, 0.0]])).is_identity
    assert default_zone(Frame.identity(), [[50e3, 0.0]], [[0.0, 0.0]]).along == (2e3, 48e3)


def test_a_zone_box_is_the_zone_without_its_frame_and_joins_by_hand() -> None:
    """``Zone.box`` keeps the bounds in the zone's own axes whatever its frame; the options are the zone's;
    the union is the hull of the intervals with the larger speed bound, worked by hand."""
    frame = Frame(origin=(1000.0, -500.0), basis=((0.6, 0.8), (-0.8, 0.6)))
    zone = fd.Zone(frame=frame, along=(100.2, 900.7), across=(-50.5, 50.0), speed_max=120.4)
    box = zone.box()
    assert (box.along, box.across, box.speed_max, box.altitude) == ((100.2, 900.7), (-50.5, 50.0), 120.4, None)
    assert box.options() == zone.options() == "--zone 100 901 -51 50 --speed-max 121"
    other = ZoneBox(along=(-20.0, 300.0), across=(0.0, 80.0), speed_max=90.0)
    assert box.union(other) == other.union(box) == ZoneBox(along=(-20.0, 900.7), across=(-50.5, 80.0),
                                                            speed_max=120.4)
    up = ZoneBox(along=(0.0, 1.0), across=(0.0, 1.0), speed_max=10.0, altitude=(100.0, 200.0))
    assert up.union(ZoneBox(along=(0.0, 1.0), across=(0.0, 1.0), speed_max=10.0, altitude=(50.0, 150.0))).altitude \
        == (50.0, 200.0)
    assert up.to_dict() == {"along": [0.0, 1.0], "across": [0.0, 1.0], "speed_max": 10.0, "altitude": [100.0, 200.0],
                            "options": "--zone 0 1 0 1 --altitude 100 200 --speed-max 10"}
    with pytest.raises(ValueError, match="2-D zone box with a 3-D"):
        box.union(up)


@pytest.mark.parametrize("bad", [{"along": (5.0, 1.0)}, {"across": (0.0, math.inf)}, {"speed_max": 0.0},
                                 {"speed_max": "fast"}, {"speed_max": True}])
def test_a_zone_box_refuses_what_a_zone_refuses(bad: dict[str, object]) -> None:
    good: dict[str, object] = {"along": (0.0, 1.0), "across": (0.0, 1.0), "speed_max": 10.0}
    with pytest.raises(ValueError, match="zone"):
        ZoneBox(**{**good, **bad})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="zone"):
        fd.Zone(**{**good, **bad})  # type: ignore[arg-type]


def test_a_finding_carries_its_advised_zone_and_mirror_into_json() -> None:
    box = ZoneBox(along=(0.0, 10.0), across=(-1.0, 1.0), speed_max=5.0)
    assert Reason(code="zone", status="doubtful", message="m", zone=box).to_dict() == {
        "code": "zone", "status": "doubtful", "message": "m", "zone": box.to_dict()}
    assert Reason(code="fit", status="ok", message="m").to_dict() == {"code": "fit", "status": "ok", "message": "m"}
    assert Reason(code="data", status="doubtful", message="m", mirror="reporting").to_dict() == {
        "code": "data", "status": "doubtful", "message": "m", "mirror": "reporting"}
    with pytest.raises(ValueError, match="mirror"):
        Reason(code="data", status="doubtful", message="m", mirror="left")  # type: ignore[arg-type]
