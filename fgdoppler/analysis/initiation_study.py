"""The initiation study: χ² pass rate, accuracy against the window CRLB, and time, per scenario.

For each scenario and seeded run the paper's window (the first 10 measurements
of each pair) is initiated; the study reports how many runs pass the 95 % χ²
test, the position RMSE at the window end, the deterministic CRLB of the
window (all its measurements) at the same time, and the wall time.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fgdoppler.analysis.bounds import crlb_deterministic
from fgdoppler.estimators.initiation import InitiationSettings, initiate
from fgdoppler.simulation import Scenario, paper_scenarios, simulate

__all__ = ["InitiationRow", "initiation_study"]


@dataclass(frozen=True, kw_only=True)
class InitiationRow:
    """Result for one scenario."""

    scenario: str
    runs: int
    passes_chi2: int
    ambiguous: int
    pos_rmse_end: float
    crlb_pos_end: float
    median_time: float
    p90_time: float

    def to_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return dict(self.__dict__)


def initiation_study(
    *,
    runs: int = 100,
    seed: int = 4,
    scenarios: tuple[Scenario, ...] | None = None,
    settings: InitiationSettings | None = None,
    per_pair: int = 10,
) -> list[InitiationRow]:
    """Run the study (serially, so the times are per single initiation)."""
    scenarios = scenarios or tuple(paper_scenarios())
    settings = settings or InitiationSettings()
    rows = []
    seqs = np.random.SeedSequence(seed).spawn(len(scenarios) * runs)
    for s, scen in enumerate(scenarios):
        errs, times, passes, amb = [], [], 0, 0
        crlb = None
        for r in range(runs):
            sim = simulate(scen, np.random.default_rng(seqs[s * runs + r]))
            w = sim.measurements.first_per_pair(per_pair)
            init = initiate(w, scen.geometry, replace(settings))
            truth_end = sim.truth.at([init.t_end])[0]
            errs.append(float(np.sum((init.x_end[:2] - truth_end[:2]) ** 2)))
            times.append(init.wall_time)
            passes += int(init.passes_chi2)
            amb += int(init.ambiguous)
            if crlb is None:
                P = crlb_deterministic(scen.geometry, scen.x0, w, [init.t_end], smoothing=True)[0]
                crlb = float(np.sqrt(P[0, 0] + P[1, 1]))
        rows.append(InitiationRow(
            scenario=scen.name, runs=runs, passes_chi2=passes, ambiguous=amb,
            pos_rmse_end=float(np.sqrt(np.mean(errs))), crlb_pos_end=float(crlb if crlb is not None else np.nan),
            median_time=float(np.median(times)), p90_time=float(np.percentile(times, 90)),
        ))
    return rows
