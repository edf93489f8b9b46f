r"""How many particles does ``map`` need in space?  Paired on the random 3-D layouts.

The plane's count (``studies/map_particles.py``: 2,048 tie 4,096 on the
paper's scenarios) need not hold for a state of six unknowns.  On the draws
of ``random_layouts_3d.py`` (``--draws``, recorded for ``--duration``
seconds; every draw's own initiation) each draw is tracked by
``MapSettings(n_particles=n)`` for every ``n`` of ``--particles`` (the
first is the one the others are compared with), each with its verdict
against one shared reference smoother.  Errors and NEES over t >= 10 s as
``filters_3d.py`` measures them (:func:`filters_3d.measures`).

Printed per count: the RMS over draws and the median of each run's position
RMS error, the draws closer and farther than with the first count by more
than a metre, the median final error, the median NEES and the runs beyond
the χ²₆ 99.9 % quantile (22.5), the ``ok`` runs and of them those beyond
it, the median CPU time; then the median error in the draws whose smoother
is itself consistent (NEES within that quantile).

Run: python studies/map_particles_3d.py [--particles 2048 4096 8192 16384] [--draws 40] [--duration 60] [--out DIR]
(about 4 min on 2 cores with the defaults; ``--draws 60 --duration 30 --particles 2048 8192`` 2.5 min)
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from filters_3d import measures
from random_layouts import recorded
from random_layouts_3d import draw
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: The χ²₆ 99.9 % quantile of a run's NEES averaged over t >= 10 s, as ``filters_3d.py`` reads it.
LIMIT = float(chi2.ppf(0.999, 6))


@one_blas_thread
def one_draw(k: int, *, particles: list[int], duration: float) -> dict[str, Any] | None:
    """The smoother's and ``map``'s measures with each particle count on draw ``k``; ``None`` if refused."""
    _, sim, init = recorded(k, *draw(k), duration=duration)
    if init is None:
        return None
    g = sim.scenario.geometry
    reference = fd.run_estimator("smoother", sim.measurements, g, init)
    out: dict[str, Any] = {"k": k, "smoother": measures(reference, sim.truth)}
    for n in particles:
        cpu = time.process_time()
        res = fd.run_estimator("map", sim.measurements, g, init, fd.MapSettings(n_particles=n), reference=reference)
        out[str(n)] = {**measures(res, sim.truth), "cpu": time.process_time() - cpu}
    return out


def table(rows: list[dict[str, Any]], particles: list[int]) -> list[str]:
    """One Markdown line per particle count, and the consistent-smoother medians."""
    def col(n: int, key: str) -> np.ndarray:
        return np.array([r[str(n)][key] for r in rows], dtype=float)

    first = col(particles[0], "rmse")
    lines = ["| particles | RMS over draws (m) | median (m) | closer / farther | median final (m) | median NEES | "
             "NEES > 22.5 | `ok` (and beyond) | median CPU (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for n in particles:
        e, nees = col(n, "rmse"), col(n, "nees")
        ok = np.array([r[str(n)]["status"] == "ok" for r in rows])
        paired = "—" if n == particles[0] else f"{int(np.sum(e < first - 1))} / {int(np.sum(e > first + 1))}"
        lines.append(f"| {n:,} | {np.sqrt(np.mean(e ** 2)):,.0f} | {np.median(e):,.0f} | {paired} | "
                     f"{np.median(col(n, 'final')):,.0f} | {np.median(nees):.0f} | {int(np.sum(nees > LIMIT))} | "
                     f"{int(ok.sum())} ({int(np.sum(ok & (nees > LIMIT)))}) | {np.median(col(n, 'cpu')):.2f} |")
    good = np.array([r["smoother"]["nees"] <= LIMIT for r in rows])
    medians = ", ".join(f"{n:,}: {np.median(col(n, 'rmse')[good]):,.0f} m" for n in particles)
    return [*lines, "", f"Draws whose smoother is consistent: {int(good.sum())}; their median error: {medians}."]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--particles", type=int, nargs="+", default=[2048, 4096, 8192, 16384])
    p.add_argument("--draws", type=int, default=40)
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    with ProcessPoolExecutor(2) as pool:
        found = pool.map(partial(one_draw, particles=a.particles, duration=a.duration), range(a.draws))
        rows = [r for r in found if r is not None]
    lines = [f"`map` on {len(rows)} random 3-D draws ({a.duration:g} s), paired against {a.particles[0]:,} particles:",
             "", *table(rows, a.particles)]
    _common.save_table(a.out, "map_particles_3d", "\n".join(lines) + "\n", rows)


if __name__ == "__main__":
    main()
