r"""Does the exact posterior's sampler describe the posterior where the benchmark reads it, and where not?

The accuracy benchmark's exact-posterior rows (:mod:`benchmarks._exact`,
:func:`benchmarks.bench_accuracy.exact_posteriors`) decide part of goal 4's
second clause: a run of ours that is inconsistent where the exact posterior
is inconsistent too is counted as one no verdict could see.  That reading
holds only where the importance sampler's last pass describes the
posterior, i.e. where its effective sample size (Kish's
:math:`1/\sum_i w_i^2`) is near its target
(:data:`benchmarks._exact.ESS_TARGET`, 10,000): a proposal that misses the
posterior's mass leaves a few samples with all the weight and moments that
can be kilometres off.

Part 1, the paper's scenarios: on the benchmark's recordings (``--runs``
per scenario, ``--seed``), with the benchmark's own starts, times and
random numbers, the effective sample size of every sampled posterior.
Printed per scenario: the least, the 1st percentile and the median ESS, the
posteriors below :data:`LOW` (a tenth of the target), those with another
optimum (:attr:`~benchmarks._exact.ExactPosterior.other_mode`), and the
least ESS among the runs whose exact posterior is inconsistent (smoothed
NEES of the truth beyond the :math:`\chi^2_4` 99.9 % quantile, the runs
goal 4's count calls shared).

Part 2, ``--draws-3d K``: the first ``K`` random 3-D layouts of
``random_layouts_3d.py`` (60 s), the posterior given the data up to every
10 s, started from the truth, the initiation and its other solutions:
there the same sampler is not validated, and this says whether it can be
read ("collapsed": a pass's weight fell on too few samples to span the
state, which :func:`~benchmarks._exact.exact_posterior` refuses).

Run: python studies/exact_sampler_ess.py [--runs 100] [--seed 2026] [--workers 2] [--draws-3d 10] [--out DIR]
(41 min for seed 2026 with 10 draws in 3-D, on 2 cores beside the accuracy benchmark)
"""

from __future__ import annotations

import json
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

# _common also puts the repository root on the path, for the benchmarks
from _common import each_run, paper_run
from random_layouts import recorded
from random_layouts_3d import draw
from scipy.stats import chi2

import fgdoppler as fd
from benchmarks._exact import ESS_TARGET, MIN_ESS, exact_track
from benchmarks.bench_accuracy import exact_posteriors
from fgdoppler.analysis.workers import one_blas_thread

#: An effective sample size below this is too few to read the moments from: the sampler's own refusal.
LOW = MIN_ESS
#: Quantile of the truth's smoothed NEES (4 dimensions) beyond which a run's exact posterior is inconsistent.
LEVEL = 0.999
#: Times (s) at which part 2 samples the posterior of a 3-D draw.
TIMES_3D = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0)


@one_blas_thread
def one_run(args: tuple[int, int, int], draws_3d: int = 0) -> dict[str, Any]:
    """Every sampled posterior's ESS and second optimum in run ``r`` of scenario ``s``, and the truth's smoothed
    NEES (the posterior given the whole recording); ``draws_3d``, part 2's option, reaches it unused."""
    s, r, seed = args
    sim, model, init = paper_run(s, r, seed)
    m = sim.measurements
    reference = fd.run_estimator("smoother", m, model, init)
    _, posts = exact_posteriors(m, model, init, reference, seed=seed, min_ess=0.0)
    last = max(posts)
    smoothed = posts[last]
    truth = sim.truth.at(np.array([last]))[0]
    return {"s": s, "r": r, "ess": [p.ess for p in posts.values()],
            "other_mode": sum(p.other_mode for p in posts.values()),
            "nees": smoothed.nees(truth, last, model.motion)}


