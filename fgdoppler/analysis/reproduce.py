"""One-command reproduction of the paper, plus the studies that go beyond it.

:func:`reproduce` writes every artefact into one folder with a ``report.md``
that puts the paper's values beside ours and marks each of the paper's
claims as reproduced or not:

* Table 2 and Figs. 3–8 (observability), via :mod:`fgdoppler.analysis.artefacts`;
* Figs. 10–11: position RMSE versus time over Monte Carlo runs of the six
  scenarios for the grid-only, ILS and LM initiations, the EKF, iSAM2
  (filtered), the fixed-lag smoother and the full smoother, with the
  Cramér–Rao bounds (filtering and smoothing) on the same axes;
* beyond the paper: a lag sweep, NEES consistency, and the observability
  report of every scenario.
"""

from __future__ import annotations

import json
import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fgdoppler import plotting
from fgdoppler._io import atomic_write_text
from fgdoppler.analysis import artefacts
from fgdoppler.analysis.bounds import crlb_deterministic
from fgdoppler.analysis.montecarlo import MonteCarloResult, MonteCarloSpec, run_monte_carlo
from fgdoppler.analysis.observability import observability_report
from fgdoppler.estimators.registry import ESTIMATORS
from fgdoppler.simulation import Scenario, paper_scenarios, simulate

__all__ = ["ReproduceSettings", "altitude_section", "lag_sweep", "paper_monte_carlo", "reproduce"]

TRACKERS = tuple(ESTIMATORS)


@dataclass(frozen=True, kw_only=True)
class ReproduceSettings:
    """Settings of :func:`reproduce`.

    Parameters
    ----------
    runs
        Monte Carlo runs per scenario (the paper uses 100).
    workers
        Worker processes (ignored when an executor is given).
    seed
        Root seed of all Monte Carlo runs.
    lag_sweep_lags
        Lags (s) of the lag sweep; the sweep uses ``max(min(4, runs), runs // 5)`` runs (a
        fifth of ``runs``, at least 4, never more than ``runs``).
    altitude_runs
        Runs per scenario and height of the altitude study
        (:mod:`fgdoppler.analysis.altitude`); ``None``: ``max(1, runs // 10)``; 0 skips it.
    altitude_scenarios
        ``(case, start_x)`` of the paper scenarios in the altitude study (``None``: all six).
    """

    runs: int = 100
    workers: int = 2
    seed: int = 2026
    lag_sweep_lags: tuple[float, ...] = (1.0, 2.0, 5.0, 10.0, 30.0)
    well_observed: tuple[str, ...] = field(default=("case a, start 45 km", "case b, start 5 km"))
    altitude_runs: int | None = None
    altitude_scenarios: tuple[tuple[str, float], ...] | None = None


def paper_monte_carlo(
    out: Path, settings: ReproduceSettings, *, executor: Executor | None = None, progress: bool | None = None,
) -> tuple[MonteCarloResult, tuple[dict[tuple[str, str], bool], list[str], list[Path]]]:
    """Figs. 10-11 study: six scenarios x all estimators; saves ``montecarlo.npz/json`` and the figures.

    Returns the result and ``(claims, report lines, figure paths)``.
    """
    out.mkdir(parents=True, exist_ok=True)
    scenarios = tuple(paper_scenarios())
    spec = MonteCarloSpec(scenarios=scenarios, runs=settings.runs, seed=settings.seed)
    mc = run_monte_carlo(spec, executor=executor, workers=settings.workers, progress=progress)
    mc.save(out / "montecarlo")
    return mc, _monte_carlo_section(mc, scenarios, out, settings)


