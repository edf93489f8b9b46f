"""The values iSAM2's relinearisation check reads: one joint marginal against a marginal per state.

At every update :class:`~fgdoppler.estimators.isam2.ISAM2Tracker` reads the
estimates of its recent states (10 by default, and every tenth update the 120
before them too) to decide which Doppler factors to relinearise
(:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker._means`).  Since 2026-12-06
it reads them from the checked states' joint marginal, one
``jointBayesNet`` eliminated by QR; before, from one ``marginalFactor`` per
state (:func:`_per_state_means`, kept here as the reference).  Measured on
the long benchmark's slow three-pair recording (``benchmarks.bench_long``),
cut to ``DURATION`` seconds, through the registry as ``fgdoppler track``
runs it (seven hypotheses), without the verdict:

- per check: both ways on the same tracker state, at every check of one run,
  median time of the recent window's checks and of the older states' checks,
  and, at every ``COMPARE_EVERY``-th check, each way's largest difference from
  iSAM2's full back-substitution in marginal standard deviations;
- whole run: the estimator's CPU time with each, ``REPEATS`` times
  alternately in this process, and the largest difference between the two
  filtered tracks in their standard deviations.

Run alone: ``python -m benchmarks --only check`` (about 2 minutes).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace

import gtsam
import numpy as np
from numpy.typing import NDArray

import fgdoppler as fd
from benchmarks._common import Row
from benchmarks.bench_long import recording
from fgdoppler.estimators.isam2 import ISAM2Tracker
from fgdoppler.factors import X

DURATION = 600.0
REPEATS = 2
COMPARE_EVERY = 25
#: The tracker's two kinds of check: the recent window alone, and with the older states it checks every tenth update.
RECENT = 12

Means = Callable[[ISAM2Tracker, list[int]], NDArray[np.float64]]


def _per_state_means(tracker: ISAM2Tracker, ks: list[int]) -> NDArray[np.float64]:
    """The check's values as read before 2026-12-06: each state's own marginal, by QR, solved."""
    conds = [tracker.isam.marginalFactor(X(k), gtsam.EliminateQR) for k in ks]
    R = np.array([c.R() for c in conds])
    d = np.array([c.d() for c in conds])
    theta = np.array([tracker.scans[k].theta for k in ks])
    return theta + np.linalg.solve(R, d[:, :, None])[:, :, 0]


@contextmanager
def _means(fn: Means) -> Iterator[None]:
    saved = ISAM2Tracker._means
    ISAM2Tracker._means = fn  # type: ignore[method-assign,assignment]
    try:
        yield
    finally:
        ISAM2Tracker._means = saved  # type: ignore[method-assign]


def _problem() -> tuple[fd.Measurements, fd.Geometry, fd.Initiation]:
    sim = fd.simulate(replace(recording("slow"), duration=DURATION), np.random.default_rng(0))
    g = sim.scenario.geometry
    return sim.measurements, g, fd.initiate(sim.measurements.first_per_pair(10), g)


def _per_check(m: fd.Measurements, g: fd.Geometry, init: fd.Initiation) -> dict[str, list[float]]:
    """Both ways at every check of one run (the joint values drive it): times (s) and deviations (sd)."""
    joint = ISAM2Tracker._means
    out: dict[str, list[float]] = {k: [] for k in ("joint recent", "per-state recent", "joint older",
                                                     "per-state older", "joint sd", "per-state sd")}
    count = [0]

    def both(tracker: ISAM2Tracker, ks: list[int]) -> NDArray[np.float64]:
        kind = "recent" if len(ks) <= RECENT else "older"
        t0 = time.process_time()
        a = joint(tracker, ks)
        t1 = time.process_time()
        b = _per_state_means(tracker, ks)
        t2 = time.process_time()
        out[f"joint {kind}"].append(t1 - t0)
        out[f"per-state {kind}"].append(t2 - t1)
        count[0] += 1
        if count[0] % COMPARE_EVERY == 0:
            best = tracker.isam.calculateBestEstimate()
            full = np.array([best.atVector(X(k)) for k in ks])
            sd = np.array([np.sqrt(np.diag(tracker.isam.marginalCovariance(X(k)))) for k in ks])
            out["joint sd"].append(float(np.max(np.abs(a - full) / sd)))
            out["per-state sd"].append(float(np.max(np.abs(b - full) / sd)))
        return a

    with _means(both):
        fd.run_estimator("isam2", m, g, init, verify=False)
    return out


def _whole(m: fd.Measurements, g: fd.Geometry, init: fd.Initiation, fn: Means) -> tuple[float, fd.Estimates]:
    with _means(fn):
        t = time.process_time()
        result = fd.run_estimator("isam2", m, g, init, verify=False)
        return time.process_time() - t, result.primary


def _largest_sd_difference(a: fd.Estimates, b: fd.Estimates) -> float:
    assert a.covariances is not None
    sd = np.sqrt(np.diagonal(a.covariances, axis1=1, axis2=2))
    return float(np.max(np.abs(a.states - b.states) / sd))


def run() -> list[Row]:
    m, g, init = _problem()
    checks = _per_check(m, g, init)
    med = {k: 1e3 * float(np.median(v)) for k, v in checks.items() if not k.endswith("sd")}
    joint_sd, per_sd = max(checks["joint sd"]), max(checks["per-state sd"])
    seconds: dict[str, list[float]] = {"joint": [], "per-state": []}
    tracks: dict[str, fd.Estimates] = {}
    for r in range(REPEATS):
        order = (("joint", ISAM2Tracker._means), ("per-state", _per_state_means))
        for name, fn in order if r % 2 == 0 else order[::-1]:
            sec, tracks[name] = _whole(m, g, init, fn)
            seconds[name].append(sec)
    a, b = (float(np.median(seconds[k])) for k in ("joint", "per-state"))
    diff = _largest_sd_difference(tracks["per-state"], tracks["joint"])
    n_recent, n_older = len(checks["joint recent"]), len(checks["joint older"])
    where = f"slow three-pair recording, first {DURATION:.0f} s, registry, no verdict"
    return [
        Row(name=f"iSAM2's check values, one joint marginal vs a marginal per state ({where}; median of {n_recent} "
                 f"checks of the recent states / {n_older} with the older ones; largest difference from the full "
                 f"back-substitution {joint_sd:.1e} vs {per_sd:.1e} standard deviations)",
            value=(f"{med['joint recent']:.3f} / {med['joint older']:.2f} ms vs "
                   f"{med['per-state recent']:.3f} / {med['per-state older']:.2f} ms CPU"),
            ratio=med["joint recent"] / med["per-state recent"], target="≤ 0.6×, no less exact",
            met=med["joint recent"] <= 0.6 * med["per-state recent"] and joint_sd <= per_sd),
        Row(name=f"iSAM2 run, joint vs per-state check values ({where}; {REPEATS} runs each alternately; filtered "
                 f"tracks {diff:.1e} standard deviations apart)",
            value=f"{a:.1f} vs {b:.1f} s CPU", ratio=a / b, target="≤ 0.9×, the same track (< 1e-6 sd)",
            met=a <= 0.9 * b and diff < 1e-6),
    ]


if __name__ == "__main__":
    for row in run():
        print(f"{row.name}: {row.value} -> {'met' if row.met else 'NOT MET'}", flush=True)
