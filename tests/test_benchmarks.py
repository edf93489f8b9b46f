"""The accuracy benchmark: its records survive a save and load, and its exact-posterior reference is right."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.stats import chi2

import fgdoppler as fd
from benchmarks._exact import ESS_TARGET, TAIL_LEVEL, exact_posterior
from benchmarks.bench_accuracy import (
    EXACT_STEP,
    RUN_NEES_LEVEL,
    T_NEES,
    _unflagged_in_exact_tail,
    exact_rows,
    goal_table,
    inconsistent_runs,
    json_summary,
    load_records,
    save_records,
)
from tests.conftest import benchmark_recording


def _records() -> list[dict[str, object]]:
    rng = np.random.default_rng(3)
    out: list[dict[str, object]] = []
    for s in range(2):
        for r in range(3):
            res = {name: {"se": rng.random(4), "nees": rng.random(4), "seconds": float(rng.random()),
                          "wall": float(rng.random()), "status": "ok" if r else "doubtful"}
                   for name in ("ekf", "smoother")}
            if r != 1:  # the peer did not run in run 1
                res["filterpy-ekf"] = {"se": rng.random(4), "nees": rng.random(4), "seconds": 0.1,
                                       "wall": float("nan"), "status": "ran"}
            out.append({"s": s, "r": r, "results": res})
    return out


def test_records_round_trip(tmp_path: Path) -> None:
    recs = _records()
    save_records(recs, tmp_path / "r.npz")
    back = load_records(tmp_path / "r.npz")
    assert [(b["s"], b["r"]) for b in back] == [(a["s"], a["r"]) for a in recs]
    for a, b in zip(recs, back, strict=True):
        assert set(a["results"]) == set(b["results"])  # type: ignore[arg-type]
        for name, x in a["results"].items():  # type: ignore[attr-defined]
            y = b["results"][name]
            np.testing.assert_array_equal(x["se"], y["se"])
            np.testing.assert_array_equal(x["nees"], y["nees"])
            assert x["seconds"] == y["seconds"] and x["status"] == y["status"]
            np.testing.assert_array_equal(x["wall"], y["wall"])


def test_records_without_wall_times_still_load(tmp_path: Path) -> None:
    """Records written before the wall times were kept load with NaN for them."""
    save_records(_records(), tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz") as z:
        old = {k: z[k] for k in z.files if not k.startswith("wall_")}
    np.savez(tmp_path / "old.npz", **old)
    back = load_records(tmp_path / "old.npz")
    assert back and all(np.isnan(x["wall"]) for rec in back for x in rec["results"].values())


def test_json_summary_leaves_out_the_per_run_arrays() -> None:
    text = json_summary({"runs": 3, "scenarios": {"a": {"_se": {"ekf": np.zeros(2)}, "crlb_filter": 1.0}}})
    assert "_se" not in text and "crlb_filter" in text


def test_inconsistent_runs_counts_the_runs_beyond_the_quantile_and_the_verdicts_that_miss_them() -> None:
    t = np.array([0.0, 5.0, T_NEES, T_NEES + 5.0])
    q = chi2.ppf(RUN_NEES_LEVEL, 4)
    nees = np.array([
        [1e9, 1e9, 4.0, 4.0],            # large only before T_NEES: consistent
        [np.nan, np.nan, q - 1, q + 3],  # average q + 1: inconsistent, judged ok
        [4.0, 4.0, q + 1, np.nan],       # inconsistent where it has a value, judged doubtful
        [4.0, 4.0, np.nan, np.nan],      # no NEES after T_NEES: neither
        [4.0, 4.0, q - 0.5, q - 0.5],    # below the quantile
    ])
    statuses = ["ok", "ok", "doubtful", "ok", "ok"]
    assert inconsistent_runs(nees, t, statuses) == (2, 1)
    assert inconsistent_runs(nees, t, ["doubtful"] * 5) == (2, 0)
    assert inconsistent_runs(np.zeros((0, 4)), t, []) == (0, 0)


def test_the_table_says_when_other_jobs_ran_beside_it() -> None:
    """CPU times beside other jobs come out longer: the Markdown says so when the load exceeds the workers."""
    from benchmarks.bench_accuracy import _load_note

    busy = _load_note({"load": {"average_15_min": 4.2, "workers": 2, "cores": 2}})
    quiet = _load_note({"load": {"average_15_min": 2.1, "workers": 2, "cores": 2}})
    assert "other jobs ran beside it" in busy and "other jobs" not in quiet and "2.1" in quiet
    assert _load_note({}) == ""  # re-summarised records: no load known


def _reproduction_page() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "studies" / "reproduction_page.py"
    spec = importlib.util.spec_from_file_location("reproduction_page", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_reproduction_page_reads_back_the_goals_the_benchmark_writes(tmp_path: Path) -> None:
    """docs/reproduction.md marks the goals from the benchmark's own Markdown: writer and reader agree."""
    page = _reproduction_page()
    scenarios = list(page.SCENARIO_COLUMNS)
    rng = np.random.default_rng(5)
    met: dict[tuple[int, str, str], bool] = {}
    for seed in (7, 2026):
        rows = []
        for goal in ("1: EKF <= plain EKF and UKF", "2: best online <= best peer filter"):
            for sn in scenarios:
                met[seed, goal, sn] = bool(rng.random() < 0.5)
                rows.append((goal, sn, met[seed, goal, sn], "ekf 1 vs 2", ""))
        rows.append(("3: smoother <= 1.1 x smoothing CRLB", scenarios[2], True, "0.94", ""))
        text = f"100 runs per scenario, seed {seed}.\n\n| x |\n|---|\n\n" + "\n".join(goal_table(rows)) + "\n"
        (tmp_path / f"accuracy_seed{seed}.md").write_text(text)
        back = page.goal_rows(text)
        assert back == {(g, page.SCENARIO_COLUMNS[sn]): "yes" if ok else "no" for g, sn, ok, _, _ in rows}
    part = page.accuracy_part(tmp_path)
    assert "seeds 7 and 2026" in part and "100 runs per scenario" in part
    for goal in ("1: EKF <= plain EKF and UKF", "2: best online <= best peer filter"):
        line = next(x for x in part.splitlines() if x.startswith(f"| {goal} |"))
        cells = [c.strip() for c in line.strip("|").split("|")[1:]]
        assert cells == [" / ".join("yes" if met[seed, goal, sn] else "no" for seed in (7, 2026)) for sn in scenarios]
    crlb = next(x for x in part.splitlines() if x.startswith("| 3:"))
    assert crlb.count("yes / yes") == 1 and crlb.count("– / –") == 5
    assert page.accuracy_part(tmp_path / "nothing") == ""


