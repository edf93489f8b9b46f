"""How often each verdict comes out, and how often an ``ok`` answer is nonetheless wrong, from a Monte Carlo file.

Reads the ``.npz`` that ``fgdoppler montecarlo`` writes and prints, per
estimator over all its scenarios and runs: the counts of ``ok``,
``doubtful`` and ``failed``; the ``ok`` runs whose final NEES (at the
recording's last time) exceeds the 99.9 % quantile of
:math:`\\chi^2_n` (n the state dimension); the ``ok`` runs whose final
position error exceeds 2 km; and all runs whose final error exceeds 20 km.
Then the ``ok`` count per scenario.  docs/concepts.md ("How often each
verdict comes out") quotes it for::

    fgdoppler montecarlo --runs 60 --seed 99 --estimators lm ekf isam2 fixed-lag smoother --out output/verdicts/mc99

Run: ``python studies/verdict_counts.py output/verdicts/mc99.npz`` (a second; the Monte Carlo run above
takes about 15 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import _common  # noqa: F401  (the repository root on the path, a non-interactive backend)
import numpy as np
from scipy.stats import chi2

from fgdoppler.analysis.montecarlo import MonteCarloResult

#: Final NEES beyond this quantile of chi-square(n) counts as an overconfident ``ok``.
NEES_LEVEL = 0.999


def _final(x: np.ndarray) -> np.ndarray:
    """Each run's value at the recording's last time (NaN where it has none there)."""
    return x[:, -1]


def table(mc: MonteCarloResult) -> str:
    """The Markdown table of verdict counts and wrong ``ok`` answers, and the ``ok`` counts per scenario."""
    limit = chi2.ppf(NEES_LEVEL, mc.state_dim)
    lines = ["| estimator | ok | doubtful | failed | ok, yet final NEES > chi2 99.9 % | ok, final error > 2 km "
             "| final error > 20 km |", "|---|---|---|---|---|---|---|"]
    for e in mc.estimators:
        v = np.concatenate([mc.verdicts[s][e] for s in range(len(mc.scenario_names))])
        err = np.sqrt(np.concatenate([_final(mc.pos_se[s][e]) for s in range(len(mc.scenario_names))]))
        nees = np.concatenate([_final(mc.nees[s][e]) for s in range(len(mc.scenario_names))])
        ok = v == "ok"
        with np.errstate(invalid="ignore"):
            lines.append(f"| {e} | {ok.sum()} | {(v == 'doubtful').sum()} | {(v == 'failed').sum()} | "
                         f"{(ok & (nees > limit)).sum()} | {(ok & (err > 2e3)).sum()} | {(err > 20e3).sum()} |")
    lines += ["", "| estimator | " + " | ".join(mc.scenario_names) + " |",
              "|---|" + "---|" * len(mc.scenario_names)]
    for e in mc.estimators:
        lines.append(f"| {e} | " + " | ".join(f"{int(np.sum(mc.verdicts[s][e] == 'ok'))} of {mc.runs}"
                                             for s in range(len(mc.scenario_names))) + " |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("npz", type=Path, help="the .npz written by fgdoppler montecarlo --out")
    args = p.parse_args()
    mc = MonteCarloResult.load(args.npz)
    print(f"{mc.runs} runs per scenario, seed {mc.seed}")
    print(table(mc))


if __name__ == "__main__":
    main()
