"""Uncalibrated Doppler offsets on random layouts: the smoother told nothing, considering them, estimating them.

The layouts, targets and 30 s recordings of ``studies/random_layouts.py``
(its ``draw``: two to four pairs anywhere in an 80 km square), every pair
offset by its own :math:`b_p \\sim N(0, \\sigma_b^2)` (:data:`BIAS_SIGMA`,
drawn after the layout with the draw's generator).  The smoother runs from
the default initiation three times: told nothing, with ``bias_sigma``
:data:`BIAS_SIGMA` (the consider covariance), and with ``estimate_offsets``
too.  Printed per variant: the median and RMS final position error, the
median final NEES (4 dimensions), the ``ok`` count, the ``ok`` answers whose
final NEES exceeds the χ²₄ 99.9 % level, the ``ok`` answers that are *wrong*
(farther from the truth than three standard deviations along the
covariance's major axis, as in ``studies/random_layouts.py``), and for the
estimated offsets their NEES per pair against the drawn ones.
docs/concepts.md ("Calibration offsets") quotes it.

Run: ``python studies/offsets_random_layouts.py [--draws 120] [--out DIR]`` (about 6 minutes per 120 draws on
2 cores).
"""

from __future__ import annotations

from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from random_layouts import draw, saved
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: The offsets' standard deviation (m/s), one noise σ.
BIAS_SIGMA = 1.0

#: The smoother's settings per variant.
VARIANTS = {"told nothing": fd.SmootherSettings(),
            "considered": fd.SmootherSettings(bias_sigma=BIAS_SIGMA),
            "estimated": fd.SmootherSettings(bias_sigma=BIAS_SIGMA, estimate_offsets=True)}


@one_blas_thread
def one(i: int) -> dict[str, Any]:
    g, x0, rng = draw(i)
    bias = rng.normal(0.0, BIAS_SIGMA, g.n_pairs)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=30.0, dt=0.5, bias=tuple(bias)), rng)
    out: dict[str, Any] = {"draw": i, "pairs": g.n_pairs, "bias": bias.round(3).tolist()}
    try:
        init = fd.initiate(sim.measurements.first_per_pair(10), g)
    except ValueError as exc:
        return {**out, "refused": str(exc)}
    for label, settings in VARIANTS.items():
        r = fd.run_estimator("smoother", sim.measurements, g, init, settings)
        e = r.primary
        d = e.states[-1] - sim.truth.at(e.times[-1:])[0]
        ok_cov = bool(e.cov_ok[-1])
        sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2])))) if ok_cov else float("nan")
        err = float(np.hypot(*d[:2]))
        row = {"status": str(r.status), "err": err, "sd": sd,
               "nees": float(d @ np.linalg.solve(e.covariances[-1], d)) if ok_cov else float("nan"),
               "wrong_ok": bool(r.status == "ok" and err > 3.0 * sd)}
        if r.offsets is not None:
            db = r.offsets.values - bias[r.offsets.pairs]
            row["offsets_nees_per_pair"] = float(db @ np.linalg.solve(r.offsets.covariance, db)) / db.size
        out[label] = row
    return out


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 120)
    rows = saved(all_rows, a.out, "offsets_random_layouts.json",
                 "median / RMS final error, median NEES, ok, ok beyond chi2 99.9 %, wrong and ok")
    limit = chi2.ppf(0.999, 4)
    for label in VARIANTS:
        v = [r[label] for r in rows]
        err = np.array([x["err"] for x in v])
        ok = np.array([x["status"] == "ok" for x in v])
        nees = np.array([x["nees"] for x in v])
        print(f"  {label:12s} {np.median(err):7,.0f} / {np.sqrt(np.mean(err**2)):8,.0f} m, NEES "
              f"{np.nanmedian(nees):.2f}, ok {ok.sum()}, ok beyond {int(np.sum(ok & (nees > limit)))}, "
              f"wrong and ok {sum(x['wrong_ok'] for x in v)}")
    per_pair = [r["estimated"]["offsets_nees_per_pair"] for r in rows if "offsets_nees_per_pair" in r["estimated"]]
    print(f"  estimated offsets' NEES per pair: mean {np.mean(per_pair):.2f}, median {np.median(per_pair):.2f} "
          f"({len(per_pair)} draws)")
    for r in rows:
        if any(r[label]["wrong_ok"] for label in VARIANTS):
            print(f"  draw {r['draw']} ({r['pairs']} pairs, offsets {r['bias']}): wrong and ok "
                  + ", ".join(label for label in VARIANTS if r[label]["wrong_ok"]))


if __name__ == "__main__":
    main()
