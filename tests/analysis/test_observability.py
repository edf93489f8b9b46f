"""Observability: the paper's claims, symmetries, agreement with GTSAM, and the report."""

from __future__ import annotations

import itertools

import gtsam
import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.analysis import observability as ob
from fgdoppler.factors import X, cv_factor


@pytest.mark.parametrize("group", [1, 3])
def test_baseline_groups_unobservable_only_along_baseline(group: int) -> None:
    case, y = ob.PAPER_GROUPS[group]
    m = ob.observability_map(fd.paper_geometry(case), y=y)
    along = np.isin(m.heading_deg, (90.0, 270.0))
    assert np.all(m.O[:, along] == ob.O_FLOOR)
    assert np.all(m.O[:, ~along] > ob.O_FLOOR)


def test_group2_and_group4_are_mirror_images() -> None:
    # h_a(x, y, vx, vy) = h_b(50 km - x, y, -vx, vy) (tests/models/test_doppler.py), so
    # J_b(mirror x0) = J_a(x0) D with D = diag(-1, 1, -1, 1); |det D| = 1 leaves det(J'J)
    # unchanged. Mirroring maps initial x to 50 km - x and heading h (vx = v sin h) to -h.
    m2 = ob.observability_map(fd.paper_geometry("a"), y=2e3)
    m4 = ob.observability_map(fd.paper_geometry("b"), y=2e3)
    xi = np.array([np.flatnonzero(np.isclose(m4.x, 50e3 - x))[0] for x in m2.x])
    hi = np.array([np.flatnonzero(np.isclose(m4.heading_deg, (-h) % 360))[0] for h in m2.heading_deg])
    np.testing.assert_allclose(m2.O, m4.O[np.ix_(xi, hi)], atol=1e-6)
    assert not np.allclose(m2.O, m4.O, atol=1e-3)  # the mirror is a real symmetry, not an identity


@pytest.mark.parametrize("case", ["a", "b"])
def test_observability_increases_with_speed(case: str) -> None:
    # The paper's claim (Table 2) is about the max and min over the map. Pointwise it holds
    # almost everywhere; a few cells next to a sensor (x ~ 48 km in case a) break it because
    # the faster target covers a visibly different geometry within the batch.
    g = fd.paper_geometry(case)
    Os = [ob.observability_map(g, y=2e3, speed=s).O for s in (25.0, 50.0, 75.0, 100.0)]
    for slow, fast in itertools.pairwise(Os):
        assert fast.max() > slow.max() and fast.min() > slow.min()
        assert np.median(fast) > np.median(slow)
        assert np.mean(fast > slow) >= 0.995


def test_table2_reproduced_with_default_batch() -> None:
    tab = ob.speed_table()
    for g in (2, 4):
        for s, (mx, mn) in ob.PAPER_TABLE2[g].items():
            ours_max, ours_min = tab.values[g][s]
            assert abs(ours_max - mx) <= 0.05, (g, s, ours_max, mx)
            assert abs(ours_min - mn) <= 1.0, (g, s, ours_min, mn)
    assert "2 samples per pair every 1 s" in tab.to_markdown()


def test_numpy_JtJ_equals_gtsam_hessian(rng: np.random.Generator, paper_geom: fd.Geometry) -> None:
    times = [np.arange(10) * 0.5, 0.25 + np.arange(10) * 0.5]
    for x0 in [np.array([25e3, 2e3, 10.0, -100.0]), np.array([45e3, 2e3, 10.0, -100.0]),
               np.array([8e3, -3e3, 60.0, 40.0])]:
        J = fd.cv_doppler_jacobian(x0, paper_geom, times)
        graph = gtsam.NonlinearFactorGraph()
        graph.add(cv_factor(X(0), paper_geom, times, fd.cv_doppler(x0, paper_geom, times), 1.0))
        v = gtsam.Values()
        v.insert(X(0), x0)
        H, _ = graph.linearize(v).hessian()
        np.testing.assert_allclose(H, J.T @ J, rtol=1e-9, atol=1e-9 * np.abs(J.T @ J).max())


def test_measure_matches_direct_determinant() -> None:
    g = fd.paper_geometry("a")
    x0 = np.array([45e3, 2e3, 10.0, -100.0])
    times = [np.arange(10) * 0.5] * 2
    J = fd.cv_doppler_jacobian(x0, g, times)
    assert ob.observability_measure(x0, g, times) == pytest.approx(np.log10(np.linalg.det(J.T @ J)), abs=1e-8)
    # fewer measurements than unknowns: det(J'J) = 0 -> floor
    assert ob.observability_measure(x0, g, [[0.0], [0.0]]) == ob.O_FLOOR
    many = ob.observability_measure(np.stack([x0, x0 + np.array([1e3, 0, 0, 0])]), g, times)
    assert isinstance(many, np.ndarray) and many.shape == (2,)


