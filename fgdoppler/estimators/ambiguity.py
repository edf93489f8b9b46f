"""Ambiguous initiations: follow every hypothesis and let the later data decide.

Near-collinear sensors admit a mirror-image trajectory and other distant
solutions of equal window cost.  :func:`hypotheses` turns an ambiguous
:class:`~fgdoppler.estimators.initiation.Initiation` into one unambiguous
initiation per solution; :func:`resolve` runs an estimator from each and
reports one track:

* EKF, iSAM2, fixed-lag ("likelihood"): an EKF per hypothesis accumulates
  the predictive log-likelihood of every measurement; each *filtered*
  estimate comes from the hypothesis leading at that time (causal), the
  smoothed or lagged estimates from the hypothesis leading at the end;
* smoother ("cost"): the hypothesis with the lowest final cost.

:attr:`TrackResult.hypothesis <fgdoppler.estimators.results.TrackResult>`
records which hypothesis was reported when.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fgdoppler.estimators.ekf import run_ekf
from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.settings import EKFSettings, TrackerSettings
from fgdoppler.estimators.verdict import Event, Reason
from fgdoppler.measurements import Measurements
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, prefixed

__all__ = ["Resolution", "hypotheses", "resolve"]

Resolution = Literal["likelihood", "cost"]
Runner = Callable[..., TrackResult]
"""``run(measurements, model, init, settings, *, progress=None) -> TrackResult``."""


def hypotheses(init: Initiation) -> list[Initiation]:
    """The initiation and one unambiguous copy per alternative (best first).

    Each copy starts from the alternative's state and covariance at the
    window start, propagated to the window end.  Alternatives without a
    determinate covariance are skipped.  A copy's ``objective`` is its data
    cost (the regularisers are not evaluated for alternatives).
    """
    kept = tuple(r for r in init.reasons if r.code != "ambiguous")
    out = [replace(init, alternatives=(), reasons=kept)]
    F = ConstantVelocity.F(init.t_end - init.t_start)
    for a in init.alternatives:
        if a.covariance is None:
            continue
        out.append(replace(
            init, x_start=a.state, x_end=F @ a.state, P_start=a.covariance, P_end=F @ a.covariance @ F.T,
            cost=a.cost, objective=a.cost, passes_chi2=a.passes_chi2, alternatives=(),
            reasons=tuple(r for r in kept if r.code not in ("covariance", "boundary")),
            events=(*init.events, Event(time=init.t_start, message="hypothesis from an ambiguous initiation")),
        ))
    return out


def resolve(run: Runner, resolution: Resolution, measurements: Measurements, model: TrackingModel,
            hyps: list[Initiation], settings: TrackerSettings, progress: Progress | None = None) -> TrackResult:
    """Run ``run`` from every hypothesis and report one track (module docstring).

    ``progress`` sees each run's tasks prefixed with ``"hypothesis i/n"``.
    """
    t_begin = time.perf_counter()
    n = len(hyps)
    results = [run(measurements, model, h, settings, progress=prefixed(progress, f"hypothesis {i + 1}/{n}"))
               for i, h in enumerate(hyps)]
    note = f"ambiguous initiation: {len(hyps)} hypotheses run"
    if resolution == "cost":
        costs = np.array([np.inf if r.cost is None else r.cost for r in results])
        best = int(np.argmin(costs))
        r = results[best]
        event = Event(time=float(r.primary.times[-1]), message=f"{note}; hypothesis {best} has the lowest cost")
        return replace(r, hypothesis=np.full(len(r.primary), best), events=(*r.events, event),
                       reasons=(*r.reasons, *_competing(costs, results, best)),
                       wall_time=time.perf_counter() - t_begin)
    # an estimator that reports its own predictive likelihood (the EKF) is ranked by it
    ekf_settings = EKFSettings(gate_probability=settings.gate_probability, huber_k=settings.huber_k)
    ekfs = results if results[0].log_likelihood.size else [
        run_ekf(measurements, model, h, ekf_settings, progress=prefixed(progress, f"ranking {i + 1}/{n}"))
        for i, h in enumerate(hyps)]
    L = np.array([e.log_likelihood for e in ekfs])
    t_ekf = ekfs[0].primary.times

    def leaders(times: NDArray[np.float64]) -> NDArray[np.intp]:
        idx = np.clip(np.searchsorted(t_ekf, times, side="right") - 1, 0, t_ekf.size - 1)
        return np.argmax(L[:, idx], axis=0)

    final = int(np.argmax(L[:, -1]))
    stitched = []
    for est in results[0].estimates:
        choice = leaders(est.times) if est.kind == "filtered" else np.full(len(est), final)
        parts = [results[h].estimate(est.kind) for h in choice]
        stitched.append(Estimates(
            kind=est.kind, times=est.times,
            states=np.array([p.states[i] for i, p in enumerate(parts)]),
            covariances=np.array([p.covariances[i] for i, p in enumerate(parts)]),
            cov_ok=np.array([p.cov_ok[i] for i, p in enumerate(parts)], dtype=bool),
        ))
    primary = stitched[0]
    hyp = leaders(primary.times) if primary.kind == "filtered" else np.full(len(primary), final)
    event = Event(time=float(t_ekf[-1]), message=f"{note}; hypothesis {final} leads at the end")
    return replace(results[final], estimates=tuple(stitched), hypothesis=np.asarray(hyp, dtype=np.int64),
                   events=(*results[final].events, event),
                   reasons=(*results[final].reasons, *_competing(-2.0 * L[:, -1], results, final)),
                   wall_time=time.perf_counter() - t_begin)


#: Two hypotheses closer than this in cost (χ²₁ at 95 %) cannot be told apart by the data.
COMPETING = float(chi2.ppf(0.95, 1))


def _distinct(a: TrackResult, b: TrackResult) -> bool:
    """Two tracks end at different places: farther apart than 50 m and three of ``a``'s standard deviations."""
    d = b.primary.states[-1, :2] - a.primary.states[-1, :2]
    P = a.primary.covariances[-1, :2, :2]
    sd = float(np.sqrt(np.max(np.linalg.eigvalsh(P)))) if a.primary.cov_ok[-1] else 0.0
    return bool(np.linalg.norm(d) > max(50.0, 3.0 * sd))


def _competing(costs: NDArray[np.float64], results: list[TrackResult], best: int) -> tuple[Reason, ...]:
    """A ``competing`` finding if a distinct solution explains the data about as well as the one reported."""
    others = [h for h in range(len(results))
              if h != best and np.isfinite(costs[h]) and _distinct(results[best], results[h])]
    if not others:
        return (Reason(code="competing", status="ok", message=(
            f"{len(results)} hypotheses from an ambiguous initiation all converge to the track reported")),)
    second = min(others, key=lambda h: costs[h])
    margin = float(costs[second] - costs[best])
    apart = float(np.linalg.norm(results[second].primary.states[-1, :2] - results[best].primary.states[-1, :2]))
    if margin >= COMPETING:
        return (Reason(code="competing", status="ok", message=(
            f"{len(results)} hypotheses from an ambiguous initiation; the data prefer the one reported by "
            f"{margin:.1f} in cost (> {COMPETING:.2f}) over one ending {apart / 1e3:.1f} km away")),)
    return (Reason(code="competing", status="doubtful", message=(
        f"a competing solution explains the data about as well (cost higher by only {margin:.2f} < {COMPETING:.2f}) "
        f"and ends {apart / 1e3:.1f} km away: the data cannot tell them apart")),)
