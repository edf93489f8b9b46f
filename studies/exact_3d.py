"""In 3-D over ground sensors, how far from the truth is the exact posterior's mean, and how far are ours?

Every online estimator is kilometres off on the random 3-D layouts of
``random_layouts_3d.py``, mostly in height (``filters_3d.py``).  Whether that
is what the data allow needs the exact posterior there, which the importance
sampler of :mod:`benchmarks._exact` cannot give (``exact_sampler_ess.py``
part 2).  This samples it with the tempered sampler
(:func:`benchmarks._tempered.tempered_posterior`: from the zone's prior,
two independent bridges whose moments must agree), given the data up to
every 10 s of each draw's 60 s, and compares at those times:

- the exact posterior's mean (the minimum-mean-square-error estimate) against the truth:
  its position error, height error, and the truth's NEES (6 dimensions)
  under the exact mean and covariance;
- ``ekf`` and ``map`` (filtered, the data up to that time) and the offline
  smoother (all 60 s, against the exact posterior given all 60 s), their
  position and height errors there, against the same references.

Printed: per draw and time whether the sampler's bridges agreed, and over
the readable posteriors the median errors side by side (paired on the same
draws and times) and the mean of the truth's NEES under the exact
posterior (6 when the truth is a draw from the posterior: here the truths'
heights, 0.5-4.5 km, are not drawn from the zone's prior, which spans the
whole altitude band).

Run: python studies/exact_3d.py [--draws 20] [--out DIR]  (22 min on 2 cores)
"""

from __future__ import annotations

from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from random_layouts import recorded
from random_layouts_3d import draw

import fgdoppler as fd
from benchmarks._tempered import tempered_posterior
from fgdoppler.analysis.workers import one_blas_thread

#: Times (s) given the data up to which the posterior is sampled.
TIMES = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0)
#: The online estimators compared (filtered at each time), and the offline one (at the last time).
FILTERS = ("ekf", "map")
DURATION = 60.0


def _at(res: fd.TrackResult, t: float) -> np.ndarray:
    """The estimate of ``res`` at time ``t`` (its nearest estimate time)."""
    e = res.primary
    return e.states[int(np.argmin(np.abs(e.times - t)))]


@one_blas_thread
def one(k: int) -> dict[str, Any]:
    """Draw ``k``: the exact posterior at each of :data:`TIMES` and the estimators' errors there."""
    out, sim, init = recorded(k, *draw(k), duration=DURATION)
    if init is None:
        return out
    g = sim.scenario.geometry
    model = fd.TrackingModel.of(g)
    reference = fd.run_estimator("smoother", sim.measurements, g, init)
    runs = {name: fd.run_estimator(name, sim.measurements, g, init, reference=reference) for name in FILTERS}
    last = float(np.max(sim.measurements.time))
    rows = []
    for i, t in enumerate(TIMES):
        t = min(t, last)
        truth = sim.truth.at(np.array([t]))[0]
        row: dict[str, Any] = {"t": t}
        ours = {name: _at(res, t) for name, res in runs.items()}
        if t == last:
            ours["smoother"] = _at(reference, t)
        for name, x in ours.items():
            row[name] = {"error": float(np.linalg.norm(x[:3] - truth[:3])), "height": float(abs(x[2] - truth[2]))}
        try:
            post = tempered_posterior(sim.measurements, model, t, np.random.default_rng([k, i]))
        except ValueError as err:
            row["refused"] = str(err)
        else:
            mean = model.motion.F(t - post.t0) @ post.mean
            cov = model.motion.F(t - post.t0) @ post.covariance @ model.motion.F(t - post.t0).T
            row["exact"] = {"error": float(np.linalg.norm(mean[:3] - truth[:3])),
                            "height": float(abs(mean[2] - truth[2])), "sd_height": float(np.sqrt(cov[2, 2])),
                            "nees": post.nees(truth, t, model.motion)}
        rows.append(row)
    return {**out, "times": rows}


def summary(draws: list[dict[str, Any]]) -> str:
    """The readable posteriors' errors side by side, and the refusals."""
    rows = [(d["draw"], r) for d in draws for r in d.get("times", [])]
    readable = [(k, r) for k, r in rows if "exact" in r]
    lines = [f"{len(draws)} draws, {len(rows)} posteriors, {len(readable)} readable (the bridges agreed); "
             f"refused: " + (", ".join(f"draw {k} at {r['t']:g} s" for k, r in rows if "refused" in r) or "none"), "",
             "| given the data up to | estimator | posteriors | median error: exact / ours (m) "
             "| median height error: exact / ours (m) | ours nearer the truth | exact: median height sd (m), "
             "mean NEES |", "|---|---|---|---|---|---|---|"]
    for label, names, pick in (("each time", FILTERS, lambda r: True),
                               (f"{DURATION:g} s (offline)", ("smoother",), lambda r: "smoother" in r)):
        for name in names:
            sel = [r for _, r in readable if pick(r) and name in r]
            if not sel:
                continue
            ex = np.array([r["exact"]["error"] for r in sel])
            ou = np.array([r[name]["error"] for r in sel])
            eh = np.array([r["exact"]["height"] for r in sel])
            oh = np.array([r[name]["height"] for r in sel])
            lines.append(f"| {label} | {name} | {len(sel)} | {np.median(ex):,.0f} / {np.median(ou):,.0f} | "
                         f"{np.median(eh):,.0f} / {np.median(oh):,.0f} | {int(np.sum(ou < ex))} | "
                         f"{np.median([r['exact']['sd_height'] for r in sel]):,.0f}, "
                         f"{np.mean([r['exact']['nees'] for r in sel]):.1f} |")
    lines += ["", "| draw | pairs | t (s) | exact error (m) | height error / sd (m) | NEES | "
              + " | ".join(f"{n} error (m)" for n in (*FILTERS, "smoother")) + " |",
              "|---|---|---|---|---|---|" + "---|" * (len(FILTERS) + 1)]
    for d in draws:
        for r in d.get("times", []):
            cells = " | ".join(f"{r[n]['error']:,.0f}" if n in r else "" for n in (*FILTERS, "smoother"))
            if "exact" in r:
                e = r["exact"]
                lines.append(f"| {d['draw']} | {d['pairs']} | {r['t']:g} | {e['error']:,.0f} | "
                             f"{e['height']:,.0f} / {e['sd_height']:,.0f} | {e['nees']:.1f} | {cells} |")
            else:
                lines.append(f"| {d['draw']} | {d['pairs']} | {r['t']:g} | refused | | | {cells} |")
    return "\n".join(lines)


def main() -> None:
    a, draws = _common.each_count(one, __doc__.splitlines()[0], "draws", 20)
    _common.save_table(a.out, "exact_3d", summary(draws) + "\n", draws)


if __name__ == "__main__":
    main()