def _paper_simulation(s: int, r: int, seed: int = 2026) -> tuple[fd.TrackingModel, fd.Simulation]:
    """Run ``r`` of paper scenario ``s``, as the accuracy benchmark simulates it."""
    sim, model = benchmark_recording(s, r, seed)
    return model, sim


def _paper_run(s: int, r: int, seed: int = 2026) -> tuple[fd.TrackingModel, fd.Measurements, np.ndarray]:
    model, sim = _paper_simulation(s, r, seed)
    return model, sim.measurements, sim.truth.states[0]


def _gauss_newton(model: fd.TrackingModel, m: fd.Measurements, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares optimum of the whole track and its Gauss-Newton covariance (an independent scipy fit)."""
    fit = least_squares(lambda x: (m.doppler - model.observation.predict_along(x, m.time, m.pair)[0]) / m.sigma,
                        start, method="lm")
    return fit.x, np.linalg.inv(fit.jac.T @ fit.jac)


def _whitened(cov: np.ndarray, by: np.ndarray) -> np.ndarray:
    li = np.linalg.inv(np.linalg.cholesky(by))
    return np.linalg.eigvalsh(li @ cov @ li.T)


def test_the_exact_posterior_of_a_well_observed_track_is_its_gauss_newton_gaussian() -> None:
    """Case a 45 km: the likelihood is nearly Gaussian, so the sampled moments are the optimum and its
    inverse Gauss-Newton information.  With 10,000 effective samples a whitened variance scatters by
    about sqrt(2 / 10,000) = 1.4 %, so 7 % is five of those; the mean may sit off the mode by the
    likelihood's small skew (measured 0.06-0.08 standard deviations in four runs of a 45 km and b 5 km)
    and the mass beyond the 99.9 % ellipsoid is a Gaussian's (measured 0.10 % and 0.12 % in two runs)."""
    model, m, truth = _paper_run(2, 0)
    mode, cov = _gauss_newton(model, m, truth)
    post = exact_posterior(m, model, float(m.time.max()), [truth], np.random.default_rng(0))
    assert post.ess >= 0.9 * ESS_TARGET and not post.other_mode
    # a Gaussian leaves 1 - TAIL_LEVEL outside its ellipsoid; binomial sd with 10,000 effective samples 0.03 %
    assert abs(post.tail_mass - (1.0 - TAIL_LEVEL)) < 0.001
    li = np.linalg.inv(np.linalg.cholesky(cov))
    assert np.all(np.abs(li @ (post.mean - mode)) < 0.15)
    assert np.all(np.abs(_whitened(post.covariance, cov) - 1.0) < 0.07)


def test_the_exact_posterior_agrees_with_a_metropolis_sampler_where_it_is_far_from_gaussian() -> None:
    """Case a 5 km, run 1 (seed 2026), all 30 s: the posterior is 3.4 times the Gauss-Newton covariance along
    one direction.  Random-walk Metropolis chains on the same density (an independent method: started from
    and stepping with the Gauss-Newton Gaussian, not the importance sampler's proposal) give the same moments:
    measured, chain seeds 11-13, whitened means within 0.012 standard deviations and variances within
    0.95-1.10."""
    model, m, truth = _paper_run(0, 1)
    mode, cov = _gauss_newton(model, m, truth)
    post = exact_posterior(m, model, float(m.time.max()), [truth], np.random.default_rng(0))
    # the test means something: not the Gaussian case (measured 3.3 times the variance, 1.3 % in the tail)
    assert _whitened(post.covariance, cov).max() > 2.0 and post.tail_mass > 5 * (1.0 - TAIL_LEVEL)

    prior = model.prior()
    assert prior is not None and model.zone is not None
    whiten = np.linalg.inv(np.linalg.cholesky(prior[1]))

    def cost(x: np.ndarray) -> np.ndarray:
        """The same density: the Doppler likelihood, the weak prior, the zone as support."""
        c = np.sum(((m.doppler - model.observation.predict_along(x, m.time, m.pair)) / m.sigma) ** 2, axis=1)
        c += np.sum(((x - prior[0]) @ whiten.T) ** 2, axis=1)
        return np.where(np.isfinite(c) & model.zone.contains(x), c, np.inf)

    rng = np.random.default_rng(11)
    step = np.linalg.cholesky(cov)
    x = mode + rng.standard_normal((1000, 4)) @ step.T
    cx = cost(x)
    kept = []
    for k in range(2000):
        y = x + rng.standard_normal(x.shape) @ (1.2 * step).T
        cy = cost(y)
        take = np.log(rng.random(len(x))) < -0.5 * (cy - cx)
        x[take], cx[take] = y[take], cy[take]
        if k >= 1000 and k % 10 == 0:
            kept.append(x.copy())
    chain = np.concatenate(kept)
    li = np.linalg.inv(np.linalg.cholesky(post.covariance))
    assert np.all(np.abs(li @ (chain.mean(axis=0) - post.mean)) < 0.05)
    assert np.all(np.abs(_whitened(np.cov(chain.T), post.covariance) - 1.0) < 0.1)


def test_the_exact_posterior_refuses_data_that_do_not_fix_the_state() -> None:
    model, m, truth = _paper_run(2, 0)
    one_scan = m.subset(m.time <= float(m.time.min()) + 1e-9)
    with pytest.raises(ValueError, match="do not determine"):
        exact_posterior(one_scan, model, float(m.time.min()), [truth], np.random.default_rng(0))
    with pytest.raises(ValueError, match="at least one start"):
        exact_posterior(m, model, 30.0, [], np.random.default_rng(0))


def test_the_exact_posterior_refuses_a_posterior_its_proposal_misses() -> None:
    """An aircraft 2.2 km up over two ground pairs far apart (draw 0 of ``studies/random_layouts_3d.py``, its
    layout rounded to metres), the data of the first 10 s: the Gauss-Newton Gaussian about the best fit does not
    describe a posterior that the altitude band cuts and whose height is seen only through z/r.  Measured: 11
    effective samples of the 10,000 aimed at, and the moments read from them put the truth at a NEES of 1e13.
    The sampler refuses them instead; a rank-deficient proposal (a pass whose weight fell on one sample) is
    refused in the same words, not raised as a linear-algebra error."""
    from benchmarks._exact import MIN_ESS, _proposal_scale

    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(-32247.0, 39368.0, 0.0), rx=(32083.0, -37472.0, 0.0)),
                           fd.BistaticPair(tx=(38434.0, 35804.0, 0.0), rx=(-10088.0, 32700.0, 0.0))))
    x0 = np.array([-11065.0, 49570.0, 2169.0, 56.0, -103.0, -4.0])
    sim = fd.simulate(fd.Scenario(geometry=g, x0=tuple(x0), duration=10.0), np.random.default_rng(0))
    model = fd.TrackingModel.of(g)
    init = fd.initiate(sim.measurements.first_per_pair(10), g)
    starts = [x0, init.x_start]
    read = exact_posterior(sim.measurements, model, 10.0, starts, np.random.default_rng(0), min_ess=0.0)
    # the test means something: read anyway, the moments are far from describing the truth
    assert read.ess < 0.1 * MIN_ESS
    assert read.nees(sim.truth.states[-1], 10.0, model.motion) > 1e6
    with pytest.raises(ValueError, match="effective samples"):
        exact_posterior(sim.measurements, model, 10.0, starts, np.random.default_rng(0))
    with pytest.raises(ValueError, match="collapsed onto 1 effective"):
        _proposal_scale(np.outer(x0, x0), 1.0, 10.0)


