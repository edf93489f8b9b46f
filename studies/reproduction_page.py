"""Rebuild docs/reproduction.md (and its figures in docs/img) from a `fgdoppler reproduce` output folder.

Run: fgdoppler reproduce --runs 100 --out output/reproduce && python studies/reproduction_page.py output/reproduce

With ``--accuracy DIR`` (default ``output/bench_accuracy``) the
page also marks which goals of the accuracy issue hold, from the Markdown
tables ``accuracy_seed<N>.md`` that ``python -m benchmarks.bench_accuracy``
writes there (one per seed).
"""

import argparse
import re
import shutil
from pathlib import Path

SCENARIO_COLUMNS = {"case a, start 5 km": "a-5", "case a, start 25 km": "a-25", "case a, start 45 km": "a-45",
                    "case b, start 5 km": "b-5", "case b, start 25 km": "b-25", "case b, start 45 km": "b-45"}

FIGURES = ("fig10_rmse_case_a.png", "fig11_rmse_case_b.png", "fig5_map_group2.png", "fig8_slices.png", "lag_sweep.png",
           "altitude.png")


def section(text: str, start: str, end: str) -> str:
    return text[text.index(start):text.index(end)].strip()


def altitude_part(rep: str) -> str:
    """The 3-D altitude study's section of the page (text, table and figure)."""
    body = section(rep, "## Beyond the paper", "![altitude study]").split("\n", 1)[1].strip()
    return f"""
## Beyond the paper: the scenarios at altitude (3-D)

{body}

![altitude study](img/altitude.png)

What it means for a system designer: the paper's four sensors lie within
1 km of one line, and a target rotated about that line gives the same
Doppler, so in 3-D the data alone leave its across-track position and height
undetermined (bounds of hundreds of kilometres; at 0 km the information is
singular).  Every estimator is then held by the zone's weak prior, errs by
kilometres, and the smoother's verdict says so (`doubtful`: its likelihood
bends far beyond any Gaussian).  The paper's 2-D model, run on the same
recordings, does far better horizontally at low altitude and degrades as
the altitude grows: a Doppler-only system that must see aircraft needs
sensors off the line (a receiver across the baseline or on high ground), or
a 2-D model with its altitude error budgeted.
"""


def goal_rows(table: str) -> dict[tuple[str, str], str]:
    """``{(goal, scenario column): "yes" | "no"}`` from the goal table of one ``accuracy_seed<N>.md``."""
    out: dict[tuple[str, str], str] = {}
    lines = table.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("| goal | scenario | met |"))
    for line in lines[head + 2:]:
        if not line.startswith("|"):
            break
        goal, scenario, met = (c.strip() for c in line.strip("|").split("|")[:3])
        out[(goal, SCENARIO_COLUMNS[scenario])] = "yes" if met == "yes" else "no"
    return out


def clause_two(table: str) -> tuple[int, int, int | None]:
    """Goal 4's second clause over the scenarios of one ``accuracy_seed<N>.md``: (inconsistent runs, of them
    flagged, of the misses those where the exact posterior is inconsistent too — ``None`` where the benchmark ran
    with ``--no-exact``)."""
    bad = flagged = tail = 0
    missed = said = False  # a scenario with misses; one that counts the shared ones (only with the exact posterior)
    for line in table.splitlines():
        if not line.startswith("| 4: inconsistent runs' verdicts not ok |"):
            continue
        numbers, evidence = (c.strip() for c in line.strip().strip("|").split("|")[3:5])
        counted = re.match(r"(\d+) of (\d+) flagged", numbers)
        if counted:
            flagged, bad = flagged + int(counted.group(1)), bad + int(counted.group(2))
        shared = re.search(r"(\d+) of them in runs where the exact posterior", evidence)
        tail += int(shared.group(1)) if shared else 0
        missed, said = missed or evidence.startswith("judged ok"), said or shared is not None
    return bad, flagged, None if missed and not said else tail


