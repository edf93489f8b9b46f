"""Outliers too many for the initiation window: named from the whole recording (docs/concepts.md, "Outliers too
many for the window").

On each of the accuracy benchmark's recordings of the paper's six scenarios (``--runs`` each, ``--seed``), four of
the initiation window's 20 measurements and two later ones are moved by 20-100 sigma, each of a random sign (a
fifth of the window: more than the tenth that the window's own ``outliers`` finding calls a few).  For each:

* whether the window names them (it should not: too many for it);
* whether the whole recording's check (:func:`fgdoppler.estimators.later_mistakes.later_mistakes`, asked as for a
  track that fails its residual test) names exactly the six;
* the offline smoother's verdict from that initiation: not ``ok``, carrying the finding, and ``track``'s hint
  putting ``--huber`` first (:func:`fgdoppler.cli.track.mistake_hint`);
* the same check on the recording as simulated, told its track misfits: any ``outliers`` finding there is false.

Run: python studies/outliers_in_the_recording.py [--runs 10] [--seed 2026] [--workers 2] [--out DIR]
(2026-12-06, ``--runs 10``: 161 s on 2 cores)
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from _common import each_run, paper_run, save_table

#: A named outlier in an ``outliers`` finding's words: its pair and time.
_NAMED = re.compile(r"pair (\d+) at t = ([\d.e+-]+) s:")


def one_run(task: tuple[int, int, int]) -> dict[str, Any]:
    """One recording: its corrupted version's window, check and smoother, and the check as simulated."""
    import fgdoppler as fd
    from fgdoppler.cli.track import mistake_hint
    from fgdoppler.estimators.later_mistakes import later_mistakes
    from fgdoppler.estimators.verdict import Reason

    s, r, seed = task
    sim, model, clean_init = paper_run(s, r, seed)
    misfit = (Reason(code="fit", status="doubtful", message="the residuals fail the chi-square test"),)
    m = sim.measurements
    rng = np.random.default_rng(np.random.SeedSequence([seed, s, r, 6]))
    window = np.flatnonzero(m._first_mask(10, "n"))  # the rows first_per_pair(10) keeps
    made = np.r_[rng.choice(window, 4, replace=False),
                 rng.choice(np.setdiff1d(np.arange(len(m)), window), 2, replace=False)]
    jump = np.zeros(len(m))
    jump[made] = rng.uniform(20.0, 100.0, made.size) * rng.choice([-1.0, 1.0], made.size)
    bad = fd.Measurements(time=m.time, pair=m.pair, doppler=m.doppler + jump * m.sigma, sigma=m.sigma)
    init = fd.initiate(bad.first_per_pair(10), model)
    found = [x for x in later_mistakes(bad, model, init, misfit) if x.code == "outliers"]
    want = sorted((int(m.pair[i]), float(m.time[i])) for i in made)
    track = fd.run_estimator("smoother", bad, model, init)
    hint = mistake_hint(track.reasons) or ""
    return {"scenario": s, "run": r,
            "window_named": any(x.code == "outliers" and x.status != "ok" for x in init.reasons),
            "named": bool(found),
            "exact": bool(found) and sorted((int(p), float(t)) for p, t in _NAMED.findall(found[0].message)) == want,
            "status": track.status,
            "track_finding": any(x.code == "outliers" and x.status != "ok" for x in track.reasons),
            "huber_hint": "--huber" in hint,
            "false_as_simulated": bool([x for x in later_mistakes(m, model, clean_init, misfit)
                                        if x.code == "outliers"])}


def main() -> None:
    args, rows = each_run(one_run, "outliers_in_the_recording.py", "outliers_in_the_recording")
    lines = [f"Four outliers of 20-100 sigma in the initiation window and two later ({args.runs} runs per scenario, "
             f"seed {args.seed})", "",
             "| scenario | window names them | recording names them (exactly the six) | smoother not ok | "
             "smoother's finding | hint --huber | false finding as simulated |", "|---|---|---|---|---|---|---|"]
    import fgdoppler as fd

    names = [sc.name for sc in fd.paper_scenarios()]
    for s, name in enumerate(names):
        mine = [x for x in rows if x["scenario"] == s]
        n = len(mine)

        def count(key: str, rows: list[dict[str, Any]] = mine) -> int:
            return sum(bool(x[key]) for x in rows)

        lines.append(f"| {name} | {count('window_named')}/{n} | {count('named')}/{n} ({count('exact')}) | "
                     f"{sum(x['status'] != 'ok' for x in mine)}/{n} | {count('track_finding')}/{n} | "
                     f"{count('huber_hint')}/{n} | {count('false_as_simulated')}/{n} |")
    save_table(args.out, "outliers_in_the_recording", "\n".join(lines) + "\n", rows)


if __name__ == "__main__":
    main()