def test_the_exact_rows_hold_one_posterior_per_conditioning_time() -> None:
    """Filtered at t, lagged at t + lag and smoothed at the end: the same sampled posterior where those
    coincide (bit-identical), and the NEES at every time equals the first state's (F is invertible)."""
    model, sim = _paper_simulation(2, 0)
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), model)
    ref = fd.run_estimator("smoother", m, model, init)
    tt, truth = sim.truth.times, sim.truth.states
    rows = exact_rows(m, model, init, ref, tt, truth, seed=1)
    lag = fd.FixedLagSettings().lag
    last = float(m.time.max())
    f, lg, sm = (rows[n]["nees"] for n in ("exact-filtered", "exact-lagged", "exact-smoothed"))
    sampled = np.isfinite(f)
    assert np.allclose(tt[sampled], np.arange(T_NEES, last + 1e-9, EXACT_STEP))
    assert np.all(np.isfinite(sm)) and np.allclose(sm, sm[0])
    end = np.isclose(tt, last)
    assert f[end] == sm[end] and lg[end] == sm[end]
    for i in np.flatnonzero(sampled & (tt + lag <= last)):
        assert lg[i] == f[np.argmin(np.abs(tt - (tt[i] + lag)))]
    assert not np.any(np.isfinite(rows["exact-filtered"]["se"][~sampled]))