def accuracy_part(folder: Path) -> str:
    """The goals of the accuracy issue per scenario and seed, from the accuracy benchmark's tables in ``folder``."""
    tables = sorted(folder.glob("accuracy_seed*.md"), key=lambda f: int(f.stem.removeprefix("accuracy_seed")))
    if not tables:
        return ""
    seeds = [f.stem.removeprefix("accuracy_seed") for f in tables]
    per_seed = [goal_rows(f.read_text()) for f in tables]
    goals = sorted(dict.fromkeys(g for rows in per_seed for g, _ in rows), key=lambda g: g.split(":")[0])
    cols = list(SCENARIO_COLUMNS.values())
    lines = [f"| goal (seed {' / '.join(seeds)}) | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for goal in goals:
        cells = [" / ".join(rows.get((goal, c), "–") for rows in per_seed) for c in cols]
        lines.append(f"| {goal} | " + " | ".join(cells) + " |")
    counts = [(seed, *clause_two(f.read_text())) for seed, f in zip(seeds, tables, strict=True)]
    misses = "; ".join(f"seed {seed}: flagged {flagged} of {bad}" + (
        f", and {tail} of the {bad - flagged} it misses are runs where the exact posterior is inconsistent too"
        if tail is not None else " (run with --no-exact: which misses the exact posterior shares is not counted "
        "here; docs/concepts.md, \"What the exact posterior says\")") for seed, bad, flagged, tail in counts)
    first = tables[0].read_text().splitlines()[0]
    runs = re.match(r"(\d+) runs per scenario", first)
    return f"""
## The accuracy issue's goals

Which goals of the accuracy issue hold, scenario by scenario, on the
accuracy benchmark ({runs.group(1) if runs else "?"} runs per scenario, seeds {" and ".join(seeds)}):
fgdoppler's estimators against FilterPy's EKF, UKF and URTS and Stone Soup's
EKF + RTS and UKF + URTS started from fgdoppler's initiation, and against the
issue's particle filter (its published 10-run RMSEs; its run time is that
of Stone Soup's particle filter timed in the same benchmark run, so that
goal 2's tenth is a ratio measured on one machine).  "no" is the goal as
the issue states it, on these runs; the benchmark's own tables give the
numbers and, beside each comparison, whether the runs resolve it (paired
bootstrap) or it is a tie, and docs/concepts.md ("How sure is each
comparison?") discusses every "no".

{chr(10).join(lines)}

Goal 4's second clause asks the verdict to flag every run whose own NEES,
averaged over t >= 10 s, exceeds the chi-square(4) 99.9 % quantile ({misses}).
The exact posterior is the benchmark's reference row: the posterior that
every estimator approximates (the truth's exactly constant-velocity
motion, the zone, the weak prior) given the same data, importance-sampled
and read as a mean and a covariance, as every estimator's answer is.  Where even it is inconsistent the truth lies in the tail of a curved
posterior that no mean and covariance enclose, while the data fit the
truth as well as the likelihood promises (docs/concepts.md, "What the
exact posterior says").

Rebuild with `python -m benchmarks.bench_accuracy --runs 100 --seed 2026`
and `--seed 7` (extras `bench`, `stonesoup`; with `--no-exact`, which leaves
out the exact posterior's row, 16–17 minutes each on 2 cores on 2026-12-06),
then this page with `--accuracy output/bench_accuracy`.
"""


def main(folder: Path, docs: Path = Path("docs"), accuracy: Path | None = None) -> None:
    rep = (folder / "report.md").read_text()
    wall = re.search(r"Wall time ([\d.]+) s \(observability ([\d.]+) s, Monte Carlo ([\d.]+) s\)", rep)
    runs = re.search(r"Runs per scenario: (\d+)", rep)
    if wall is None or runs is None:
        raise SystemExit(f"{folder / 'report.md'} lacks its wall time or runs per scenario: not a reproduce report")
    (docs / "img").mkdir(parents=True, exist_ok=True)
    for f in FIGURES:
        if (folder / f).exists():
            shutil.copy(folder / f, docs / "img" / f)
    altitude = "## Beyond the paper" in rep
    end_obs = "## Beyond the paper" if altitude else "## Files"
    page = f"""# Reproducing the paper

Everything on this page was produced by one command on a 2-core machine
(Python 3.11, GTSAM 4.3.0), {runs.group(1)} Monte Carlo runs per scenario, seed 2026:

```bash
fgdoppler reproduce --runs {runs.group(1)} --workers 2 --out output/reproduce
python studies/reproduction_page.py output/reproduce   # rebuilds this page
```

Wall time inside the run: {wall.group(1)} s (observability {wall.group(2)} s, Monte Carlo {wall.group(3)} s, the
rest: the lag sweep, the 3-D altitude study, bounds and figures).  `fgdoppler reproduce --quick` (5 runs, the altitude study at 1 run per cell) takes 149 s (measured on a fresh clone, 2026-11-24, with `map`; 190 s on 2026-11-28 on an idle 2-core machine, 4 min 49 s on a fresh clone beside other work).

## The paper's claims

{section(rep, "| artefact | claim | reproduced |", "## Table 2")}

## Table 2: observability versus speed

The paper does not say which measurement batch its observability study used.
Two synchronous samples per pair, 1 s apart (evaluation points at y = +2 km),
reproduces it; our values beside the paper's:

{section(rep, "Sampling: 2 samples", "## Observability figures")}

![group 2 map](img/fig5_map_group2.png)
![Fig. 8](img/fig8_slices.png)

## Figs. 10–11: position RMSE

Time-averaged position RMSE after the initiation window (m); `grid`, `ils`,
`lm` are the initiation estimates extrapolated at constant velocity, `CRLB`
the deterministic constant-velocity bounds (filtering: data up to *t*;
smoothing: all data).

{section(rep, "| scenario | grid | ils", "Section 5 of the paper finds")}

{section(rep, "Section 5 of the paper finds", "## Smoother vs EKF")}

![Fig. 10](img/fig10_rmse_case_a.png)
![Fig. 11](img/fig11_rmse_case_b.png)

## Smoother versus EKF

{section(rep, "## Smoother vs EKF vs CRLB", "## NEES").replace("## Smoother vs EKF vs CRLB", "").strip() or "The full smoother is no worse than the EKF at any time after the initiation window in any scenario."}

## Consistency

Run-averaged NEES over t >= 10 s, then per run.  In the well-observed
scenarios (case a at 45 km, case b at 5 km) every estimator is consistent
or slightly conservative.  Elsewhere every estimator is consistent in the
median run.  The filters' covariances (EKF, iSAM2, the fixed-lag smoother's
lagged ones) are widened to posterior samples of the data they have read
and to that posterior linearised about the offline smoother's track
(`fgdoppler.estimators.spread`, docs/concepts.md "The linearised enclosure
at every estimate"): few of their runs average above 20, and their
averages in the poorly observed scenarios lie at or below the band's lower
edge (conservative).  The offline smoother, whose covariance is sampled
from the posterior where the likelihood is not Gaussian about its
estimate, stays in or near the band everywhere; the particle estimator and
its mode (`map`) are raised in case b at 45 km by a few runs (2-3 in 100
above 20) where the likelihood is a curved valley.

{section(rep, "## NEES", "![figures 10-11]").replace("## NEES ", "Run-averaged NEES ").strip()}

## Lag sweep

{section(rep, "## Lag sweep", "![lag sweep]").replace("## Lag sweep", "").strip()}

![lag sweep](img/lag_sweep.png)

## Observability report per scenario

{section(rep, "| scenario | O(x0) |", end_obs)}
{altitude_part(rep) if altitude else ""}{accuracy_part(accuracy) if accuracy is not None else ""}"""
    (docs / "reproduction.md").write_text(page)
    print(f"wrote {docs / 'reproduction.md'}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", type=Path, default=Path("output/reproduce"),
                        help="a `fgdoppler reproduce` output folder (default output/reproduce)")
    parser.add_argument("--accuracy", type=Path, default=None,
                        help="the accuracy benchmark's output folder (default output/bench_accuracy)")
    args = parser.parse_args()
    accuracy = args.accuracy if args.accuracy is not None else Path("output/bench_accuracy")
    if not list(accuracy.glob("accuracy_seed*.md")):
        print(f"no accuracy_seed*.md in {accuracy}: the page leaves out the accuracy goals "
              "(run python -m benchmarks.bench_accuracy first)")
    main(args.folder, accuracy=accuracy)
