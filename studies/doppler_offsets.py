"""Uncalibrated Doppler offsets on the paper's scenarios: the trackers with and without ``bias_sigma``.

Every pair of every recording is offset by its own constant
:math:`b_p \\sim N(0, \\sigma_b^2)` (:data:`BIAS_SIGMA`, drawn with the
recording's seed), the declared noise σ unchanged.  Per scenario and
tracker (``--estimators``, default the smoother; also ekf, isam2,
fixed-lag, particle, map): the final position RMSE, its mean and median
final NEES (4 dimensions) without the offsets declared and with
``bias_sigma`` :data:`BIAS_SIGMA`, the ``ok`` counts, the ``ok`` runs whose
final NEES exceeds the 99.9 % quantile of :math:`\\chi^2_4` (confident and
wrong), the CPU time per run and, where the offsets are estimated, the
mean NEES of the estimator's reading of them (``TrackResult.offsets``)
against the drawn ones (one dimension per pair).  The Gaussian trackers'
track is the same either way (only their covariances differ); the particle
estimators integrate the offsets out, and ``smoother-joint`` (the smoother
with ``estimate_offsets``) estimates them with the track, so their track
moves.  docs/concepts.md
("Calibration offsets") quotes it.

The filters run without their ``reference`` check (``verify=False``: the
verdict of their own tests) unless ``--verify`` holds them against one
offline smoother per recording, as ``fgdoppler track`` does; a second
table gives, per scenario and tracker, the answers within the χ²₄ level
that the verdict calls not ``ok`` and the findings behind the verdicts.

Run: ``python studies/doppler_offsets.py [--runs 60] [--seed 2026] [--estimators NAME ...] [--verify] [--workers 2]
[--out DIR]`` (about 6 minutes on 2 cores for 60 runs of the smoother; 41 minutes for the three filters with
``--verify``).
"""

from __future__ import annotations

import json
import time
from collections import Counter
from dataclasses import replace
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: The offsets' standard deviation (m/s), one noise σ of the paper's scenarios.
BIAS_SIGMA = 1.0


#: The trackers that take ``bias_sigma``; ``smoother-joint`` is the smoother estimating the offsets with the
#: track (``estimate_offsets``) where they are declared.
TRACKERS = ("smoother", "smoother-joint", "ekf", "isam2", "fixed-lag", "particle", "map")


def _settings(name: str, bias_sigma: float) -> tuple[str, fd.TrackerSettings]:
    """The registry's name and settings of a study's tracker ``name`` told ``bias_sigma``."""
    if name == "smoother-joint":
        return "smoother", fd.SmootherSettings(bias_sigma=bias_sigma, estimate_offsets=bias_sigma > 0)
    return name, fd.ESTIMATORS[name].settings(bias_sigma=bias_sigma)


def offset_recording(s: int, r: int, seed: int) -> tuple[fd.Scenario, fd.Simulation, fd.TrackingModel,
                                                         fd.Initiation]:
    """Run ``r`` of paper scenario ``s``, every pair offset by its own draw of :data:`BIAS_SIGMA` (drawn first from
    ``SeedSequence([seed, s, r])``, then the recording): the scenario, the recording, the model and the
    initiation on the first 10 measurements per pair."""
    base = fd.paper_scenarios()[s]
    rng = np.random.default_rng(np.random.SeedSequence([seed, s, r]))
    scen = replace(base, bias=tuple(rng.normal(0.0, BIAS_SIGMA, base.geometry.n_pairs)))
    sim = fd.simulate(scen, rng)
    model = fd.TrackingModel.of(scen.geometry)
    return scen, sim, model, fd.initiate(sim.measurements.first_per_pair(10), model)


@one_blas_thread
def one(task: tuple[int, int, int], *, estimators: list[str], verify: bool) -> dict[str, Any]:
    s, r, seed = task
    scen, sim, model, init = offset_recording(s, r, seed)
    m = sim.measurements
    out: dict[str, Any] = {"s": s}
    # One reference smoother per recording and gate, loss and seed, shared as ``run_estimators`` shares it, but
    # made here: that call would time no tracker alone, and cannot run ``smoother`` and ``smoother-joint``
    # together.  Its CPU time is not any tracker's.
    references: dict[fd.SmootherSettings, fd.TrackResult] = {}
    for name in estimators:
        out[name] = {}
        for label, sb in (("without", 0.0), ("with", BIAS_SIGMA)):
            registered, settings = _settings(name, sb)
            reference = None
            if verify:
                key = fd.SmootherSettings.reference_for(settings)
                if key not in references:
                    references[key] = fd.run_estimator("smoother", m, model, init, key)
                reference = references[key]
            cpu = time.process_time()
            res = fd.run_estimator(registered, m, model, init, settings, verify=verify, reference=reference)
            e = res.primary
            d = e.states[-1] - sim.truth.at(e.times[-1:])[0]
            out[name][label] = {"nees": float(d @ np.linalg.solve(e.covariances[-1], d)), "ok": res.status == "ok",
                                "cpu": time.process_time() - cpu, "se": float(d[0] ** 2 + d[1] ** 2),
                                "findings": sorted({f.code for f in res.reasons if f.status != "ok"})}
            if res.offsets is not None:  # the estimator's reading of the offsets, against the drawn ones
                db = res.offsets.values - np.asarray(scen.biases)[res.offsets.pairs]
                out[name][label]["offsets_nees"] = float(db @ np.linalg.solve(res.offsets.covariance, db))
    return out