def test_misses_are_counted_apart_where_the_exact_posterior_misses_too() -> None:
    t = np.array([T_NEES, T_NEES + 5.0])
    q = chi2.ppf(RUN_NEES_LEVEL, 4)
    big, small = np.full(2, q + 5.0), np.full(2, 3.0)

    def rec(ours: np.ndarray, exact: np.ndarray, status: str) -> dict[str, object]:
        return {"results": {"ekf": {"nees": ours, "status": status}, "exact-filtered": {"nees": exact}}}

    recs = [rec(big, big, "ok"),         # counted: ours and the exact posterior both inconsistent, judged ok
            rec(big, small, "ok"),       # a miss the exact posterior does not share
            rec(big, big, "doubtful"),   # flagged: not a miss
            rec(small, big, "ok")]       # ours consistent
    assert _unflagged_in_exact_tail(recs, "ekf", "exact-filtered", t) == 1
    assert _unflagged_in_exact_tail(recs, "smoother", "exact-smoothed", t) == 0


def test_the_reproduction_page_adds_up_goal_fours_second_clause() -> None:
    """The page's per-seed sums are the benchmark's per-scenario counts (numbers and evidence cells)."""
    page = _reproduction_page()
    scenarios = list(page.SCENARIO_COLUMNS)
    goal = "4: inconsistent runs' verdicts not ok"
    rows = [(goal, scenarios[0], False, "3 of 5 flagged",
             "judged ok: ekf 1, smoother 1; 1 of them in runs where the exact posterior is inconsistent too"),
            (goal, scenarios[1], True, "2 of 2 flagged", ""),
            (goal, scenarios[2], False, "0 of 4 flagged",
             "judged ok: map 4; 4 of them in runs where the exact posterior is inconsistent too"),
            ("4: NEES <= 2 x band's upper edge", scenarios[0], True, "worst ekf 5 (limit 9)", "")]
    assert page.clause_two("\n".join(goal_table(rows))) == (11, 5, 5)
    # a benchmark run without the exact posterior (--no-exact) counts no shared misses: none, not 0
    plain = [(g, s, m, n, e.split(";")[0]) for g, s, m, n, e in rows]
    assert page.clause_two("\n".join(goal_table(plain))) == (11, 5, None)
    # and with nothing missed there is nothing to share
    assert page.clause_two("\n".join(goal_table([rows[1]]))) == (2, 2, 0)


