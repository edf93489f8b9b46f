"""Accuracy under marginal observability: every fgdoppler estimator against FilterPy's and Stone Soup's filters.

The paper's six scenarios, ``--runs`` seeded recordings each.  Every run is
initiated once by fgdoppler (LM, 10 measurements per pair); the peers
(:mod:`benchmarks._peers`: FilterPy's EKF, UKF and URTS; Stone Soup's EKF
and UKF smoothers when its extra is installed) start from that initiation's state and covariance
at the end of its window, exactly where fgdoppler's EKF starts.  Per
scenario and estimator:

* position RMSE over runs at each truth time, averaged over t ≥ 5 s (m);
* NEES averaged over runs at each time, then over t ≥ 10 s, with the 95 %
  band for that many runs;
* median run time (s): the CPU time of the estimator alone (for fgdoppler,
  the call of :func:`fgdoppler.run_estimator`; the verdict's reference
  smoother is shared and not counted).  Process CPU time, not wall time,
  because other jobs on a shared machine stretch wall times far more:
  against the same code's uncontended wall times (seed 2026), two benchmark
  runs side by side gave wall times 2.1-3.9 times longer (median 2.5),
  which flipped goal 2's verdicts, and a run beside a test suite, at a
  load of 4-5 on 2 cores, CPU times 1.0-1.7 times (median 1.25).  Not
  immune, then: goal 2's budget is a tenth of the run time of a particle
  filter timed in the same benchmark run (below), so that both sides of the
  ratio see the same machine.  The wall times are kept in the per-run
  records;
* how many runs each verdict got (fgdoppler) or failed to run (peers), and
  of the runs whose own NEES, averaged over t ≥ 10 s, lies beyond the χ²₄
  99.9 % quantile (the truth outside the stated 99.9 % ellipsoid on
  average), how many the verdict does not flag (goal 4's second clause);
* the deterministic-CV CRLB of the position for filtering and smoothing,
  averaged over the same times;
* the exact posterior (:mod:`benchmarks._exact`: importance-sampled; the
  truth's exactly constant-velocity motion, the zone and the weak prior
  that the estimators assume) given the data up to each of t = 10, 12.5,
  ..., 30 s: rows ``exact-filtered``, ``exact-lagged`` (the data up to
  t plus the fixed-lag smoother's lag) and ``exact-smoothed`` (all the
  data, at every time).  Its NEES is what a perfect Bayesian estimator's
  mean and covariance would give; a run where even it lies beyond the
  99.9 % quantile has the truth in the posterior's tail, where no mean and
  covariance of the data's posterior enclose it, and goal 4's second
  clause counts such runs apart.  The filtered and lagged rows have no
  RMSE in the table (they are sampled from 10 s on, every 2.5 s, only).
* row ``stonesoup-pf`` (with the extra ``stonesoup``): Stone Soup's
  resample-move particle filter (:func:`benchmarks._peers.run_stonesoup_pf`,
  20,000 particles) on the first ``--pf-timing-runs`` runs of each scenario
  (3 by default), for its CPU time only: goal 2 asks for a tenth of the
  particle filter's run time, and the issue's 9 s were measured on another
  machine.  Its accuracy is not the issue's (it collapses in case a 45 km),
  so goal 2's RMSE stays the issue's and the table shows this row's time
  alone.

Then the goals of the accuracy issue are checked on the table.

Run: ``python -m benchmarks.bench_accuracy --runs 100 --seed 2026`` (30
minutes on 2 cores, 16 of them without the exact posterior, ``--no-exact``,
2026-11-24; on a slower machine on 2026-12-01, with the particle filter's
timing, 27 and 30 min with ``--no-exact``); results go to
``output/bench_accuracy/`` (JSON and a Markdown table).
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

import fgdoppler as fd
from benchmarks._common import Row
from benchmarks._exact import MIN_ESS, ExactPosterior, exact_track
from fgdoppler.analysis.bounds import crlb_deterministic
from fgdoppler.analysis.metrics import compare_rmse, errors, nees, nees_band, time_averaged_rmse
from fgdoppler.analysis.workers import one_blas_thread

FloatArray = NDArray[np.float64]

OURS: tuple[str, ...] = tuple(fd.ESTIMATORS)
#: Settings variants run beside the registry's defaults (row name -> estimator, settings).
VARIANTS: dict[str, tuple[str, Any]] = {"ekf-scan": ("ekf", fd.EKFSettings(update="scan"))}
ONLINE: tuple[str, ...] = tuple(n for n, info in fd.ESTIMATORS.items() if info.online)
T_RMSE = 5.0
T_NEES = 10.0
#: A run is called inconsistent when its NEES averaged over t >= T_NEES exceeds this quantile of chi-square(4):
#: a consistent run's time average, of identically distributed chi-square(4) terms, exceeds it with a probability
#: of at most about 0.1 % (exactly that when the terms are fully correlated, less when they are not).
RUN_NEES_LEVEL = 0.999
#: Spacing (s) of the times, from ``T_NEES`` after the first measurement, at which the exact posterior is sampled.
EXACT_STEP = 2.5
#: Which exact posterior each of fgdoppler's estimators is held against (goal 4's second clause).
EXACT_OF: dict[str, str] = {"smoother": "exact-smoothed", "fixed-lag": "exact-lagged"}
#: Rows sampled at a few times from ``T_NEES`` on only: NEES but no time-averaged RMSE in the table.
SPARSE: tuple[str, ...] = ("exact-filtered", "exact-lagged")
#: Stone Soup's particle filter, timed on a few runs per scenario for goal 2's budget (module docstring).
PF_ROW = "stonesoup-pf"
#: Runs per scenario (the first ones) on which :data:`PF_ROW` is timed by default.
PF_TIMING_RUNS = 3


def _on_grid(truth_t: FloatArray, t: FloatArray, x: FloatArray, P: FloatArray, truth: FloatArray,
             ok: NDArray[np.bool_] | None = None) -> tuple[FloatArray, FloatArray]:
    """Squared position error and NEES on the truth time grid (NaN where the estimator has no state)."""
    se = np.full(truth_t.size, np.nan)
    ne = np.full(truth_t.size, np.nan)
    idx = np.searchsorted(truth_t, t)
    hit = (idx < truth_t.size) & (np.abs(truth_t[np.clip(idx, 0, truth_t.size - 1)] - t) < 1e-9)
    if ok is not None:
        hit &= ok
    if not np.any(hit):
        return se, ne
    finite = np.all(np.isfinite(x[hit]), axis=1)
    i = idx[hit][finite]
    xs, Ps = x[hit][finite], P[hit][finite]
    se[i] = errors(xs, truth[i])[0]
    with np.errstate(all="ignore"):
        try:
            ne[i] = nees(xs, Ps, truth[i])
        except np.linalg.LinAlgError:
            ne[i] = np.nan
    return se, ne


def recording(s: int, r: int, seed: int) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation]:
    """Run ``r`` of paper scenario ``s`` as the benchmark simulates it with ``seed``, its model and its start (the
    initiation on each pair's first 10 measurements)."""
    sim = fd.simulate(fd.paper_scenarios()[s], np.random.default_rng(np.random.SeedSequence([seed, s, r])))
    model = fd.TrackingModel.of(sim.scenario.geometry)
    return sim, model, fd.initiate(sim.measurements.first_per_pair(10), model)


@one_blas_thread
def one_run(args: tuple[int, int, int, bool, bool]) -> dict[str, Any]:
    """Simulate, initiate and run every estimator and peer on run ``r`` of scenario ``s`` (one BLAS thread),
    with ``exact`` sample the exact posterior (:func:`exact_rows`) and with ``time_pf`` run :data:`PF_ROW`."""
    from benchmarks._peers import run_peers, run_stonesoup_pf, stonesoup_available

    s, r, seed, exact, time_pf = args
    sim, model, init = recording(s, r, seed)
    m = sim.measurements
    tt, truth = sim.truth.times, sim.truth.states
    out: dict[str, Any] = {}
    cpu = time.process_time()
    reference = fd.run_estimator("smoother", m, model, init)
    cpu_reference = time.process_time() - cpu
    runs = [(name, name, None) for name in OURS] + [(row, n, st) for row, (n, st) in VARIANTS.items()]
    for row, name, settings in runs:
        cpu = time.process_time()
        res = reference if row == "smoother" else fd.run_estimator(name, m, model, init, settings, reference=reference)
        cpu = cpu_reference if row == "smoother" else time.process_time() - cpu
        e = res.primary
        se, ne = _on_grid(tt, e.times, e.states, e.covariances, truth, e.cov_ok)
        out[row] = {"se": se, "nees": ne, "seconds": cpu, "wall": res.wall_time, "status": str(res.status)}
    if exact:
        out.update(exact_rows(m, model, init, reference, tt, truth, seed=seed))
    if time_pf and stonesoup_available():
        t, x, P, sec = run_stonesoup_pf(model, m, seed=r)
        se, ne = _on_grid(tt, t, x, P, truth)
        out[PF_ROW] = {"se": se, "nees": ne, "seconds": sec, "wall": float("nan"), "status": "ran"}
    if init.P_end is None:
        return {"s": s, "r": r, "results": out, "peers_skipped": "initiation covariance indeterminate"}
    try:
        peers = run_peers(model, init, m)
    except (np.linalg.LinAlgError, ValueError) as exc:
        return {"s": s, "r": r, "results": out, "peers_skipped": str(exc).splitlines()[0]}
    for name, (t, x, P, sec) in peers.items():
        se, ne = _on_grid(tt, t, x, P, truth)
        out[name] = {"se": se, "nees": ne, "seconds": sec, "wall": float("nan"), "status": "ran"}
    return {"s": s, "r": r, "results": out}


def exact_posteriors(m: fd.Measurements, model: fd.TrackingModel, init: fd.Initiation, reference: fd.TrackResult,
                     *, seed: int, min_ess: float = MIN_ESS) -> tuple[FloatArray, dict[float, ExactPosterior]]:
    """The times at which the benchmark samples the exact posterior, and the posteriors given the data up to each.

    The times are every :data:`EXACT_STEP` from ``T_NEES`` after the first
    measurement, and the last measurement's; each posterior is started from
    the offline smoother's first state, the initiation's and the previous
    time's mean (:func:`benchmarks._exact.exact_track`), keyed by its time
    rounded to the microsecond.  A time where the data do not fix the state,
    or where the sampler has fewer than ``min_ess`` effective samples, is
    left out.
    """
    t0, last = float(np.min(m.time)), float(np.max(m.time))
    starts = [model.motion.F(t0 - float(reference.primary.times[0])) @ reference.primary.states[0],
              model.motion.F(t0 - init.t_start) @ init.x_start]
    ends = np.union1d(t0 + np.arange(T_NEES, last - t0 - 1e-6, EXACT_STEP), [last])
    posts = exact_track(m, model, ends, starts, seed, min_ess=min_ess)
    return ends, {round(t_end, 6): post for t_end, post in posts.items()}


def exact_rows(m: fd.Measurements, model: fd.TrackingModel, init: fd.Initiation, reference: fd.TrackResult,
               tt: FloatArray, truth: FloatArray, *, seed: int) -> dict[str, dict[str, Any]]:
    """Rows ``exact-filtered``, ``exact-lagged`` and ``exact-smoothed`` of one run (module docstring), read from
    :func:`exact_posteriors`; a time it leaves out is NaN."""
    last = float(np.max(m.time))
    cpu = time.process_time()
    ends, posts = exact_posteriors(m, model, init, reference, seed=seed)
    cpu = time.process_time() - cpu
    lag = fd.FixedLagSettings().lag
    given = {"exact-filtered": lambda t: t, "exact-lagged": lambda t: min(t + lag, last),
             "exact-smoothed": lambda t: last}
    rows: dict[str, dict[str, Any]] = {}
    for name, condition in given.items():
        se = np.full(tt.size, np.nan)
        ne = np.full(tt.size, np.nan)
        for i, t in enumerate(tt):
            sampled = name == "exact-smoothed" or np.any(np.abs(ends - t) < 1e-9)
            found = posts.get(round(condition(float(t)), 6)) if sampled else None
            if found is not None:
                se[i] = found.position_error(truth[i], float(t), model.motion)
                ne[i] = found.nees(truth[i], float(t), model.motion)
        rows[name] = {"se": se, "nees": ne, "seconds": cpu, "wall": float("nan"), "status": "ran"}
    return rows


def _bounds(scen: fd.Scenario) -> tuple[FloatArray, FloatArray, FloatArray]:
    sim = fd.simulate(scen, np.random.default_rng(0))
    t = sim.truth.times
    f = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, t)
    sm = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, t, smoothing=True)
    return t, np.sqrt(f[:, 0, 0] + f[:, 1, 1]), np.sqrt(sm[:, 0, 0] + sm[:, 1, 1])


