"""The EKF's wider gate on layouts of one's own: does keeping a measurement where the Gaussian fits ever cost?

``EKFSettings.gaussian_gate_probability`` keeps a measurement between the
0.9999 gate and the wider one when the prediction's sag ratio is below 1
(docs/concepts.md, "The gate where the Gaussian fits"); its limit was set
on the paper's two geometries.  This study runs the EKF with it (the
default) and with one gate (``gaussian_gate_probability=None``) on the same
recordings of the random-layout studies: ``random_layouts.py`` (2-D, two to
four pairs anywhere in an 80 km square) and ``random_layouts_3d.py`` (an
aircraft over ground sensors), draws ``--first`` to ``--first + --draws - 1``
of each.  Both filters take the default smoother of the recording as their
verdict's reference.  Printed per geometry kind: the draws whose track
changed, the mean and median change of the position RMSE over t >= 5 s
(m), the measurements kept by the wider gate, and the wrong-and-``ok``
count of each (wrong: final position farther from the truth than three
standard deviations along the covariance's major axis, as in those
studies); then every changed draw.

Run: ``python studies/wider_gate_layouts.py [--draws 60] [--first 0] [--out DIR]`` (about 6 minutes per 60 draws
on 2 cores).
"""

from __future__ import annotations

from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
import random_layouts
import random_layouts_3d
from random_layouts import recorded, row, saved

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: The two variants compared: the default, and the one gate of before.
VARIANTS: dict[str, fd.EKFSettings] = {"wider": fd.EKFSettings(),
                                       "one gate": fd.EKFSettings(gaussian_gate_probability=None)}
#: Start of the time average of the position error (s), as in the accuracy benchmark.
T_RMSE = 5.0


def _measured(r: fd.TrackResult, truth: fd.Trajectory) -> list[Any]:
    """:func:`random_layouts.row` with the RMSE over ``t >= T_RMSE`` and the count of measurements kept."""
    e = r.primary
    k = e.states.shape[1] // 2
    late = e.times >= T_RMSE
    err = e.states[late, :k] - truth.at(e.times[late])[:, :k]
    rmse = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    kept = sum("measurement kept" in ev.message for ev in r.events)
    return [*row(r, truth), round(rmse, 2), kept]


@one_blas_thread
def one(k: int, first: float = 0.0) -> dict[str, Any]:
    i = k + int(first)
    out: dict[str, Any] = {"draw": i}
    for kind, study in (("2-D", random_layouts), ("3-D", random_layouts_3d)):
        record, sim, init = recorded(i, *study.draw(i))
        if init is None:
            out[kind] = record
            continue
        m, g, truth = sim.measurements, sim.scenario.geometry, sim.truth
        reference = fd.run_estimator("smoother", m, g, init)
        record["rows"] = {label: _measured(fd.run_estimator("ekf", m, g, init, settings, reference=reference), truth)
                          for label, settings in VARIANTS.items()}
        out[kind] = record
    return out


def _summary(rows: list[dict[str, Any]], kind: str) -> None:
    """Print one geometry kind's comparison (rows: the draws that ran)."""
    new, old = ([r["rows"][label] for r in rows] for label in VARIANTS)
    d = np.array([a[4] - b[4] for a, b in zip(new, old, strict=True)])
    changed = [r for r, a, b in zip(rows, new, old, strict=True) if a[:5] != b[:5]]
    print(f"{kind}: {len(rows)} draws, {len(changed)} changed; RMSE change (wider - one gate) mean {d.mean():+.1f} m, "
          f"median {np.median(d):+.2f} m, worst {d.max():+.1f} m, best {d.min():+.1f} m; "
          f"measurements kept {sum(a[5] for a in new)}; wrong and ok: wider {sum(a[3] for a in new)}, "
          f"one gate {sum(b[3] for b in old)}")
    for r in changed:
        a, b = r["rows"]["wider"], r["rows"]["one gate"]
        print(f"  draw {r['draw']} ({r['pairs']} pairs): RMSE {b[4]:,.0f} -> {a[4]:,.0f} m, final error "
              f"{b[1]:,.0f} -> {a[1]:,.0f} m, status {b[0]} -> {a[0]}, kept {a[5]}")


def main() -> None:
    a, results = _common.each_count(one, __doc__.splitlines()[0], "draws", 60, {"first": 0.0})
    for kind in ("2-D", "3-D"):
        name = f"wider_gate_layouts_{kind.lower().replace('-', '')}.json"
        _summary(saved([r[kind] for r in results], a.out, name, "the EKF with the wider gate and with one gate"), kind)
        print(f"  wrote {a.out / name}")


if __name__ == "__main__":
    main()