def test_goal_four_names_the_shared_misses_only_when_the_exact_posterior_ran() -> None:
    """With ``--no-exact`` there is no exact posterior to share misses with, and the goal table says nothing
    about it rather than "0 of them"."""
    from benchmarks.bench_accuracy import OURS, goals

    def summary(shared: int | None) -> dict[str, object]:
        est: dict[str, dict[str, object]] = {n: {"rmse": 1.0, "nees": 4.0, "inconsistent": 0, "unflagged": 0}
                                             for n in OURS}
        est["ekf"].update(inconsistent=3, unflagged=2)
        if shared is not None:
            for n in OURS:
                est[n]["unflagged_in_exact_tail"] = shared if n == "ekf" else 0
        return {"nees_band": (3.46, 4.57), "scenarios": {"case b, start 25 km": {"estimators": est}}}

    def evidence(shared: int | None) -> str:
        row = next(g for g in goals(summary(shared)) if g[0].startswith("4: inconsistent"))
        assert row[2] is False and row[3] == "1 of 3 flagged"
        return row[4]

    assert evidence(1).endswith("judged ok: ekf 2; 1 of them in runs where the exact posterior is inconsistent too")
    assert evidence(None) == "judged ok: ekf 2"


def test_compare_outputs_leaves_out_run_times_and_names_every_other_difference(tmp_path: Path,
                                                                               capsys: pytest.CaptureFixture[str]
                                                                               ) -> None:
    # Two folders as a reproduction writes them: the same results, other run times.  Equal folders exit 0;
    # a changed result anywhere (one array element, a NaN where a number was, a nested JSON value, a dtype,
    # a file on one side only) exits 1 and is named, while run times and the load never are.
    from benchmarks.compare_outputs import main

    old, new = tmp_path / "old", tmp_path / "new"
    for folder, seconds in ((old, 1.5), (new, 9.0)):
        folder.mkdir()
        np.savez(folder / "montecarlo.npz", pos_0_ekf=np.array([1.0, np.nan, 3.0]), times_0=np.arange(3.0),
                 seconds_0_ekf=np.array([seconds]), wall_0_ekf=np.array([seconds]))
        (folder / "montecarlo.json").write_text(json.dumps(
            {"summary": {"rows": [{"rmse": 2.0, "status": ["ok", "doubtful"]}], "timing_per_run": {"ekf": seconds}},
             "wall_time": seconds, "load": {"average_15_min": seconds}}))
    assert main([str(old), str(new)]) == 0
    said = capsys.readouterr().out
    assert "same    montecarlo.npz: 2 arrays" in said and "DIFFERS" not in said

    def changed(**arrays: np.ndarray) -> str:
        np.savez(new / "montecarlo.npz", **{"pos_0_ekf": np.array([1.0, np.nan, 3.0]), "times_0": np.arange(3.0),
                                           **arrays})
        assert main([str(old), str(new)]) == 1
        return capsys.readouterr().out

    assert "pos_0_ekf" in changed(pos_0_ekf=np.array([1.0, np.nan, 3.0000000000000004]))
    assert "pos_0_ekf" in changed(pos_0_ekf=np.array([1.0, 2.0, 3.0]))
    assert "times_0" in changed(times_0=np.arange(3))  # the same values as integers
    assert "1 of 3 arrays: extra" in changed(extra=np.zeros(1))
    np.savez(new / "montecarlo.npz", pos_0_ekf=np.array([1.0, np.nan, 3.0]), times_0=np.arange(3.0))
    (new / "montecarlo.json").write_text(json.dumps(
        {"summary": {"rows": [{"rmse": 2.0, "status": ["ok", "ok"]}], "timing_per_run": {"ekf": 3.0}},
         "wall_time": 3.0, "load": {}}))
    assert main([str(old), str(new)]) == 1
    assert "/summary/rows[0]/status[1]: 'doubtful' vs 'ok'" in capsys.readouterr().out
    (new / "montecarlo.json").unlink()
    assert main([str(old), str(new)]) == 1
    assert "DIFFERS montecarlo.json: only in" in capsys.readouterr().out