def mean_after(x: FloatArray, t: FloatArray, t0: float) -> float:
    """Mean of the finite values of ``x`` at the times ``t >= t0`` (NaN where none): the time average of the
    tables (position error from ``T_RMSE``, NEES from ``T_NEES``)."""
    sel = (t >= t0 - 1e-9) & np.isfinite(x)
    return float(np.mean(x[sel])) if np.any(sel) else float("nan")


def inconsistent_runs(nees_runs: FloatArray, t: FloatArray, statuses: list[str]) -> tuple[int, int]:
    r"""(inconsistent runs, those of them judged ``ok``) of one estimator in one scenario.

    A run is inconsistent when its NEES averaged over :math:`t \ge` ``T_NEES``
    exceeds the :data:`RUN_NEES_LEVEL` quantile of :math:`\chi^2_4`.  Runs
    with no NEES after ``T_NEES`` count as neither.
    """
    if not nees_runs.size:
        return 0, 0
    bad = run_inconsistent(nees_runs, t)
    return int(bad.sum()), int(sum(1 for b, st in zip(bad, statuses, strict=True) if b and st == "ok"))


def run_inconsistent(nees_runs: FloatArray, t: FloatArray) -> NDArray[np.bool_]:
    r"""Per run: NEES averaged over :math:`t \ge` ``T_NEES`` beyond the :data:`RUN_NEES_LEVEL` quantile of
    :math:`\chi^2_4` (False for a run with no NEES then)."""
    late = nees_runs[:, t >= T_NEES]
    has = np.any(np.isfinite(late), axis=1)
    run_nees = np.full(late.shape[0], np.nan)
    run_nees[has] = np.nanmean(late[has], axis=1)
    return np.asarray(np.nan_to_num(run_nees, nan=0.0) > chi2.ppf(RUN_NEES_LEVEL, 4))


