"""The values iSAM2's relinearisation check reads: joint marginal, marginal per state, full back-substitution.

At every update :class:`~fgdoppler.estimators.isam2.ISAM2Tracker` reads the
estimates of its recent states (10 by default) to decide which Doppler
factors to relinearise, and every tenth update those of the 120 before them
too (the history check).  Since 2026-12-06 the recent states' values are
the back-substitution of their joint marginal, one ``jointBayesNet``
eliminated by QR (:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker._means`);
before, one ``marginalFactor`` per state (:func:`_per_state_means`, kept
here as the reference).  Later that day the history check began to read iSAM2's
full back-substitution instead
(:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker._solved`), O(N) in the
states held but cheaper than the joint marginal of 130 states.  Measured on
the long benchmark's slow three-pair recording (``benchmarks.bench_long``),
cut to ``DURATION`` seconds, through the registry as ``fgdoppler track``
runs it (seven hypotheses), without the verdict:

- per check: every way on the same tracker state, at every check of one run,
  median time of the recent window's checks and of the history checks,
  and, at every ``COMPARE_EVERY``-th check, each way's largest difference from
  iSAM2's full back-substitution in marginal standard deviations;
- whole runs: the estimator's CPU time with the tracker's own values, with
  the joint marginal for every check, and with a marginal per state for
  every check, ``REPEATS`` times alternately in this process, and the largest
  differences between the filtered tracks in their standard deviations.

Run alone: ``python -m benchmarks --only check`` (about 3 minutes).
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
def _values(recent: Means, history: Means) -> Iterator[None]:
    """The tracker's check values read by ``recent`` (its ``_means``) and ``history`` (its ``_solved``)."""
    saved = ISAM2Tracker._means, ISAM2Tracker._solved
    ISAM2Tracker._means, ISAM2Tracker._solved = recent, history  # type: ignore[method-assign,assignment]
    try:
        yield
    finally:
        ISAM2Tracker._means, ISAM2Tracker._solved = saved  # type: ignore[method-assign]


def _problem() -> tuple[fd.Measurements, fd.Geometry, fd.Initiation]:
    sim = fd.simulate(replace(recording("slow"), duration=DURATION), np.random.default_rng(0))
    g = sim.scenario.geometry
    return sim.measurements, g, fd.initiate(sim.measurements.first_per_pair(10), g)


def _per_check(m: fd.Measurements, g: fd.Geometry, init: fd.Initiation) -> dict[str, list[float]]:
    """Every way at every check of one run (the tracker's own values drive it): times (s) and deviations (sd)."""
    joint, solved = ISAM2Tracker._means, ISAM2Tracker._solved
    ways: dict[str, Means] = {"joint": joint, "per-state": _per_state_means, "full": solved}
    out: dict[str, list[float]] = {f"{w} {kind}": [] for w in ways for kind in ("recent", "history", "sd")}
    count = [0]

    def timed(kind: str, own: Means) -> Means:
        def read(tracker: ISAM2Tracker, ks: list[int]) -> NDArray[np.float64]:
            got = {}
            for w, fn in ways.items():
                t0 = time.process_time()
                got[w] = fn(tracker, ks)
                out[f"{w} {kind}"].append(time.process_time() - t0)
            count[0] += 1
            if count[0] % COMPARE_EVERY == 0:
                sd = np.array([np.sqrt(np.diag(tracker.isam.marginalCovariance(X(k)))) for k in ks])
                for w in ways:
                    out[f"{w} sd"].append(float(np.max(np.abs(got[w] - got["full"]) / sd)))
            return own(tracker, ks)
        return read

    with _values(timed("recent", joint), timed("history", solved)):
        fd.run_estimator("isam2", m, g, init, verify=False)
    return out


def _whole(m: fd.Measurements, g: fd.Geometry, init: fd.Initiation, recent: Means,
           history: Means) -> tuple[float, fd.Estimates]:
    with _values(recent, history):
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
    sd = {w: max(checks[f"{w} sd"]) for w in ("joint", "per-state")}
    joint, solved = ISAM2Tracker._means, ISAM2Tracker._solved
    variants = (("tracker", joint, solved), ("joint", joint, joint),
                ("per-state", _per_state_means, _per_state_means))
    seconds: dict[str, list[float]] = {name: [] for name, _, _ in variants}
    tracks: dict[str, fd.Estimates] = {}
    for r in range(REPEATS):
        for name, recent, history in variants if r % 2 == 0 else variants[::-1]:
            sec, tracks[name] = _whole(m, g, init, recent, history)
            seconds[name].append(sec)
    cpu = {k: float(np.median(v)) for k, v in seconds.items()}
    joint_vs_per_state = _largest_sd_difference(tracks["per-state"], tracks["joint"])
    tracker_vs_joint = _largest_sd_difference(tracks["joint"], tracks["tracker"])
    n_recent, n_history = len(checks["joint recent"]), len(checks["joint history"])
    where = f"slow three-pair recording, first {DURATION:.0f} s, registry, no verdict"
    return [
        Row(name=f"iSAM2's check values, one joint marginal vs a marginal per state ({where}; median of {n_recent} "
                 f"checks of the recent states / {n_history} history checks; largest difference from the full "
                 f"back-substitution {sd['joint']:.1e} vs {sd['per-state']:.1e} standard deviations)",
            value=(f"{med['joint recent']:.3f} / {med['joint history']:.2f} ms vs "
                   f"{med['per-state recent']:.3f} / {med['per-state history']:.2f} ms CPU"),
            ratio=med["joint recent"] / med["per-state recent"], target="≤ 0.6×, no less exact",
            met=med["joint recent"] <= 0.6 * med["per-state recent"] and sd["joint"] <= sd["per-state"]),
        Row(name=f"iSAM2's history check, the full back-substitution vs the joint marginal ({where}; median of "
                 f"{n_history} checks; the recent states alone: {med['full recent']:.3f} vs "
                 f"{med['joint recent']:.3f} ms)",
            value=f"{med['full history']:.2f} vs {med['joint history']:.2f} ms CPU",
            ratio=med["full history"] / med["joint history"], target="≤ 0.6×",
            met=med["full history"] <= 0.6 * med["joint history"]),
        Row(name=f"iSAM2 run, joint marginal vs per-state check values for every check ({where}; {REPEATS} runs "
                 f"each alternately; filtered tracks {joint_vs_per_state:.1e} standard deviations apart)",
            value=f"{cpu['joint']:.1f} vs {cpu['per-state']:.1f} s CPU", ratio=cpu["joint"] / cpu["per-state"],
            target="≤ 0.9×, the same track (< 1e-6 sd)", met=cpu["joint"] <= 0.9 * cpu["per-state"]
            and joint_vs_per_state < 1e-6),
        Row(name=f"iSAM2 run, the tracker's check values (history checks by the full back-substitution) vs the "
                 f"joint marginal for every check ({where}; {REPEATS} runs each alternately; filtered tracks "
                 f"{tracker_vs_joint:.1e} standard deviations apart)",
            value=f"{cpu['tracker']:.1f} vs {cpu['joint']:.1f} s CPU", ratio=cpu["tracker"] / cpu["joint"],
            target="≤ 0.95×, the same track (< 1e-6 sd)", met=cpu["tracker"] <= 0.95 * cpu["joint"]
            and tracker_vs_joint < 1e-6),
    ]


if __name__ == "__main__":
    for row in run():
        print(f"{row.name}: {row.value} -> {'met' if row.met else 'NOT MET'}", flush=True)