def _goal_two_summary(pf_seconds: float | None) -> dict[str, object]:
    """Case b 45 km where ``map`` beats the issue's particle filter (1,162 m) in 0.8 s per run."""
    from benchmarks.bench_accuracy import OURS, PF_ROW

    est: dict[str, dict[str, object]] = {n: {"rmse": 2000.0, "nees": 4.0, "seconds": 0.01, "inconsistent": 0,
                                             "unflagged": 0} for n in OURS}
    est["map"].update(rmse=1100.0, seconds=0.8)
    for peer in ("filterpy-ekf", "filterpy-ukf", "filterpy-urts"):
        est[peer] = {"rmse": 1900.0, "nees": 4.0, "seconds": 0.05}
    if pf_seconds is not None:
        est[PF_ROW] = {"rmse": 5000.0, "nees": 40.0, "seconds": pf_seconds, "runs": 2}
    return {"nees_band": (3.46, 4.57), "scenarios": {"case b, start 45 km": {"estimators": est}}}


@pytest.mark.parametrize(("pf_seconds", "met", "by"), [
    (None, True, "map 1100 in 0.80 s vs 1162 (the issue's PF 1162; PF time 9.0 s, the issue's)"),
    (6.0, False, "PF time 6.0 s, Stone Soup's PF timed here, median of 2 runs"),
    (12.0, True, "map 1100 in 0.80 s vs 1162 (the issue's PF 1162; PF time 12.0 s, Stone Soup's PF timed here"),
])
def test_goal_two_holds_our_time_to_a_tenth_of_the_particle_filter_timed_in_the_same_run(
        pf_seconds: float | None, met: bool, by: str) -> None:
    """The same 0.8 s passes against the issue's 9 s or a PF timed at 12 s beside it, and fails against one
    timed at 6 s; the PF's own accuracy never enters (its RMSE here is the worst of all)."""
    from benchmarks.bench_accuracy import goals

    row = next(g for g in goals(_goal_two_summary(pf_seconds)) if g[0].startswith("2:"))
    assert row[2] is met and by in row[3]
    if not met:  # the fast ones' best is then the online estimator to compare
        assert not row[3].startswith("map")


