"""Shared helpers for the study scripts: the output folder, a non-interactive backend, the benchmarks importable."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path
from typing import Any

os.environ.setdefault("MPLBACKEND", "Agg")
# A study run as a script sees only its own folder; the repository root makes the benchmarks' recordings
# importable, so a study measures on exactly the benchmark's data instead of a copy of its definition.
_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.append(_ROOT)


def out_dir(default: str) -> Path:
    """The output folder (``--out``, default under the git-ignored ``output/``)."""
    p = argparse.ArgumentParser()
    p.add_argument("--out", type=Path, default=Path("output") / default)
    return p.parse_args().out


def report(artefact: Any) -> None:
    """Print what an artefact produced and its claims."""
    print(artefact.summary)
    for claim, ok in artefact.claims.items():
        print(f"  [{'reproduced' if ok else 'NOT reproduced'}] {claim}")
    for f in artefact.files:
        print(f"  wrote {f}")


def save_table(out: Path, stem: str, text: str, rows: Any) -> None:
    """Write a study's table ``text`` to ``out/stem.md`` and its ``rows`` to ``out/stem.json``, and print the
    table."""
    import json

    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.md").write_text(text)
    (out / f"{stem}.json").write_text(json.dumps(rows, indent=1))
    print(text)


def paper_run(s: int, r: int, seed: int) -> tuple[Any, Any, Any]:
    """Run ``r`` of paper scenario ``s`` as the accuracy benchmark records it: (simulation, model, initiation).

    The recording draws from ``SeedSequence([seed, s, r])``; the initiation
    reads the first 10 measurements per pair (the paper's window).
    """
    import numpy as np

    import fgdoppler as fd

    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    return sim, model, fd.initiate(sim.measurements.first_per_pair(10), model)


def each_run(one_run: Callable[..., Any], prog: str, out: str, *, chunksize: int = 4,
             options: dict[str, dict[str, Any]] | None = None) -> tuple[argparse.Namespace, list[Any]]:
    """Parse ``--runs --seed --workers --out`` and map ``one_run`` over every ``(scenario, run, seed)``.

    ``options`` adds the study's own (flag: ``add_argument`` keywords); their values reach ``one_run`` as
    keywords.  Returns the parsed options and ``one_run``'s results in task order.
    """
    import fgdoppler as fd

    p = argparse.ArgumentParser(prog=f"python studies/{prog}")
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("output") / out)
    for flag, keywords in (options or {}).items():
        p.add_argument(flag, **keywords)
    args = p.parse_args()
    own = {f.lstrip("-").replace("-", "_") for f in options or {}}
    run = partial(one_run, **{k: getattr(args, k) for k in own}) if own else one_run
    tasks = [(s, r, args.seed) for s in range(len(fd.paper_scenarios())) for r in range(args.runs)]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        return args, list(pool.map(run, tasks, chunksize=chunksize))


def each_count(one: Callable[..., Any], description: str, name: str, default: int,
               options: dict[str, float] | None = None) -> tuple[argparse.Namespace, list[Any]]:
    """Parse ``--<name> N --out DIR`` and map ``one`` over ``range(N)`` on up to two processes.

    Each of ``options`` (name: default) is a float option ``--<name>`` (``_`` spelt ``-``), passed to
    ``one`` as a keyword argument.  Returns the parsed options (``DIR`` default ``output/studies``) and
    ``one``'s results in order.
    """
    p = argparse.ArgumentParser(description=description)
    p.add_argument(f"--{name}", type=int, default=default)
    for option, value in (options or {}).items():
        p.add_argument(f"--{option.replace('_', '-')}", dest=option, type=float, default=value)
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    args = p.parse_args()
    task = partial(one, **{option: getattr(args, option) for option in options or {}})
    with ProcessPoolExecutor(max(1, min(2, os.cpu_count() or 1))) as pool:
        return args, list(pool.map(task, range(getattr(args, name))))


def paired_cells(rows: list[dict[str, Any]], keys: list[str]) -> tuple[str, str, str]:
    """One scenario's RMSE, paired-difference and NEES cells of variants run on the same recordings.

    ``rows`` are the scenario's runs, each with the truth times ``row["t"]`` and, for every variant ``k`` of
    ``keys``, the squared position errors ``row[k]["se"]`` and NEES ``row[k]["nees"]`` on that grid (the
    accuracy benchmark's ``_on_grid``).  Returns the time-averaged RMSE over t >= 5 s of each variant
    (" / "-joined), each later variant's paired difference against the first with its 95 % bootstrap
    interval (" | "-joined) and the NEES averaged over runs, then over t >= 10 s (" / "-joined): the
    benchmark's measures.
    """
    import warnings

    import numpy as np

    from benchmarks.bench_accuracy import T_NEES, T_RMSE, mean_after
    from fgdoppler.analysis.metrics import compare_rmse, time_averaged_rmse

    t = np.array(rows[0]["t"])
    se = {k: np.array([row[k]["se"] for row in rows]) for k in keys}
    with warnings.catch_warnings():  # all-NaN columns are expected: no state before the window ends
        warnings.simplefilter("ignore", RuntimeWarning)
        nees = [mean_after(np.nanmean(np.array([row[k]["nees"] for row in rows]), axis=0), t, T_NEES)
                for k in keys]
    return (" / ".join(f"{time_averaged_rmse(se[k], t, t0=T_RMSE):,.0f}" for k in keys),
            " | ".join(str(compare_rmse(se[k], se[keys[0]], t, t0=T_RMSE)) for k in keys[1:]),
            " / ".join(f"{v:.2f}" for v in nees))