@one_blas_thread
def one_draw(k: int) -> dict[str, Any]:
    """Part 2 on 3-D draw ``k``: each time's ESS, the truth's NEES and the mean's position error there."""
    out, sim, init = recorded(k, *draw(k), duration=60.0)
    if init is None:
        return out
    model = fd.TrackingModel.of(sim.scenario.geometry)
    t0 = float(np.min(sim.measurements.time))
    carry = model.motion.F(t0 - init.t_start)
    starts = [sim.truth.at(np.array([t0]))[0], carry @ init.x_start,
              *(carry @ c.state for c in (*init.alternatives, *init.candidates))]
    posts = exact_track(sim.measurements, model, np.array(TIMES_3D), starts, seed=k, min_ess=0.0)
    rows = []
    for t, p in posts.items():
        x = sim.truth.at(np.array([t]))[0]
        rows.append({"t": t, "ess": p.ess, "nees": p.nees(x, t, model.motion),
                     "error": float(np.sqrt(p.position_error(x, t, model.motion))), "other_mode": p.other_mode})
    return {**out, "posteriors": rows}


def summary(rows: list[dict[str, Any]]) -> str:
    """Part 1: one Markdown table line per scenario."""
    q = chi2.ppf(LEVEL, 4)
    lines = [f"| scenario | posteriors | least ESS | 1st percentile | median | below {LOW:,.0f} | another optimum "
             "| exact NEES > q: runs, their least ESS |", "|---|---|---|---|---|---|---|---|"]
    for s, scen in enumerate(fd.paper_scenarios()):
        rs = [row for row in rows if row["s"] == s]
        if not rs:
            continue
        ess = np.concatenate([row["ess"] for row in rs])
        missed = [row for row in rs if row["nees"] > q]
        least = f"{min(min(row['ess']) for row in missed):,.0f}" if missed else "—"
        lines.append(f"| {scen.name} | {ess.size} | {ess.min():,.0f} | {np.percentile(ess, 1):,.0f} | "
                     f"{np.median(ess):,.0f} | {int(np.sum(ess < LOW))} | {sum(row['other_mode'] for row in rs)} | "
                     f"{len(missed)}, {least} |")
    return "\n".join(lines)


def summary_3d(draws: list[dict[str, Any]]) -> str:
    """Part 2: one line per draw."""
    lines = ["| draw | pairs | ESS at " + ", ".join(f"{t:g}" for t in TIMES_3D) + " s | truth's NEES (least, most) "
             "| mean's error (m, least, most) |", "|---|---|---|---|---|"]
    for d in draws:
        if "posteriors" not in d:
            lines.append(f"| {d['draw']} | {d['pairs']} | refused | | |")
            continue
        ps = d["posteriors"]
        nees, err = [p["nees"] for p in ps] or [np.nan], [p["error"] for p in ps] or [np.nan]
        ess = {p["t"]: p["ess"] for p in ps}
        lines.append(f"| {d['draw']} | {d['pairs']} | "
                     + ", ".join(f"{ess[t]:,.0f}" if t in ess else "collapsed" for t in TIMES_3D)
                     + f" | {min(nees):.3g}, {max(nees):.3g} | {min(err):,.0f}, {max(err):,.0f} |")
    return "\n".join(lines)


def main() -> None:
    args, rows = each_run(one_run, "exact_sampler_ess.py", "exact_sampler_ess",
                          options={"--draws-3d": {"type": int, "default": 10,
                                                  "help": "random 3-D layouts to sample too (part 2)"}})
    text = (f"Part 1: {args.runs} runs per scenario, seed {args.seed}; q = {chi2.ppf(LEVEL, 4):.2f} "
            f"(the chi-square(4) {100 * LEVEL:g} % quantile), ESS target {ESS_TARGET:,}\n\n" + summary(rows) + "\n")
    draws: list[dict[str, Any]] = []
    if args.draws_3d > 0:
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            draws = list(pool.map(one_draw, range(args.draws_3d)))
        text += f"\nPart 2: the first {args.draws_3d} random 3-D layouts (60 s)\n\n" + summary_3d(draws) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"ess_seed{args.seed}.md").write_text(text)
    (args.out / f"ess_seed{args.seed}.json").write_text(json.dumps({"paper": rows, "3-D": draws}, indent=1))
    print(text)


if __name__ == "__main__":
    main()