def test_the_stone_soup_particle_filter_reports_every_scan_with_the_truth_inside_its_spread() -> None:
    """The particle filter timed for goal 2 is a working filter: one state per scan time, and in the
    well-observed case a 45 km its last position error within three of its stated standard deviations
    (2,000 particles here against the benchmark's 20,000, for the test's time)."""
    pytest.importorskip("stonesoup")
    from benchmarks._peers import run_stonesoup_pf

    sim, model = benchmark_recording(2, 0)
    t, x, P, seconds = run_stonesoup_pf(model, sim.measurements, n_particles=2000)
    np.testing.assert_array_equal(t, np.unique(sim.measurements.time))
    assert x.shape == (t.size, 4) and P.shape == (t.size, 4, 4) and seconds > 0
    truth = sim.truth.states[np.searchsorted(sim.truth.times, t[-1])]
    assert np.linalg.norm(x[-1, :2] - truth[:2]) < 3 * np.sqrt(P[-1, 0, 0] + P[-1, 1, 1])


def test_same_as_records_names_the_runs_whose_errors_nees_or_verdict_changed() -> None:
    from benchmarks.same_as_records import compare

    rng = np.random.default_rng(0)
    runs, n_t = 3, 5
    records: dict[str, np.ndarray] = {}
    rows = [{"s": s, "r": r} for s in range(6) for r in range(runs)]
    for s in range(6):
        se, ne = rng.random((runs, n_t)), rng.random((runs, n_t))
        se[:, 0] = ne[:, 0] = np.nan  # no state before the window: NaN equals NaN here
        records |= {f"se_{s}_map": se, f"nees_{s}_map": ne, f"status_{s}_map": np.array(["ok"] * runs),
                    f"seconds_{s}_map": np.full(runs, 0.2)}
        for row in rows[s * runs:(s + 1) * runs]:
            r = row["r"]
            row["map"] = {"se": se[r].copy(), "nees": ne[r].copy(), "status": "ok", "seconds": 0.3}
    rows[1]["map"]["se"][3] = np.nextafter(rows[1]["map"]["se"][3], 2.0)  # one bit in scenario 0, run 1
    rows[4]["map"]["status"] = "doubtful"  # scenario 1, run 1
    rows[8]["map"]["nees"][2] = np.nan  # scenario 2, run 2
    lines = compare(records, rows, ("map",))
    assert lines[2].split("|")[3:5] == [" 2 of 3 ", " 1 "]
    assert lines[3].split("|")[3:5] == [" 2 of 3 ", " 1 "]
    assert lines[4].split("|")[3:5] == [" 2 of 3 ", " 2 "]
    assert all(line.split("|")[3:6] == [" 3 of 3 ", " - ", " 0.300 / 0.200 "] for line in lines[5:])


def test_same_as_records_merges_the_new_runs_into_records_the_benchmark_summarises_again(tmp_path: Path) -> None:
    """``--write``: the named estimator's runs replaced (a verdict longer than any recorded one kept whole), every
    other estimator's as recorded, and the file read back by the benchmark's own loader."""
    from benchmarks.bench_accuracy import load_records
    from benchmarks.same_as_records import merged

    runs, n_t = 2, 4
    arrays: dict[str, np.ndarray] = {}
    for s in range(6):
        for name in ("isam2", "ekf"):
            arrays |= {f"se_{s}_{name}": np.full((runs, n_t), 1.0), f"nees_{s}_{name}": np.full((runs, n_t), 4.0),
                       f"status_{s}_{name}": np.array(["ok"] * runs), f"seconds_{s}_{name}": np.full(runs, 0.1),
                       f"wall_{s}_{name}": np.full(runs, 0.1)}
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    rows = [{"s": s, "r": r, "isam2": {"se": np.full(n_t, 9.0), "nees": np.full(n_t, 2.0),
                                       "status": "doubtful" if (s, r) == (3, 1) else "ok", "seconds": 0.2,
                                       "wall": 0.3}} for s in range(6) for r in range(runs)]
    with np.load(tmp_path / "old.npz") as old:
        out = merged(old, rows, ("isam2",))
    np.savez_compressed(tmp_path / "new.npz", **out)
    back = {(x["s"], x["r"]): x["results"] for x in load_records(tmp_path / "new.npz")}
    assert len(back) == 6 * runs
    assert back[(3, 1)]["isam2"]["status"] == "doubtful" and back[(3, 0)]["isam2"]["status"] == "ok"
    assert all(np.all(x["isam2"]["se"] == 9.0) and x["isam2"]["wall"] == 0.3 for x in back.values())
    assert all(np.all(x["ekf"]["se"] == 1.0) and x["ekf"]["status"] == "ok" for x in back.values())