def main() -> None:
    args, results = _common.each_run(one, "doppler_offsets.py", "doppler_offsets", chunksize=1, options={
        "--estimators": {"nargs": "+", "default": ["smoother"], "choices": TRACKERS,
                         "help": "trackers to run (default: smoother)"},
        "--verify": {"action": "store_true",
                     "help": "hold the filters against the offline smoother, as fgdoppler track does "
                             "(default: not, the filters' verdict without its reference check)"}})
    rows = []
    lines = [f"offsets N(0, {BIAS_SIGMA:g}^2) m/s per pair, {args.runs} runs per scenario, seed {args.seed}",
             "| scenario | estimator | final RMSE (m) without / with | mean NEES without / with | median NEES without / with "
             "| ok without / with | ok, NEES > chi2 99.9 %, without / with | CPU per run (s) without / with "
             "| offsets' mean NEES (where estimated) |",
             "|---|---|---|---|---|---|---|---|---|"]
    limit = chi2.ppf(0.999, 4)
    for s, scen in enumerate(fd.paper_scenarios()):
        for name in args.estimators:
            rs = [x[name] for x in results if x["s"] == s]
            row: dict[str, Any] = {"scenario": scen.name, "estimator": name}
            for label in ("without", "with"):
                ne = [x[label]["nees"] for x in rs]
                row[label] = {"rmse": float(np.sqrt(np.mean([x[label]["se"] for x in rs]))), "mean_nees": float(np.mean(ne)), "median_nees": float(np.median(ne)),
                              "ok": sum(x[label]["ok"] for x in rs),
                              "cpu": float(np.median([x[label]["cpu"] for x in rs])),
                              "ok_beyond": int(sum(x[label]["ok"] and x[label]["nees"] > limit for x in rs)),
                              "not_ok_within": int(sum(not x[label]["ok"] and x[label]["nees"] <= limit for x in rs)),
                              "findings": dict(Counter(c for x in rs for c in x[label]["findings"]))}
            offsets = [x["with"]["offsets_nees"] for x in rs if "offsets_nees" in x["with"]]
            if offsets:
                row["with"]["offsets_mean_nees"] = float(np.mean(offsets))
            rows.append(row)
            w, d = row["without"], row["with"]
            lines.append(f"| {scen.name} | {name} | {w['rmse']:,.0f} / {d['rmse']:,.0f} | {w['mean_nees']:.3g} / {d['mean_nees']:.3g} | "
                         f"{w['median_nees']:.3g} / {d['median_nees']:.3g} | {w['ok']} / {d['ok']} | "
                         f"{w['ok_beyond']} / {d['ok_beyond']} | {w['cpu']:.2f} / {d['cpu']:.2f} | "
                         + (f"{d['offsets_mean_nees']:.3g} |" if "offsets_mean_nees" in d else "– |"))
    lines += ["", "the verdict" + (" (held against the offline smoother)" if args.verify else
                                   " (without the reference check; --verify adds it)"),
              "| scenario | estimator | not ok, NEES within chi2 99.9 %, without / with | findings with (runs) |",
              "|---|---|---|---|"]
    lines += [f"| {r['scenario']} | {r['estimator']} | {r['without']['not_ok_within']} / {r['with']['not_ok_within']} | "
              + (", ".join(f"{c} {n}" for c, n in sorted(r["with"]["findings"].items())) or "–") + " |" for r in rows]
    print("\n".join(lines))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "doppler_offsets.json").write_text(json.dumps({"runs": args.runs, "seed": args.seed,
                                                               "bias_sigma": BIAS_SIGMA, "verify": args.verify,
                                                               "rows": rows}, indent=1))
    print(f"wrote {args.out / 'doppler_offsets.json'}")


if __name__ == "__main__":
    main()
