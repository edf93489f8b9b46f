"""Where the smoother told of calibration offsets is ``ok`` and far off: is the truth in the declared model's tail?

For chosen runs of ``studies/doppler_offsets.py`` (the same recordings: pair
offsets :math:`b_p \\sim N(0, \\sigma_b^2)`, :math:`\\sigma_b` =
:data:`doppler_offsets.BIAS_SIGMA`, drawn with the recording's seed) the
smoother runs with ``bias_sigma`` declared, as the study's smoother does, and
the joint objective of track and offsets — the model the user declared: data,
motion, the zone's weak prior and wall, and the offsets' prior
:math:`\\sum_p (b_p/\\sigma_b)^2` (:mod:`fgdoppler.estimators.smoother_offsets`)
— is read at the truth with the drawn offsets and at its mode (Levenberg–Marquardt
from the reported track with zero offsets, and from the truth).  Printed per run:
the verdict and final NEES (4 dimensions, the reported covariance), the drawn
offsets in units of :math:`\\sigma_b`, the objective at the truth and its
offsets' part, the objective at the modes, and how probable a draw of the offsets
at least as far out is (:math:`\\chi^2_P` tail of the offsets' part).  Where the
objective at the truth exceeds the mode's by about its offsets' part, the data
fit the truth and the reported track alike and only the offsets' prior tells
them apart: the draw is in the prior's tail, and no test of the declared model
can prefer the truth.

Run: ``python studies/offsets_tail.py [--seed 2026] [--run SCENARIO RUN ...]`` (default the three runs that
the offsets-aware wall and mirror tests of 2026-12-03 turned ``ok`` beyond the χ²₄ 99.9 % level: scenario 1
run 6, scenario 1 run 52, scenario 4 run 47; scenario numbers index ``fgdoppler.paper_scenarios()``; about
a minute).  docs/concepts.md ("Calibration offsets") quotes it.
"""

from __future__ import annotations

import argparse

import _common  # noqa: F401  (the repository root on the path)
import numpy as np
from doppler_offsets import BIAS_SIGMA, offset_recording
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.estimators.smoother_offsets import _JointProblem, bias_sigmas
from fgdoppler.estimators.smoother_solve import _levenberg_marquardt

#: The runs (scenario, run) the study looks at by default.
RUNS = ((1, 6), (1, 52), (4, 47))


def one_run(s: int, r: int, seed: int) -> str:
    """One run's line of the table."""
    scen, sim, model, init = offset_recording(s, r, seed)
    m = sim.measurements
    settings = fd.SmootherSettings(bias_sigma=BIAS_SIGMA)
    res = fd.run_estimator("smoother", m, model, init, settings)
    e = res.primary
    err = e.states[-1] - sim.truth.at(e.times[-1:])[0]
    nees = float(err @ np.linalg.solve(e.covariances[-1], err))
    problem = _JointProblem(model, m, settings, e.times, bias_sigmas(BIAS_SIGMA, model.observation.n_channels))
    drawn = np.asarray(scen.bias)
    truth = np.concatenate([sim.truth.at(e.times).ravel(), drawn])
    prior_part = float(np.sum((drawn / BIAS_SIGMA) ** 2))
    modes = []
    for start in (np.concatenate([e.states.ravel(), np.zeros(problem.p)]), truth):
        z, *_ = _levenberg_marquardt(problem, start, settings.max_iterations)
        modes.append(problem.data_cost(z))
    at_truth = problem.data_cost(truth)
    return (f"| {scen.name} | {r} | {res.status} | {nees:.1f} | "
            f"{', '.join(f'{b / BIAS_SIGMA:+.2f}' for b in drawn)} | {at_truth:.2f} | {prior_part:.2f} | "
            f"{modes[0]:.2f} | {modes[1]:.2f} | {at_truth - min(modes):.2f} | "
            f"{chi2.sf(prior_part, drawn.size):.3f} |")


def main() -> None:
    p = argparse.ArgumentParser(prog="python studies/offsets_tail.py")
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--run", nargs=2, type=int, action="append", metavar=("SCENARIO", "RUN"),
                   help="a run to look at (repeatable); default the three of the module docstring")
    args = p.parse_args()
    runs = [tuple(r) for r in args.run] if args.run else list(RUNS)
    print("| scenario | run | verdict | final NEES | offsets (sigma_b) | objective at truth | its offsets' part "
          "| mode from the track | mode from the truth | truth - mode | P(offsets' part >= drawn) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for s, r in runs:
        print(one_run(s, r, args.seed))


if __name__ == "__main__":
    main()
