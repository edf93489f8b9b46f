"""In the plane, does the particle estimators' restart test at every checkpoint pay, as ``map``'s does in space?

``MapSettings.check_every`` makes ``map``'s online re-initiation test — a
fresh fit of all the data so far — at every checkpoint in space, where on
the random 3-D layouts it found wrong basins the data leave slowly
(``filters_3d.py``), and only where something calls for it in the plane.
This measures the plane: the random 2-D layouts of ``random_layouts.py``
(two to four pairs in general position, 60 s), ``map`` and ``particle`` each
with the test made only where something calls for it (``check_every=False``)
and at every checkpoint (``True``), paired on the same recordings and
initiations.

Printed per estimator and choice: the RMS and median over draws of each
run's position RMS error over t >= 10 s, the median final error, the
restarts, the median wall time, and for ``True`` the draws whose error and
whose final error fell / rose by more than a metre against ``False``.

Run: python studies/check_every_plane.py [--draws 40] [--out DIR]  (2 min on 2 cores)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from filters_3d import changes, measures
from random_layouts import draw, recorded

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: The particle estimators compared.
NAMES = ("map", "particle")


@one_blas_thread
def one(k: int) -> dict[str, Any]:
    """Draw ``k``: each estimator with the test only where called for and at every checkpoint."""
    out, sim, init = recorded(k, *draw(k), duration=60.0)
    if init is None:
        return out
    g = sim.scenario.geometry
    reference = fd.run_estimator("smoother", sim.measurements, g, init)
    for name in NAMES:
        for every in (False, True):
            settings_of: Callable[..., fd.TrackerSettings] = fd.ESTIMATORS[name].settings
            settings = settings_of(check_every=every)
            res = fd.run_estimator(name, sim.measurements, g, init, settings, reference=reference)
            out[f"{name} {every}"] = measures(res, sim.truth)
    return out


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 40)
    rows = [r for r in all_rows if "map False" in r]
    lines = [f"{len(rows)} draws of random_layouts.py, 60 s each ({len(all_rows) - len(rows)} refused); "
             "errors over t >= 10 s", "",
             "| estimator | check_every | RMS over draws (m) | median (m) | median final (m) | restarts "
             "| median wall (s) | against False: fell / rose, final fell / rose |", "|---|---|---|---|---|---|---|---|"]
    for name in NAMES:
        for every in (False, True):
            v = [r[f"{name} {every}"] for r in rows]
            rmse = np.array([x["rmse"] for x in v])
            paired = changes(v, [r[f"{name} False"] for r in rows]) if every else ""
            lines.append(f"| {name} | {every} | {math.sqrt(np.mean(rmse ** 2)):,.0f} | {np.median(rmse):,.0f} | "
                         f"{np.median([x['final'] for x in v]):,.0f} | {sum(x['restarts'] for x in v)} | "
                         f"{np.median([x['wall'] for x in v]):.2f} | {paired} |")
    _common.save_table(a.out, "check_every_plane", "\n".join(lines) + "\n", all_rows)


if __name__ == "__main__":
    main()