def lag_sweep(
    out: Path, settings: ReproduceSettings, *, executor: Executor | None = None, progress: bool | None = None,
) -> tuple[list[str], Path]:
    """Lag sweep on case (b) at 5 km (``max(min(4, runs), runs // 5)`` runs); saves ``lag_sweep.npz/json`` and the figure."""
    out.mkdir(parents=True, exist_ok=True)
    scen = next(s for s in paper_scenarios() if s.name == "case b, start 5 km")
    spec = MonteCarloSpec(scenarios=(scen,), runs=max(min(4, settings.runs), settings.runs // 5), seed=settings.seed + 1,
                          estimators=(*(f"lag:{lag:g}" for lag in settings.lag_sweep_lags), "ekf", "smoother"))
    sweep = run_monte_carlo(spec, executor=executor, workers=settings.workers, progress=progress)
    sweep.save(out / "lag_sweep")
    return _lag_sweep_section(sweep, out)


def altitude_section(out: Path, settings: ReproduceSettings) -> tuple[list[str], Path | None]:
    """The altitude study (3-D): saves ``altitude.json`` and ``altitude.png``; returns the report lines."""
    from fgdoppler.analysis.altitude import altitude_study

    runs = max(1, settings.runs // 10) if settings.altitude_runs is None else settings.altitude_runs
    if runs == 0:
        return [], None
    study = altitude_study(runs=runs, seed=settings.seed + 2, workers=settings.workers,
                           scenarios=settings.altitude_scenarios)
    atomic_write_text(out / "altitude.json", json.dumps(study.to_dict(), indent=1))
    fig = study.figure(out / "altitude.png")
    n = len(study.scenarios)
    lines = ["## Beyond the paper: the scenarios at altitude (3-D)", "",
             f"{'The scenario' if n == 1 else f'The {n} scenarios'} flown level at "
             f"{', '.join(f'{a / 1e3:g}' for a in study.altitudes)} km over the "
             f"same ground sensors, {runs} run(s) per cell ({study.wall_time:.0f} s; "
             "`fgdoppler.analysis.altitude.altitude_study`, `studies/altitude_study.py` for more runs).  O of the "
             "initiation window in 3-D (6x6 information, -40 = unobservable), the smoothing CRLB of the end position "
             "from the data alone and with the zone's weak prior, 3-D position RMSE after the window of the smoother "
             f"and the better of {' and '.join(study.online)}, the smoother's end NEES (about 6 when honest) and share of `ok` verdicts, and "
             "the horizontal RMSE of the paper's 2-D model run on the same recordings.", "",
             study.table_markdown(), ""]
    return lines, fig


def _bounds(scen: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic-CV CRLB of the position (sqrt of the trace) for filtering and smoothing."""
    sim = simulate(scen, np.random.default_rng(0))
    t = sim.truth.times
    f = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, t)
    s = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, t, smoothing=True)

    def pos(P: np.ndarray) -> np.ndarray:
        return np.sqrt(P[:, 0, 0] + P[:, 1, 1])

    return pos(f), pos(s)


def _mean_after(x: np.ndarray, t: np.ndarray, t0: float) -> float:
    sel = (t >= t0) & np.isfinite(x)
    return float(np.mean(x[sel])) if np.any(sel) else float("nan")


def reproduce(
    out: str | Path, settings: ReproduceSettings | None = None, *, executor: Executor | None = None,
    progress: bool | None = None,
) -> Path:
    """Run every study and write ``report.md`` (returned) and the artefacts into ``out``."""
    settings = settings or ReproduceSettings()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_begin = time.perf_counter()
    arts = [artefacts.fig3_geometry(out), artefacts.fig7a_ellipses(out)]
    maps_art, _ = artefacts.figs4_7_maps(out)
    arts.append(maps_art)
    arts.append(artefacts.fig8_slices(out))
    table_art, table = artefacts.table2(out)
    arts.append(table_art)
    t_obs = time.perf_counter() - t_begin

    scenarios = tuple(paper_scenarios())
    mc, (mc_claims, mc_lines, figs) = paper_monte_carlo(out, settings, executor=executor, progress=progress)
    t_mc = time.perf_counter() - t_begin - t_obs
    sweep_lines, sweep_fig = lag_sweep(out, settings, executor=executor, progress=progress)
    altitude_lines, altitude_fig = altitude_section(out, settings)
    obs_lines = _report_section(scenarios)
    wall = time.perf_counter() - t_begin

    lines = [
        "# fgdoppler: reproduction of Yang, Leung & Bar-Shalom (FUSION 2026)",
        "",
        f"Runs per scenario: {settings.runs}, workers: {mc.workers}, seed {settings.seed}. "
        f"Wall time {wall:.1f} s (observability {t_obs:.1f} s, Monte Carlo {t_mc:.1f} s).",
        "",
        "## Claims",
        "",
        "| artefact | claim | reproduced |",
        "|---|---|---|",
    ]
    for a in arts:
        for claim, ok in a.claims.items():
            lines.append(f"| {a.name} | {claim} | {'yes' if ok else '**no**'} |")
    for (name, claim), ok in mc_claims.items():
        lines.append(f"| {name} | {claim} | {'yes' if ok else '**no**'} |")
    note = _few_runs_note(settings.runs, len(mc_claims))
    if note is not None:
        lines += ["", note]
    lines += ["", "## Table 2 (observability vs speed)", "", table.to_markdown(), ""]
    lines += ["## Observability figures", ""]
    for a in arts:
        for f in a.files:
            if f.suffix == ".png":
                lines.append(f"![{a.name}]({f.name})")
    lines += [""] + mc_lines + [""] + [f"![figures 10-11]({f.name})" for f in figs]
    lines += ["", *sweep_lines, f"![lag sweep]({sweep_fig.name})", "", *obs_lines]
    if altitude_fig is not None:
        lines += ["", *altitude_lines, f"![altitude study]({altitude_fig.name})"]
    lines += ["", "## Files", "", "`montecarlo.npz`/`.json` and `lag_sweep.npz`/`.json` reload with "
              "`fgdoppler.analysis.montecarlo.MonteCarloResult.load` (no re-running)."]
    report = out / "report.md"
    atomic_write_text(report, "\n".join(lines) + "\n")
    summary: dict[str, object] = {"claims": {f"{a.name}: {c}": ok for a in arts for c, ok in a.claims.items()}
                                  | {f"{n}: {c}": ok for (n, c), ok in mc_claims.items()}, "wall_time": wall}
    if note is not None:
        summary["note"] = note
    atomic_write_text(out / "claims.json", json.dumps(summary, indent=1))
    return report


def _few_runs_note(runs: int, monte_carlo_claims: int) -> str | None:
    """What a reproduction with fewer runs than the paper's can say of its Monte Carlo claims (``None`` with as
    many runs as :class:`ReproduceSettings` takes by default, the paper's 100, or more)."""
    full = ReproduceSettings().runs
    if runs >= full:
        return None
    return (f"With {runs} run{'s' if runs != 1 else ''} per scenario, the last {monte_carlo_claims} claims (the "
            f"Monte Carlo ones: Figs. 10-11, Section 5, the smoother) compare averages over {runs} "
            f"recording{'s' if runs != 1 else ''} and can go either way; `fgdoppler reproduce` runs the paper's {full} "
            "and settles them (docs/reproduction.md shows that run).")


def _monte_carlo_section(mc: MonteCarloResult, scenarios: tuple[Scenario, ...], out: Path,
                         settings: ReproduceSettings) -> tuple[dict[tuple[str, str], bool], list[str], list[Path]]:
    names = list(mc.scenario_names)
    claims: dict[tuple[str, str], bool] = {}
    lines = ["## Figs. 10–11: position RMSE (time average after the initiation window, m)", ""]
    header = "| scenario | " + " | ".join(mc.estimators) + " | CRLB filt. | CRLB smooth. |"
    lines += [header, "|" + "---|" * (len(mc.estimators) + 3)]
    avg: dict[str, dict[str, float]] = {}
    crlbs = {}
    t_init = 4.75  # the 10-per-pair window ends by 4.75 s in every paper scenario
    for s, scen in enumerate(scenarios):
        t = mc.times[s]
        cf, cs = _bounds(scen)
        crlbs[scen.name] = (cf, cs)
        avg[scen.name] = {e: _mean_after(mc.pos_rmse(s, e), t, t_init) for e in mc.estimators}
        lines.append(f"| {scen.name} | " + " | ".join(f"{avg[scen.name][e]:.0f}" for e in mc.estimators)
                     + f" | {_mean_after(cf, t, t_init):.0f} | {_mean_after(cs, t, t_init):.0f} |")
    figs = _rmse_figures(mc, crlbs, out)
    _paper_claims(avg, names, claims, lines)
    _smoother_claims(mc, crlbs, names, settings, claims, lines)
    figs.append(_nees_section(mc, names, out, lines))
    return claims, lines, figs


def _rmse_figures(mc: MonteCarloResult, crlbs: dict[str, tuple[np.ndarray, np.ndarray]], out: Path) -> list[Path]:
    """Figs. 10-11: position RMSE over time per scenario with the CRLBs.

    One column of panels with one legend below them, so the figure stays readable at the
    width of a documentation page; the initiation estimates (constant-velocity extrapolations
    of the window's solution) are thin dotted lines, the trackers solid, the bounds black.
    """
    import matplotlib.pyplot as plt

    names = list(mc.scenario_names)
    figs = []
    for fig_no, case in ((10, "a"), (11, "b")):
        fig, axes = plt.subplots(3, 1, figsize=(7.2, 9.6), layout="constrained", sharex=True)
        for ax, x in zip(axes, ("5", "25", "45"), strict=True):
            name = f"case {case}, start {x} km"
            s = names.index(name)
            cf, cs = crlbs[name]
            plotting.plot_rmse(mc.times[s], {e: mc.pos_rmse(s, e) for e in mc.estimators}, ax,
                               bounds={"CRLB (filtering)": cf}, title=name, legend=False,
                               dotted=tuple(m for m in ("grid", "ils", "lm") if m in mc.estimators))
            ax.semilogy(mc.times[s], cs, ":", color="k", lw=1.2, label="CRLB (smoothing)")
            finite = np.concatenate([np.asarray(mc.pos_rmse(s, e))[np.isfinite(mc.pos_rmse(s, e))]
                                     for e in mc.estimators] + [cs[np.isfinite(cs)]])
            if finite.size:  # the filtering bound starts near 1e6 m: keep the estimators' range in view
                ax.set_ylim(0.5 * finite.min(), 2.0 * finite.max())
            if ax is not axes[-1]:
                ax.set_xlabel("")
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize="small", frameon=False)
        figs.append(plotting.save(axes[0], out / f"fig{fig_no}_rmse_case_{case}.png"))
    return figs


def _paper_claims(avg: dict[str, dict[str, float]], names: list[str], claims: dict[tuple[str, str], bool],
                  lines: list[str]) -> None:
    """The orderings of Figs. 10-11 and Section 5's grid-versus-EKF finding."""
    ekf = {n: avg[n]["ekf"] for n in names}
    claims[("Fig. 10", "case (a): 45 km best, 25 km worst (EKF)")] = bool(
        ekf["case a, start 45 km"] < ekf["case a, start 5 km"] < ekf["case a, start 25 km"])
    claims[("Fig. 11", "case (b): 5 km best, 25 km worst (EKF)")] = bool(
        ekf["case b, start 5 km"] < ekf["case b, start 45 km"] < ekf["case b, start 25 km"])
    poor = ("case a, start 5 km", "case a, start 25 km", "case b, start 25 km", "case b, start 45 km")
    grid_wins = {n: avg[n]["grid"] < avg[n]["ekf"] for n in poor}
    claims[("Section 5", "poor observability (25 km, a 5 km, b 45 km): the grid-only initial estimate beats the "
                         "EKF")] = all(grid_wins.values())
    lines += ["", "Section 5 of the paper finds the grid-only initial estimate more accurate than the EKF in the "
              "poorly observed scenarios. Here (time-averaged position RMSE after the window): "
              + "; ".join(f"{n}: grid {avg[n]['grid']:.0f} m vs EKF {avg[n]['ekf']:.0f} m" for n in poor)
              + ". Our EKF starts from the LM initiation (not the grid point) with its covariance and resolves "
              "ambiguous initiations by likelihood, and our grid estimate is extrapolated at constant velocity over "
              "30 s, where its velocity error (grid step 10 m/s, 20 deg) grows into kilometres; the paper's "
              "curves start from its grid point and do not state the EKF's initial covariance."]


def _smoother_claims(mc: MonteCarloResult, crlbs: dict[str, tuple[np.ndarray, np.ndarray]], names: list[str],
                     settings: ReproduceSettings, claims: dict[tuple[str, str], bool], lines: list[str]) -> None:
    """Beyond the paper: the smoother against the EKF, the grid estimate and the smoothing CRLB."""
    t_init = 4.75
    lines += ["", "## Smoother vs EKF vs CRLB", ""]
    for name in names:
        s = names.index(name)
        t = mc.times[s]
        after = t >= t_init
        sm, ek, gr = mc.pos_rmse(s, "smoother"), mc.pos_rmse(s, "ekf"), mc.pos_rmse(s, "grid")
        worse_than_ekf = np.flatnonzero(after & (sm > ek))
        ok = worse_than_ekf.size == 0
        claims[("smoother", f"{name}: smoother no worse than the EKF at every time after initiation")] = ok
        if not ok:
            when = ", ".join(f"{v:g}" for v in t[worse_than_ekf])
            lines.append(f"- {name}: the smoother is worse than the EKF at {worse_than_ekf.size} of "
                         f"{int(after.sum())} times (t = {when} s; max ratio {np.max(sm[after] / ek[after]):.2f})"
                         + (f"; at the last time ({t[-1]:g} s) both estimates condition on the same data, so the "
                            "smoother has no information advantage there"
                            if t[worse_than_ekf[-1]] == t[-1] else "") + ".")
        worse_than_grid = after & (sm > gr)
        if np.any(worse_than_grid):
            lines.append(f"- {name}: the smoother is worse than the grid-only estimate at "
                         f"{int(worse_than_grid.sum())} of {int(after.sum())} times — the paper's poor-"
                         "observability finding (a grid estimate extrapolated at constant velocity can beat "
                         "estimators that linearise an ill-conditioned problem; here the smoother also pays "
                         "for runs that settle in the wrong basin).")
        if name in settings.well_observed:
            _, cs = crlbs[name]
            sel = t >= 10.0
            ratio = float(np.max(sm[sel] / cs[sel]))
            claims[("smoother", f"{name}: full smoother RMSE within 1.1x the smoothing CRLB for t >= 10 s "
                                f"(max ratio {ratio:.2f})")] = ratio <= 1.1


def _nees_section(mc: MonteCarloResult, names: list[str], out: Path, lines: list[str]) -> Path:
    """NEES per estimator (average over t >= 10 s) with its band, and per-run medians."""
    import matplotlib.pyplot as plt

    band = mc.nees_band()
    beyond: list[str] = []
    lines += ["", f"## NEES (95 % band for {mc.runs} runs: [{band[0]:.2f}, {band[1]:.2f}])", "",
              "| scenario | " + " | ".join(TRACKERS) + " |", "|---|" + "---|" * len(TRACKERS)]
    _, axes = plt.subplots(2, 3, figsize=(15, 7.5), layout="constrained")
    for ax, name in zip(axes.ravel(), names, strict=True):
        s = names.index(name)
        t = mc.times[s]
        curves = {e: mc.mean_nees(s, e) for e in TRACKERS}
        values = {e: v if (v := mc.nees_after(s, e)) is not None else float("nan") for e in TRACKERS}
        beyond += [f"{e} in {name} ({v:.1f})" for e, v in values.items() if not v <= 2 * band[1]]
        lines.append(f"| {name} | " + " | ".join(_nees_cell(v, band) for v in values.values()) + " |")
        plotting.plot_nees(t, curves, band, ax, title=name)
    fig = plotting.save(axes.ravel()[0], out / "nees.png")
    lines.append("")
    lines.append("(average NEES over t >= 10 s; unmarked: inside the band; † above it but at most twice its upper "
                 "edge; ‡ below it, conservative; **bold**: more than twice the upper edge)")
    lines += ["", "Goal 4 of the accuracy issue (every estimator's run-averaged NEES inside the band or at most twice "
              "its upper edge): " + ("holds in every scenario." if not beyond else
                                     "does not hold for " + "; ".join(beyond) + "."),
              "Goals 1-3 compare with peer filters and smoothers (FilterPy, Stone Soup) from the same start: "
              "`python -m benchmarks.bench_accuracy --runs 100 --seed 2026` (extras `bench`, `stonesoup`)."]
    lines += ["", "Per run: median over runs of each run's NEES averaged over t >= 10 s, and in brackets the "
              "number of runs whose average exceeds 20 (a run that is consistent averages about 4).", "",
              "| scenario | " + " | ".join(TRACKERS) + " |", "|---|" + "---|" * len(TRACKERS)]
    for s, name in enumerate(names):
        per_run = {e: mc.run_nees(s, e, 10.0) for e in TRACKERS}
        lines.append(f"| {name} | " + " | ".join(
            f"{np.nanmedian(v):.2f} ({int(np.sum(v > 20))})" for v in per_run.values()) + " |")
    return fig


def _nees_cell(value: float, band: tuple[float, float]) -> str:
    """A NEES value marked against its band (see the legend under the table)."""
    if not np.isfinite(value):
        return "—"
    if value > 2 * band[1]:
        return f"**{value:.2f}**"
    if value > band[1]:
        return f"{value:.2f} †"
    if value < band[0]:
        return f"{value:.2f} ‡"
    return f"{value:.2f}"


def _lag_sweep_section(sweep: MonteCarloResult, out: Path) -> tuple[list[str], Path]:
    t = sweep.times[0]
    lags = [e for e in sweep.estimators if e.startswith("lag:")]
    values = {e: _mean_after(sweep.pos_rmse(0, e), t, 4.75) for e in sweep.estimators}
    lines = [f"## Lag sweep ({sweep.scenario_names[0]}, {sweep.runs} run{'' if sweep.runs == 1 else 's'}): position RMSE vs lag", "",
             "| lag (s) | RMSE (m) |", "|---|---|"]
    lines += [f"| {e[4:]} | {values[e]:.1f} |" for e in lags]
    lines += [f"| EKF (lag 0) | {values['ekf']:.1f} |", f"| full smoother | {values['smoother']:.1f} |", ""]
    ax = plotting.plot_lag_sweep([float(e[4:]) for e in lags], [values[e] for e in lags],
                                 references={"EKF": values["ekf"], "full smoother": values["smoother"]})
    return lines, plotting.save(ax, out / "lag_sweep.png")


def _report_section(scenarios: tuple[Scenario, ...]) -> list[str]:
    lines = ["## Observability report of each scenario (graph linearised at the truth, deterministic CV)", "",
             "| scenario | O(x0) | cond(J'J) | σ pos at 5 s (m) | σ pos at 30 s (m) | min angle to ellipse (deg) |",
             "|---|---|---|---|---|---|"]
    for scen in scenarios:
        sim = simulate(scen, np.random.default_rng(0))
        rep = observability_report(scen.geometry, sim.truth, sim.measurements)
        if rep.pos_std is None:
            lines.append(f"| {scen.name} | {rep.O_x0:.2f} | {rep.cond_JtJ:.3g} | {rep.status} | | |")
            continue
        i5 = int(np.searchsorted(rep.times, 5.0))
        sd = np.hypot(rep.pos_std[:, 0], rep.pos_std[:, 1])
        lines.append(f"| {scen.name} | {rep.O_x0:.2f} | {rep.cond_JtJ:.3g} | {sd[i5]:.0f} | {sd[-1]:.0f} | "
                     f"{rep.tangent_angle_deg.min():.1f} |")
    return lines