def summarise(records: list[dict[str, Any]], runs: int) -> dict[str, Any]:
    """Per scenario: RMSE, NEES, median time and verdict counts of every estimator, and the bounds."""
    with warnings.catch_warnings():
        # all-NaN columns are expected: a filter has no state before its initiation window ends
        warnings.simplefilter("ignore", RuntimeWarning)
        return _summarise(records, runs)


def _unflagged_in_exact_tail(recs: list[dict[str, Any]], name: str, exact: str, t: FloatArray) -> int:
    """Inconsistent runs of ``name`` judged ``ok`` where the exact posterior ``exact`` is inconsistent too."""
    both = [rec["results"] for rec in recs if name in rec["results"] and exact in rec["results"]]
    if not both:
        return 0
    ours = run_inconsistent(np.array([x[name]["nees"] for x in both]), t)
    ideal = run_inconsistent(np.array([x[exact]["nees"] for x in both]), t)
    ok = np.array([x[name]["status"] == "ok" for x in both])
    return int(np.sum(ours & ideal & ok))


def _summarise(records: list[dict[str, Any]], runs: int) -> dict[str, Any]:
    scens = fd.paper_scenarios()
    table: dict[str, Any] = {}
    for s, scen in enumerate(scens):
        recs = [rec for rec in records if rec["s"] == s]
        t, crlb_f, crlb_s = _bounds(scen)
        row: dict[str, Any] = {"crlb_filter": mean_after(crlb_f, t, T_RMSE),
                               "crlb_smoother": mean_after(crlb_s, t, T_RMSE), "estimators": {}}
        names = list(dict.fromkeys(n for rec in recs for n in rec["results"]))
        for name in names:
            rs = [rec["results"][name] for rec in recs if name in rec["results"]]
            se = np.array([x["se"] for x in rs])
            ne = np.array([x["nees"] for x in rs])
            statuses = [x["status"] for x in rs]
            with np.errstate(all="ignore"):
                nees_t = np.nanmean(ne, axis=0) if ne.size else np.full(t.size, np.nan)
            inconsistent, unflagged = inconsistent_runs(ne, t, statuses)
            row["estimators"][name] = {
                "rmse": float(time_averaged_rmse(se, t, t0=T_RMSE)),
                "median_error": mean_after(np.nanmedian(np.sqrt(se), axis=0), t, T_RMSE),
                "nees": mean_after(nees_t, t, T_NEES),
                "seconds": float(np.median([x["seconds"] for x in rs])),
                "runs": len(rs),
                "verdicts": {k: statuses.count(k) for k in sorted(set(statuses))},
                "inconsistent": inconsistent,
                "unflagged": unflagged,
            }
        row["skipped_peers"] = sum(1 for rec in recs if "peers_skipped" in rec)
        # per-run errors for the goals' paired comparisons (not written to the JSON summary)
        row["_t"] = t
        row["_se"] = {name: np.array([rec["results"][name]["se"] if name in rec["results"]
                                      else np.full(t.size, np.nan) for rec in recs]) for name in names}
        for name in OURS:
            exact = EXACT_OF.get(name, "exact-filtered")
            if name in row["estimators"] and exact in names:
                row["estimators"][name]["unflagged_in_exact_tail"] = _unflagged_in_exact_tail(recs, name, exact, t)
        table[scen.name] = row
    return {"runs": runs, "nees_band": nees_band(runs), "scenarios": table}