def test_the_tempered_posterior_agrees_with_the_importance_sampler_where_that_one_is_validated() -> None:
    """Case a 5 km, run 1 (seed 2026), the data of the first 10 s: the hardest posterior of the paper's scenarios,
    where the importance sampler has 8,900 effective samples and agrees with Metropolis chains (above).  The
    tempered sampler starts from the zone's prior instead, and shares nothing with it but the density.  Measured,
    seeds 0-3: whitened means within 0.04 standard deviations, variances within 0.86-1.04 (its particles are
    correlated by the moves, so its own scatter is larger than the importance sampler's), mass beyond the 99.9 %
    ellipsoid 1.8-2.1 % against 1.95 % (the same with one covariance for the walk or eight clusters')."""
    from benchmarks._tempered import tempered_posterior

    model, m, truth = _paper_run(0, 1)
    t_end = float(m.time.min()) + 10.0
    ref = exact_posterior(m, model, t_end, [truth], np.random.default_rng(0))
    post = tempered_posterior(m, model, t_end, np.random.default_rng(5))
    # the test means something: far from a Gaussian (nearly twenty times a Gaussian's tail)
    assert ref.tail_mass > 10 * (1.0 - TAIL_LEVEL)
    li = np.linalg.inv(np.linalg.cholesky(ref.covariance))
    assert np.all(np.abs(li @ (post.mean - ref.mean)) < 0.1)
    assert np.all(np.abs(_whitened(post.covariance, ref.covariance) - 1.0) < 0.2)
    assert abs(post.tail_mass - ref.tail_mass) < 0.005


def test_the_tempered_posterior_refuses_where_its_bridges_disagree() -> None:
    """Two sample sets of one Gaussian pass the bridges' agreement test; a mean shifted by one standard deviation,
    or a variance more than AGREE_COVARIANCE times the other in one direction, does not.  On the 3-D layout of the
    importance sampler's refusal (above), with 60 s of data, the two bridges disagree (the posterior runs
    kilometres in height and the walk does not mix along it; measured with seeds 0-2: means 0.9-1.8 standard
    deviations apart and least variance ratios 0.08-0.30 with the default 4,000 particles; 2.5-27 and 0.01-0.05
    with the 1,000 used here to keep the test short), and the sampler refuses rather than pool them.
    """
    from benchmarks._tempered import AGREE_COVARIANCE, _agree, tempered_posterior

    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((4000, 3)), rng.standard_normal((4000, 3))
    _agree([a, b], 1.0)
    with pytest.raises(ValueError, match="disagree"):
        _agree([a, b + np.array([1.0, 0.0, 0.0])], 1.0)
    with pytest.raises(ValueError, match="disagree"):
        _agree([a, b * np.array([1.0, 1.0, 1.2 * AGREE_COVARIANCE])], 1.0)
    with pytest.raises(ValueError, match="at least 10 particles and one bridge"):
        tempered_posterior(fd.Measurements(time=np.zeros(1), pair=np.zeros(1, dtype=int), doppler=np.zeros(1),
                                           sigma=np.ones(1)), _paper_run(2, 0)[0], 0.0, rng, bridges=0)
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(-32247.0, 39368.0, 0.0), rx=(32083.0, -37472.0, 0.0)),
                           fd.BistaticPair(tx=(38434.0, 35804.0, 0.0), rx=(-10088.0, 32700.0, 0.0))))
    x0 = (-11065.0, 49570.0, 2169.0, 56.0, -103.0, -4.0)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=60.0), np.random.default_rng(0))
    with pytest.raises(ValueError, match="bridges given the data up to 60 s disagree"):
        tempered_posterior(sim.measurements, fd.TrackingModel.of(g), 60.0, np.random.default_rng(0), particles=1000)
