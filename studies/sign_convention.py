r"""Data written with the opposite sign convention: does the ``sign`` finding say so, and only then?

A Doppler shift in Hz is positive for a closing target; fgdoppler's
``doppler`` column is the bistatic range rate, negative for one (docs/data-formats.md).  A file
converted without the minus sign — for every pair, or for one receiver whose software differs — is
the most likely user error this study knows of.  Per recording, three versions of the data: as
simulated, every pair's Doppler negated, pair 0's alone negated.  For each: the initiation's
``sign`` finding (:func:`fgdoppler.estimators.initiation.sign_reasons`) and which pairs it names,
and (``--track 1``, the default) the offline smoother's verdict from that initiation, with its final
position error against its own sigma along the major axis.

Recordings: the accuracy benchmark's runs of the paper's six scenarios (``--runs`` each, ``--seed``)
and as many random layouts of ``studies/random_layouts.py`` (draw ``100 s + r``: two to four
pairs anywhere, the target anywhere in the default zone).

Run: python studies/sign_convention.py [--runs 10] [--seed 2026] [--track 1] [--workers 2] [--out DIR]
(``--runs 10``: about 6 min on 2 cores; ``--track 0``: the initiations alone, seconds)
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from _common import each_run, paper_run
from random_layouts import draw, one_blas_thread, recorded

import fgdoppler as fd

#: The versions of each recording: name -> pairs whose Doppler is negated (``None``: every pair).
VERSIONS: dict[str, list[int] | None] = {"as given": [], "every pair negated": None, "pair 0 negated": [0]}


def _version(m: fd.Measurements, flipped: list[int] | None) -> fd.Measurements:
    sign = -np.ones(len(m)) if flipped is None else np.where(np.isin(m.pair, flipped), -1.0, 1.0)
    return fd.Measurements(time=m.time, pair=m.pair, doppler=sign * m.doppler, sigma=m.sigma)


def _judged(sim: fd.Simulation, model: fd.TrackingModel, track: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, flipped in VERSIONS.items():
        m = _version(sim.measurements, flipped)
        init = fd.initiate(m.first_per_pair(10), model)
        found = [r.message for r in init.reasons if r.code == "sign"]
        row: dict[str, Any] = {"finding": bool(found),
                               "names": found[0].split(" negated")[0].split("Doppler of ")[-1] if found else ""}
        if track:
            r = fd.run_estimator("smoother", m, model, init)
            e = r.primary
            k = e.states.shape[1] // 2
            err = float(np.linalg.norm(e.states[-1, :k] - sim.truth.at(e.times[-1:])[0][:k]))
            sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:k, :k])))) if e.cov_ok[-1] else np.nan
            row.update(status=str(r.status), error=round(err, 1), sigma=round(sd, 1),
                       sign_in_verdict=any(x.code == "initiation-sign" for x in r.reasons))
        out[name] = row
    return out


@one_blas_thread
def one(task: tuple[int, int, int], track: int = 1) -> dict[str, Any]:
    s, r, seed = task
    sim, model, _ = paper_run(s, r, seed)
    out: dict[str, Any] = {"scenario": s, "run": r, "paper": _judged(sim, model, track)}
    i = 100 * s + r
    record, layout_sim, init = recorded(i, *draw(i))
    if init is not None:
        out["layout"] = _judged(layout_sim, fd.TrackingModel.of(layout_sim.scenario.geometry), track)
    else:
        out["layout refused"] = record.get("refused", "")
    return out


def _table(rows: list[dict[str, Any]], where: str, track: bool) -> list[str]:
    lines = [f"### {where}", "", "| data | recordings | sign finding | names the negated pairs | "
             + ("smoother ok | ok and beyond 3 sigma |" if track else ""),
             "|---|---|---|---|" + ("---|---|" if track else "")]
    for name, flipped in VERSIONS.items():
        got = [r[where][name] for r in rows if where in r]
        want = "every pair" if flipped is None else ", ".join(f"pair {k}" for k in flipped)
        right = sum(g["names"] == want for g in got) if flipped != [] else 0
        line = f"| {name} | {len(got)} | {sum(g['finding'] for g in got)} | {right if flipped != [] else '—'} |"
        if track:
            ok = [g for g in got if g["status"] == "ok"]
            wrong = sum(g["error"] > 3.0 * g["sigma"] for g in ok)
            line += f" {len(ok)} | {wrong} |"
        lines.append(line)
    return [*lines, ""]


def main() -> None:
    args, rows = each_run(one, "sign_convention.py", "studies",
                          options={"--track": {"type": int, "default": 1}})
    text = "\n".join([f"{args.runs} runs per paper scenario and as many random layouts, seed {args.seed}", "",
                      *_table(rows, "paper", bool(args.track)), *_table(rows, "layout", bool(args.track))])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "sign_convention.md").write_text(text)
    (args.out / "sign_convention.json").write_text(json.dumps(rows, indent=1))
    print(text)


if __name__ == "__main__":
    main()