#: The resample-move particle filter of the accuracy issue (Stone Soup 1.9, 20,000 particles, uniform prior over
#: the zone; 10 runs per scenario): time-averaged position RMSE (m) and its run time, 9-11 s per run.  Measured by
#: the issue's authors; a Stone Soup particle filter rebuilt here (``_peers.run_stonesoup_pf``) collapses in a-45
#: (RMSE 556-676 m), so goal 2 is checked against these published numbers rather than against a weaker rerun.
ISSUE_PARTICLE_FILTER: dict[str, float] = {
    "case a, start 5 km": 1111.0, "case a, start 25 km": 1895.0, "case a, start 45 km": 177.0,
    "case b, start 5 km": 153.0, "case b, start 25 km": 1860.0, "case b, start 45 km": 1162.0}
ISSUE_PARTICLE_FILTER_SECONDS = 9.0


#: Runs per scenario behind :data:`ISSUE_PARTICLE_FILTER`.
ISSUE_PARTICLE_FILTER_RUNS = 10


def _runs(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


def particle_filter_seconds(row: dict[str, Any]) -> tuple[float, str]:
    """Goal 2's particle-filter run time in one scenario, and where it comes from.

    The median CPU time of :data:`PF_ROW` where this benchmark run timed it
    (same machine, same load as our estimators: the ratio the goal asks
    for), else the issue's :data:`ISSUE_PARTICLE_FILTER_SECONDS`.
    """
    timed = row["estimators"].get(PF_ROW)
    if timed is not None and np.isfinite(timed["seconds"]):
        return float(timed["seconds"]), f"Stone Soup's PF timed here, median of {_runs(timed['runs'])}"
    return ISSUE_PARTICLE_FILTER_SECONDS, "the issue's"


def _paired(row: dict[str, Any], ours: str, peer: str) -> str:
    """The paired-bootstrap difference ``ours - peer`` and whether the runs resolve it."""
    se = row.get("_se")
    if se is None or ours not in se or peer not in se:
        return ""
    c = compare_rmse(se[ours], se[peer], row["_t"], t0=T_RMSE)
    return f"{ours} - {peer}: {c}, " + ("resolved" if c.resolved else "a tie within the runs' noise")


def _subset_share(row: dict[str, Any], name: str, value: float, size: int, resamples: int = 2000) -> str:
    """How often ``size`` of this scenario's runs give ``name`` a time-averaged RMSE at or below ``value``.

    The issue's particle filter was measured on 10 runs; a 10-run RMSE
    scatters by tens of per cent, so its number is put beside the
    distribution of our own 10-run RMSEs.
    """
    se = row.get("_se", {}).get(name)
    if se is None or se.shape[0] <= size:
        return ""
    rng = np.random.default_rng(0)
    counts = np.zeros((resamples, se.shape[0]))
    for b in range(resamples):
        counts[b, rng.choice(se.shape[0], size, replace=False)] = 1.0
    r = time_averaged_rmse(se, row["_t"], t0=T_RMSE, counts=counts)
    lo, hi = np.nanpercentile(r, [5, 95])
    return (f"{name}'s RMSE on {size} of the {se.shape[0]} runs: 90 % within {lo:,.0f}-{hi:,.0f} m, "
            f"at or below {value:,.0f} in {100 * float(np.mean(r <= value)):.0f} % of draws")


def goals(summary: dict[str, Any]) -> list[tuple[str, str, bool, str, str]]:
    """The accuracy issue's goals 1-4 per scenario: (goal, scenario, met, numbers, evidence).

    ``met`` is the goal as the issue states it (no worse, on these runs);
    ``evidence`` says how sure the runs are: the paired-bootstrap interval
    of the difference (:func:`fgdoppler.analysis.metrics.compare_rmse`), or
    for the issue's particle filter, measured on 10 runs only, how often
    10 of ours reach its number.
    """
    from benchmarks._peers import SMOOTHERS

    out = []
    hi = summary["nees_band"][1]
    for name, row in summary["scenarios"].items():
        est = row["estimators"]
        r = {k: v["rmse"] for k, v in est.items()}
        if "filterpy-ekf" in r:
            peer = min(("filterpy-ekf", "filterpy-ukf"), key=lambda n: r[n])
            best_peer = r[peer]
            out.append(("1: EKF <= plain EKF and UKF", name, r["ekf"] <= best_peer,
                        f"ekf {r['ekf']:.0f} vs EKF {r['filterpy-ekf']:.0f} / UKF {r['filterpy-ukf']:.0f}",
                        _paired(row, "ekf", peer)))
            # the best of the online estimators that run in a tenth of the particle filter's time
            pf_seconds, timed_by = particle_filter_seconds(row)
            fast = [n for n in ONLINE if est[n]["seconds"] <= pf_seconds / 10] or list(ONLINE)
            best_online = min(fast, key=lambda n: r[n])
            pf = ISSUE_PARTICLE_FILTER.get(name, float("inf"))
            best_filter = min(best_peer, pf)
            in_time = est[best_online]["seconds"] <= pf_seconds / 10
            evidence = (_subset_share(row, best_online, pf, ISSUE_PARTICLE_FILTER_RUNS) if pf < best_peer
                        else _paired(row, best_online, peer))
            out.append(("2: best online <= best peer filter incl. PF, <= 1/10 PF time", name,
                        r[best_online] <= best_filter and in_time,
                        f"{best_online} {r[best_online]:.0f} in {est[best_online]['seconds']:.2f} s vs "
                        f"{best_filter:.0f} (the issue's PF {pf:.0f}; PF time {pf_seconds:.1f} s, {timed_by})",
                        evidence))
            smoothers = [n for n in SMOOTHERS if n in r]
            best_sm = min(smoothers, key=lambda n: r[n])
            out.append(("3: smoother <= best peer smoother", name, r["smoother"] <= r[best_sm],
                        f"smoother {r['smoother']:.0f} vs {best_sm} {r[best_sm]:.0f}",
                        _paired(row, "smoother", best_sm)))
        if name in ("case a, start 45 km", "case b, start 5 km"):
            ratio = r["smoother"] / row["crlb_smoother"]
            out.append(("3: smoother <= 1.1 x smoothing CRLB", name, ratio <= 1.1, f"{ratio:.2f}", ""))
        worst = max(OURS, key=lambda n: est[n]["nees"])
        out.append(("4: NEES <= 2 x band's upper edge", name, est[worst]["nees"] <= 2 * hi,
                    f"worst {worst} {est[worst]['nees']:.3g} (limit {2 * hi:.2f})", ""))
        bad = sum(est[n]["inconsistent"] for n in OURS)
        missed = {n: est[n]["unflagged"] for n in OURS if est[n]["unflagged"]}
        shared = [est[n]["unflagged_in_exact_tail"] for n in missed if "unflagged_in_exact_tail" in est[n]]
        out.append(("4: inconsistent runs' verdicts not ok", name, not missed,
                    f"{bad - sum(missed.values())} of {bad} flagged",
                    ("judged ok: " + ", ".join(f"{n} {c}" for n, c in missed.items())
                     + (f"; {sum(shared)} of them in runs where the exact posterior is inconsistent too"
                        if shared else "")) if missed else ""))
    return out


def markdown(summary: dict[str, Any], seed: int, wall: float) -> str:
    """The table and the goals as Markdown."""
    scen_names = list(summary["scenarios"])
    short = [n.replace("case ", "").replace(", start ", "-").replace(" km", "") for n in scen_names]
    names = list(dict.fromkeys(n for row in summary["scenarios"].values() for n in row["estimators"]))
    scored = [n for n in names if n != PF_ROW]  # the PF row is timed only: its accuracy is not the issue's PF's
    lo, hi = summary["nees_band"]
    took = f"{wall:.0f} s" if np.isfinite(wall) else "summarised from saved per-run records"
    lines = [f"{summary['runs']} runs per scenario, seed {seed}, {took}.  Position RMSE averaged over "
             f"t >= {T_RMSE:g} s (m); NEES averaged over runs and t >= {T_NEES:g} s (95 % band {lo:.2f}-{hi:.2f}); "
             "median CPU time per run (s)." + _load_note(summary), "",
             "| estimator | " + " | ".join(short) + " |", "|---|" + "---|" * len(short)]
    for n in scored:
        cells = []
        for sn in scen_names:
            e = summary["scenarios"][sn]["estimators"].get(n)
            cells.append("—" if e is None or n in SPARSE else f"{e['rmse']:,.0f}")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    for key, label in (("crlb_filter", "filtering CRLB"), ("crlb_smoother", "smoothing CRLB")):
        lines.append(f"| {label} | " + " | ".join(f"{summary['scenarios'][sn][key]:,.0f}" for sn in scen_names)
                     + " |")
    lines += ["", "| NEES | " + " | ".join(short) + " |", "|---|" + "---|" * len(short)]
    for n in scored:
        lines.append(f"| {n} | " + " | ".join(
            f"{summary['scenarios'][sn]['estimators'][n]['nees']:.3g}" for sn in scen_names) + " |")
    lines += ["", "| median CPU time (s) / verdicts | " + " | ".join(short) + " |", "|---|" + "---|" * len(short)]
    for n in names:
        cells = []
        for sn in scen_names:
            e = summary["scenarios"][sn]["estimators"].get(n)
            if e is None:
                cells.append("—")
                continue
            v = e["verdicts"]
            ver = " ".join(f"{k[0]}{c}" for k, c in v.items()) if set(v) != {"ran"} else ""
            ver = f"({_runs(e['runs'])})" if n == PF_ROW else ver
            cells.append(f"{e['seconds']:.3f} {ver}".strip())
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    lines += ["", *goal_table(goals(summary))]
    return "\n".join(lines) + "\n"


def goal_table(rows: list[tuple[str, str, bool, str, str]]) -> list[str]:
    """The goals (:func:`goals`) as the lines of a Markdown table (read back by ``studies/reproduction_page.py``)."""
    lines = ["| goal | scenario | met | numbers | evidence |", "|---|---|---|---|---|"]
    for g, sn, met, detail, evidence in rows:
        lines.append(f"| {g} | {sn} | {'yes' if met else '**no**'} | {detail} | {evidence} |")
    return lines


def _load_note(summary: dict[str, Any]) -> str:
    load = summary.get("load")
    if not load:
        return ""
    extra = load["average_15_min"] - load["workers"]
    note = (f"  Load average over the last 15 min {load['average_15_min']:.1f} on {load['cores']} cores with "
            f"{load['workers']} workers of its own")
    return note + (": other jobs ran beside it, the times are longer than on a quiet machine." if extra > 0.5
                   else ".")


def study(runs: int, seed: int, workers: int, *, exact: bool = True, pf_runs: int = PF_TIMING_RUNS
          ) -> tuple[dict[str, Any], float, list[dict[str, Any]]]:
    """Run every (scenario, run); the summary, the wall time and the per-run records.  ``exact=False``
    leaves out the exact posterior (about half the run time) and with it goal 4's count of shared misses;
    :data:`PF_ROW` is timed on the first ``pf_runs`` runs of each scenario."""
    tasks = [(s, r, seed, exact, r < pf_runs) for s in range(len(fd.paper_scenarios())) for r in range(runs)]
    t0 = time.perf_counter()
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            records = list(pool.map(one_run, tasks, chunksize=4))
    else:
        records = [one_run(t) for t in tasks]
    summary = summarise(records, runs)
    # the machine's load over the run's last 15 minutes, its own workers included: CPU times of a run
    # beside other jobs come out longer (module docstring), and the table should say so
    summary["load"] = {"average_15_min": os.getloadavg()[2], "workers": workers, "cores": os.cpu_count()}
    return summary, time.perf_counter() - t0, records


def save_records(records: list[dict[str, Any]], path: Path) -> None:
    """Per-run squared errors, NEES, times and verdicts as ``.npz`` (keys ``<field>_<s>_<name>``)."""
    # Any, not ndarray: numpy's stub would match the unpacked dict against savez_compressed's allow_pickle
    arrays: dict[str, Any] = {}
    for s in sorted({rec["s"] for rec in records}):
        recs = sorted((rec for rec in records if rec["s"] == s), key=lambda rec: rec["r"])
        for name in dict.fromkeys(n for rec in recs for n in rec["results"]):
            rs = [rec["results"].get(name) for rec in recs]
            width = next(len(x["se"]) for x in rs if x is not None)
            nan = np.full(width, np.nan)
            arrays[f"se_{s}_{name}"] = np.array([nan if x is None else x["se"] for x in rs])
            arrays[f"nees_{s}_{name}"] = np.array([nan if x is None else x["nees"] for x in rs])
            arrays[f"seconds_{s}_{name}"] = np.array([np.nan if x is None else x["seconds"] for x in rs])
            arrays[f"wall_{s}_{name}"] = np.array([np.nan if x is None else x.get("wall", np.nan) for x in rs])
            arrays[f"status_{s}_{name}"] = np.array(["" if x is None else x["status"] for x in rs])
    np.savez_compressed(path, **arrays)


def load_records(path: Path) -> list[dict[str, Any]]:
    """The per-run records of :func:`save_records` back, to summarise a finished run again."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    records: dict[tuple[int, int], dict[str, Any]] = {}
    for key in arrays:
        field_name, s, name = key.split("_", 2)
        if field_name != "se":
            continue
        for r in range(arrays[key].shape[0]):
            se = arrays[key][r]
            if not np.any(np.isfinite(se)) and arrays[f"status_{s}_{name}"][r] == "":
                continue  # this estimator did not run here (a skipped peer)
            rec = records.setdefault((int(s), r), {"s": int(s), "r": r, "results": {}})
            rec["results"][name] = {"se": se, "nees": arrays[f"nees_{s}_{name}"][r],
                                    "seconds": float(arrays[f"seconds_{s}_{name}"][r]),
                                    "wall": float(arrays[f"wall_{s}_{name}"][r]) if f"wall_{s}_{name}" in arrays
                                    else float("nan"),
                                    "status": str(arrays[f"status_{s}_{name}"][r])}
    return [records[k] for k in sorted(records)]


def json_summary(summary: dict[str, Any]) -> str:
    """The summary as JSON, without the per-run arrays kept for the goals."""
    def clean(d: Any) -> Any:
        return {k: clean(v) for k, v in d.items() if not k.startswith("_")} if isinstance(d, dict) else d
    return json.dumps(clean(summary), indent=1)


def run() -> list[Row]:
    """For ``python -m benchmarks``: 100 runs, seed 2026, one row per goal and scenario."""
    summary, _wall, _ = study(100, 2026, 2)
    return [Row(name=f"accuracy goal {g}, {sn}", value=f"{detail}; {evidence}" if evidence else detail,
                target="see issue", met=met) for g, sn, met, detail, evidence in goals(summary)]


def main() -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_accuracy")
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("output/bench_accuracy"))
    p.add_argument("--no-exact", action="store_true",
                   help="leave out the exact posterior's rows (about half the run time)")
    p.add_argument("--pf-timing-runs", type=int, default=PF_TIMING_RUNS,
                   help="time Stone Soup's particle filter on the first K runs of each scenario, goal 2's "
                        "budget (0: the issue's 9 s)")
    p.add_argument("--records", type=Path, default=None,
                   help="summarise the per-run records (.npz) of an earlier run again instead of running")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.records is not None:
        records = load_records(args.records)
        runs = 1 + max(rec["r"] for rec in records)
        t0 = time.perf_counter()
        summary, wall = summarise(records, runs), float("nan")
        print(f"re-summarised {len(records)} records in {time.perf_counter() - t0:.1f} s")
    else:
        summary, wall, records = study(args.runs, args.seed, args.workers, exact=not args.no_exact,
                                       pf_runs=args.pf_timing_runs)
        save_records(records, args.out / f"accuracy_seed{args.seed}.npz")
    text = markdown(summary, args.seed, wall)
    (args.out / f"accuracy_seed{args.seed}.md").write_text(text)
    (args.out / f"accuracy_seed{args.seed}.json").write_text(json_summary(summary))
    print(text)


if __name__ == "__main__":
    main()