def _numpy_inverse_fisher_chain(sim: fd.Simulation, motion: fd.ConstantVelocity) -> np.ndarray:
    """Inverse Fisher information of all states, from the whitened Jacobian A (Fisher = A'A).

    A stacks the Doppler rows H_j / sigma_j and the motion rows L^-1 [-F, I] (Q = L L').
    Inverting through the SVD of A, C = V S^-2 V', avoids squaring the condition number.
    """
    m = sim.measurements
    times, scan = m.scans().times, m.scans().scan_of
    states = sim.truth.at(times)
    n = times.size
    H = fd.bistatic_doppler_jacobian(states[scan], sim.scenario.geometry)[np.arange(len(m)), m.pair]
    rows = []
    for j in range(len(m)):
        r = np.zeros(4 * n)
        r[4 * scan[j]:4 * scan[j] + 4] = H[j] / m.sigma[j]
        rows.append(r[None])
    for k in range(1, n):
        dt = times[k] - times[k - 1]
        G = np.zeros((4, 4 * n))
        G[:, 4 * (k - 1):4 * k] = -motion.F(dt)
        G[:, 4 * k:4 * k + 4] = np.eye(4)
        rows.append(np.linalg.solve(np.linalg.cholesky(motion.Q(dt)), G))
    _, S, Vt = np.linalg.svd(np.vstack(rows), full_matrices=False)
    return (Vt.T / S**2) @ Vt


def test_report_marginals_equal_inverse_fisher_deterministic() -> None:
    scen = fd.paper_scenario("a", 45e3)
    sim = fd.simulate(scen, np.random.default_rng(2))
    rep = ob.observability_report(scen.geometry, sim.truth, sim.measurements)
    assert rep.status == "ok" and rep.covariances is not None
    m = sim.measurements
    order = m.stacked_order()
    bt = fd.StackedTimes(pair=m.pair[order], t=m.time[order])
    J = fd.cv_doppler_jacobian(np.asarray(scen.x0), scen.geometry, bt) / m.sigma[order][:, None]
    P0 = np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(rep.covariances[0], P0, rtol=1e-6)
    F = fd.ConstantVelocity().F(rep.times[-1])
    np.testing.assert_allclose(rep.covariances[-1], F @ P0 @ F.T, rtol=1e-6)


def test_report_marginals_equal_inverse_fisher_with_process_noise() -> None:
    scen = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 2e3, 10.0, -100.0), duration=10.0)
    sim = fd.simulate(scen, np.random.default_rng(2))
    motion = fd.ConstantVelocity(q=0.01)
    rep = ob.observability_report(scen.geometry, sim.truth, sim.measurements, motion=motion)
    assert rep.status == "ok" and rep.covariances is not None
    C = _numpy_inverse_fisher_chain(sim, motion)
    for k in (0, rep.times.size // 2, rep.times.size - 1):
        ours, ref = rep.covariances[k], C[4 * k:4 * k + 4, 4 * k:4 * k + 4]
        # Relative error of a covariance: variances element-wise, cross terms scaled by
        # sqrt(P_ii P_jj) (near-zero cross covariances have no meaningful element-wise ratio).
        np.testing.assert_allclose(np.diag(ours), np.diag(ref), rtol=1e-6)
        scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
        assert np.max(np.abs(ours - ref) / scale) <= 1e-6
    # the weakest direction is the dominant eigenvector of the position covariance
    w, V = np.linalg.eigh(rep.covariances[0][:2, :2])
    assert abs(rep.weakest_direction[0] @ V[:, -1]) == pytest.approx(1.0)
    assert rep.weakest_std[0] == pytest.approx(np.sqrt(w[-1]))


@pytest.mark.parametrize("scenario", fd.paper_scenarios(), ids=lambda s: s.name)
def test_report_works_on_paper_scenarios(scenario: fd.Scenario) -> None:
    sim = fd.simulate(scenario, np.random.default_rng(0))
    for motion in (None, fd.ConstantVelocity(q=0.01)):
        rep = ob.observability_report(scenario.geometry, sim.truth, sim.measurements, motion=motion)
        assert rep.status == "ok", rep.message
        assert rep.pos_std is not None and np.all(np.isfinite(rep.pos_std)) and np.all(rep.pos_std > 0)
        assert rep.tangent_angle_deg.shape == (sim.truth.times.size, 2)


def test_report_on_degenerate_track_is_indeterminate_not_a_crash() -> None:
    # moving along the Tx1-Rx1 baseline: pair 1 gives zero Doppler and no information
    scen = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(10e3, 0.0, 100.0, 0.0), duration=10.0)
    sim = fd.simulate(scen, np.random.default_rng(0))
    for motion in (None, fd.ConstantVelocity(q=0.01)):
        rep = ob.observability_report(scen.geometry, sim.truth, sim.measurements, motion=motion)
        assert rep.status == "indeterminate"
        assert "indeterminate" in rep.message.lower()
        assert rep.pos_std is None and rep.covariances is None
        assert rep.O_x0 == ob.O_FLOOR
        np.testing.assert_allclose(rep.tangent_angle_deg[:, 0], 0.0, atol=1e-9)
        d = rep.to_dict()
        assert d["status"] == "indeterminate"
