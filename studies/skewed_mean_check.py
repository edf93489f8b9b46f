r"""Where should the offline smoother report its posterior mean instead of its most likely track?

The smoother reports the maximum a posteriori (MAP) track, except where the
curvature probe finds the cost near-quadratic at 3 standard deviations and an
importance-sampling check puts the posterior mean more than
:data:`~fgdoppler.estimators.spread.MEAN_SHIFT_MIN` (squared, whitened by the
Laplace covariance) from the sampled posterior's own mode: there it reports the posterior mean
(:mod:`fgdoppler.estimators.spread`, "Skewed valleys").  This study measures
that rule on the accuracy benchmark's recordings (the paper's six scenarios,
``--runs`` per scenario, ``--seed``), per scenario:

* how many runs the probe samples (a curved valley: the MAP stands with a
  sampled covariance) and how many report the mean;
* the range of the check's squared shift :math:`w = \mathbf d^\top\mathbf P_0^{-1}\mathbf d`
  over the runs the probe leaves alone (the same draws as the smoother's:
  4,096 from :math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)`, weighted and
  resampled, seed 0; :math:`\mathbf d` their mean less the sampled posterior's mode);
* the position RMSE over t >= 5 s of the MAP track
  (``SmootherSettings(posterior_mean=False)``), of the default smoother, and
  of the sample mean reported in *every* run (the smoother's own sampler,
  4,096 samples and 20 Metropolis moves about the MAP start, the mean carried
  by the constant-velocity model) — the alternative the rule was chosen
  against — with the paired differences against the MAP track.

Run: python studies/skewed_mean_check.py [--runs 100] [--seed 2026] [--workers 2] [--out DIR]
(about 5 min per seed on 2 cores)
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from _common import each_run, paper_run

import fgdoppler as fd
from fgdoppler.analysis.metrics import compare_rmse
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators import spread
from fgdoppler.estimators.curvature import probe_rises

T_RMSE = 5.0


def _squared_errors(sim: fd.Simulation, e: fd.Estimates, motion: fd.ConstantVelocity,
                    shift: np.ndarray | None = None) -> np.ndarray:
    """Squared position error at the truth's times (the estimate at the nearest time, shifted by ``F(t - t0) shift``)."""
    k = np.argmin(np.abs(e.times[None, :] - sim.truth.times[:, None]), axis=1)
    x = e.states[k]
    if shift is not None:
        x = x + motion.propagate(shift, e.times[k] - e.times[0])
    return np.sum((sim.truth.states[:, :2] - x[:, :2]) ** 2, axis=1)


@one_blas_thread
def one_run(args: tuple[int, int, int]) -> dict[str, Any]:
    """The probe, the check's shift and the three tracks' squared errors for one run."""
    s, r, seed = args
    sim, model, init = paper_run(s, r, seed)
    m = sim.measurements
    mode = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(posterior_mean=False), verify=False)
    default = fd.run_estimator("smoother", m, model, init, verify=False)
    e = mode.primary
    x0, P0 = e.states[0], e.covariances[0]
    if any(x.code == "nonlinear" for x in mode.reasons):  # sampled: P0 is no longer the Laplace covariance
        laplace = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(sampled_covariance=False),
                                   verify=False).primary
        P0 = laplace.covariances[0]
    P0 = 0.5 * (P0 + P0.T)
    info = np.linalg.inv(P0)
    post, data = spread._posterior(m, model, float(e.times[0]), None, 0, spread.SAMPLES)

    def cost(x: np.ndarray) -> float:
        return float(-2.0 * post.loglik(x[None], data.t, data.pair, data.z, data.sigma)[0])

    lo, hi, quad, _ = probe_rises(cost, x0, P0, spread._information(model, data, x0, None, info))
    rng = np.random.default_rng(0)
    post.sample_from([(x0, P0)], spread.SAMPLES, 0, rng, tempered=False)
    d = post.x.mean(axis=0) - post.mode(x0)
    post.move(spread.MOVES, rng)
    everywhere = post.x.mean(axis=0) - x0
    return {"s": s, "r": r, "ratio": min(lo, hi) / quad, "w": float(d @ info @ d),
            "mean_reported": any("posterior mean of" in x.message for x in default.reasons),
            "se_map": _squared_errors(sim, e, model.motion).tolist(),
            "se_default": _squared_errors(sim, default.primary, model.motion).tolist(),
            "se_everywhere": _squared_errors(sim, e, model.motion, everywhere).tolist(), "t": sim.truth.times.tolist()}


def summary(rows: list[dict[str, Any]]) -> str:
    """One Markdown table line per scenario."""
    lines = ["| scenario | probe samples | mean reported | w where the probe does not sample: min-max "
             "| RMSE MAP / default / mean everywhere (m) | default - MAP | mean everywhere - MAP |",
             "|---|---|---|---|---|---|---|"]
    for s, scen in enumerate(fd.paper_scenarios()):
        rs = [row for row in rows if row["s"] == s]
        if not rs:
            continue
        ratio = np.array([row["ratio"] for row in rs])
        sampled = (ratio < 1.0 / spread.SAMPLING_LIMIT) | (ratio > spread.SAMPLING_LIMIT)
        w = np.array([row["w"] for row in rs])[~sampled]
        t = np.array(rs[0]["t"])
        se = {k: np.array([row[f"se_{k}"] for row in rs]) for k in ("map", "default", "everywhere")}
        rmse = " / ".join(f"{np.sqrt(np.nanmean(se[k][:, t >= T_RMSE])):,.0f}" for k in se)
        lines.append(
            f"| {scen.name} | {int(sampled.sum())} | {sum(row['mean_reported'] for row in rs)} | "
            + (f"{w.min():.3f}-{w.max():.3f}" if w.size else "—") + f" | {rmse} | "
            + f"{compare_rmse(se['default'], se['map'], t, t0=T_RMSE)} | "
            + f"{compare_rmse(se['everywhere'], se['map'], t, t0=T_RMSE)} |")
    return "\n".join(lines)


def main() -> None:
    args, rows = each_run(one_run, "skewed_mean_check.py", "skewed_mean")
    text = (f"{args.runs} runs per scenario, seed {args.seed}; the check's limit w > {spread.MEAN_SHIFT_MIN:g}\n\n"
            + summary(rows) + "\n")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"skewed_mean_seed{args.seed}.md").write_text(text)
    (args.out / f"skewed_mean_seed{args.seed}.json").write_text(json.dumps(rows))
    print(text)


if __name__ == "__main__":
    main()
