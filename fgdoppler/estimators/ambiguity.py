r"""Many hypotheses, one track: Gaussian sums over the initiation's solutions or its window posterior.

Near-collinear sensors admit a mirror-image trajectory and other distant
solutions of equal window cost, and a poorly observed window's likelihood
is a curved valley that no single Gaussian describes.  The Gaussian
trackers (EKF, iSAM2, fixed-lag) therefore start from several hypotheses
(:func:`~fgdoppler.estimators.registry.run_estimator` chooses them):

* :func:`posterior_hypotheses` — when the initiation's covariance
  misdescribes its likelihood (a ``nonlinear`` finding) or its curvature
  probe strays beyond
  :attr:`~fgdoppler.estimators.settings.GaussianSumSettings.split_ratio`
  (a Kalman filter linearises across the whole covariance): the window's
  posterior is sampled and split into at most
  :attr:`~fgdoppler.estimators.settings.GaussianSumSettings.components`
  Gaussian terms, each a short, nearly straight piece of the valley;
* :func:`hypotheses` — when the initiation is ``ambiguous``: one
  hypothesis per distinct solution.

:func:`resolve` runs the estimator from each and reports one track:

* EKF, iSAM2, fixed-lag ("likelihood"): each hypothesis's weight is its
  prior weight (the term's weight, or the solution's share of the window's
  posterior inside the zone, :func:`hypothesis_weights`; :math:`e^{-c/2}`
  of its window cost where that was not computed)
  times the predictive likelihood of every later measurement (from an EKF
  per hypothesis); every estimate is the weighted *mixture*,
  :math:`\bar{\mathbf x} = \sum_h w_h\mathbf x_h`,
  :math:`\mathbf P = \sum_h w_h(\mathbf P_h + (\mathbf x_h - \bar{\mathbf x})(\mathbf x_h - \bar{\mathbf x})^\top)`,
  with the weights of the data each estimate has read: those up to its
  time for filtered estimates, up to ``lag`` seconds after it for the
  fixed-lag smoother's lagged ones (the scans it was smoothed with before
  it left the window), all the data for smoothed ones; a ``competing`` finding
  is doubtful when the mixture holds separate modes;
* smoother ("cost"): the hypothesis with the lowest final cost, with a
  ``competing`` finding when another explains the data about as well;
  :func:`resolve_staged` finishes only that hypothesis's run (its final
  findings and reported covariances, :class:`CostStages`).

iSAM2 and fixed-lag are ranked by an EKF per hypothesis *before* they run,
and a hypothesis whose filtered weight stays below :data:`NEGLIGIBLE` from
some scan on runs only up to that scan (it weighs nothing after it, in any
estimate): on the two-hour slow three-pair recording of
:mod:`benchmarks.bench_long`, three of seven terms stop after about
1,100 s, which took iSAM2 from 105 s to 63 s (measured before the
history check of :class:`~fgdoppler.estimators.settings.ISAM2Settings`,
which adds 19 % there).

:attr:`TrackResult.hypothesis <fgdoppler.estimators.results.TrackResult>`
records which hypothesis weighed most when.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Generic, Literal, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp
from scipy.stats import chi2

from fgdoppler._text import distance_text
from fgdoppler.estimators.ekf import run_ekf
from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.search_memo import SearchMemo
from fgdoppler.estimators.settings import EKFSettings, FixedLagSettings, TrackerSettings
from fgdoppler.estimators.verdict import Event, Reason
from fgdoppler.measurements import Measurements
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, prefixed

__all__ = ["NEGLIGIBLE", "CostStages", "Draft", "Resolution", "hypotheses", "hypothesis_weights", "posterior_hypotheses",
           "resolve", "resolve_staged"]

Resolution = Literal["likelihood", "cost", "native"]
Runner = Callable[..., TrackResult]
"""``run(measurements, model, init, settings, *, progress=None) -> TrackResult``."""


def hypotheses(init: Initiation) -> list[Initiation]:
    """The initiation and one unambiguous copy per alternative (best first).

    Each copy starts from the alternative's state and covariance at the
    window start, propagated to the window end.  An alternative without a
    determinate covariance keeps ``None`` (the EKF then starts from the
    zone's broad prior and says so; the smoother does not need one): a
    solution the window cannot pin down is still a place the target may be.
    A copy's ``objective`` is its data cost (the regularisers are not
    evaluated for alternatives).
    """
    kept = tuple(r for r in init.reasons if r.code != "ambiguous")
    out = [replace(init, alternatives=(), reasons=kept)]
    F = ConstantVelocity(dim=init.x_start.size // 2).F(init.t_end - init.t_start)
    for a in init.alternatives:
        P = a.covariance
        out.append(replace(
            init, x_start=a.state, x_end=F @ a.state, P_start=P, P_end=None if P is None else F @ P @ F.T,
            cost=a.cost, objective=a.cost, passes_chi2=a.passes_chi2, alternatives=(),
            reasons=tuple(r for r in kept if r.code not in ("covariance", "boundary")),
            events=(*init.events, Event(time=init.t_start, message="hypothesis from an ambiguous initiation")),
        ))
    return out


def hypothesis_weights(init: Initiation) -> NDArray[np.float64] | None:
    r"""Prior weights of :func:`hypotheses`: each solution's share of the window posterior inside the zone.

    :math:`w_h \propto Z_h` from the initiation's
    :attr:`~fgdoppler.estimators.initiation.Initiation.log_evidence` and its
    alternatives' (data, weak prior, the zone's truncation, the basin's
    volume).  ``None`` where those were not computed (then :func:`resolve`
    weighs by the window costs, :math:`\propto e^{-c/2}`).

    Why not the costs alone: on the paper's six scenarios (100 runs each,
    seeds 7 and 2026; 113 windows with alternatives) every alternative is
    held at the zone's along-baseline edge (the slow target near a sensor,
    or a mirror-side solution), and the truth is most probable under the
    first solution's Gaussian in all 113.  The cost
    weights give the alternatives 29 % on average (32.8 of the 113 windows'
    worth in all), these 3.5 % (3.9).
    """
    return init.posterior_shares()


def posterior_hypotheses(init: Initiation, measurements: Measurements, model: TrackingModel, k: int, *,
                         huber_k: float | None = None, seed: int = 0
                         ) -> tuple[list[Initiation], NDArray[np.float64]]:
    """One hypothesis per term of a Gaussian sum of the window's posterior, and the terms' weights.

    The posterior is sampled (:func:`~fgdoppler.estimators.particle.window_posterior`)
    and split (:meth:`~fgdoppler.estimators.particle.WindowPosterior.components`);
    each hypothesis starts a tracker at the window's end from its term
    (``window_summarised``).

    Raises
    ------
    ValueError
        If no start inside the zone explains the window.
    """
    from fgdoppler.estimators.settings import ParticleSettings
    from fgdoppler.estimators.window_posterior import window_posterior

    # One-step importance sampling, not the particle estimator's tempered start: eight terms of the
    # faithful (wider) posterior resolve its valley more coarsely, and a tracker stays near its term;
    # measured, case a 5 km gained 2-7 % while case b 25 and 45 km lost up to 9 % (docs, "A particle
    # estimator").
    post = window_posterior(measurements, model, init,
                            ParticleSettings(huber_k=huber_k, seed=seed, tempered_start=False))
    terms = post.components(k, model, seed=seed)
    Fi = np.linalg.inv(model.motion.F(init.t_end - init.t_start))
    kept = tuple(r for r in init.reasons if r.code != "ambiguous")
    hyps = [replace(init, x_start=Fi @ m, x_end=m, P_start=Fi @ P @ Fi.T, P_end=P, alternatives=(), reasons=kept,
                    window_summarised=True,
                    events=(*init.events, Event(time=init.t_end, message=(
                        f"term {i + 1} of a {len(terms)}-term Gaussian sum of the window's posterior "
                        f"(weight {w:.3f})"))))
            for i, (w, m, P) in enumerate(terms)]
    return hyps, np.array([w for w, _, _ in terms])


def resolve(run: Runner, resolution: Resolution, measurements: Measurements, model: TrackingModel,
            hyps: list[Initiation], settings: TrackerSettings, progress: Progress | None = None,
            weights: NDArray[np.float64] | None = None) -> TrackResult:
    r"""Run ``run`` from every hypothesis and report one track (module docstring).

    ``weights`` are the hypotheses' prior weights (default: from their
    window costs, :math:`\propto e^{-c/2}`); a hypothesis of weight zero is
    run but takes no share.  ``progress`` sees each run's tasks prefixed
    with ``"hypothesis i/n"``.

    Raises
    ------
    ValueError
        If ``weights`` are not one finite, non-negative number per hypothesis, or all zero.
    """
    t_begin = time.perf_counter()
    n = len(hyps)
    if weights is not None:
        w = np.asarray(weights, dtype=float)
        if w.shape != (n,) or not (np.all(np.isfinite(w)) and np.all(w >= 0.0) and np.any(w > 0.0)):
            raise ValueError(f"the {n} hypotheses' weights must be {n} finite, non-negative numbers, not all zero; "
                             f"got {w.tolist()}")
    note = _ran(n)
    if resolution == "likelihood" and run is not run_ekf:
        return _resolve_ranked(run, measurements, model, hyps, settings, progress, weights, note, t_begin)
    results = [run(measurements, model, h, settings, progress=prefixed(progress, f"hypothesis {i + 1}/{n}"))
               for i, h in enumerate(hyps)]
    if resolution == "cost":
        costs = _costs([r.cost for r in results])
        return _lowest_cost(results, costs, int(np.argmin(costs)), t_begin)
    # the EKF reports its own predictive likelihood: it is ranked by it
    return _mixed(results, _Weights.of(hyps, results, weights), note, t_begin, lag=_lag(settings))


def _lag(settings: TrackerSettings) -> float | None:
    """How far past its time a lagged estimate has read the data (the fixed-lag smoother's lag), else ``None``."""
    return settings.lag if isinstance(settings, FixedLagSettings) else None


class Draft(Protocol):
    """The first stage of a run resolved by cost: its solution's cost, and the solution as a track."""

    @property
    def cost(self) -> float: ...

    def result(self) -> TrackResult: ...


_D = TypeVar("_D", bound=Draft)


@dataclass(frozen=True, kw_only=True)
class CostStages(Generic[_D]):
    """A run resolved by cost (:func:`resolve_staged`) in two stages.

    Attributes
    ----------
    draft
        ``draft(measurements, model, init, settings, *, progress=None, memo=None) -> Draft``: the solution
        from one hypothesis.
    finish
        ``finish(measurements, model, draft, *, progress=None, memo=None) -> TrackResult``: the draft's
        reported track with every finding; the same as one run from its hypothesis but for what ``join``
        adds.
    join
        ``join(best, drafts) -> Draft``: the draft of lowest cost told of every hypothesis's draft before it
        is finished (what the others found that bears on the reported track), or ``None``.
    """

    draft: Callable[..., _D]
    finish: Callable[..., TrackResult]
    join: Callable[[_D, list[_D]], _D] | None = None


def resolve_staged(stages: CostStages[_D], measurements: Measurements, model: TrackingModel, hyps: list[Initiation],
                   settings: TrackerSettings, progress: Progress | None = None, memo: SearchMemo | None = None
                   ) -> TrackResult:
    """:func:`resolve` by cost, finishing only the hypothesis of lowest cost.

    Every hypothesis is drafted (with one ``memo`` for the recording); the
    one of lowest cost is finished and reported as :func:`resolve` would
    report its full run.  The others enter only the ``competing`` finding,
    by their cost and the end of their maximum a posteriori track — what
    their full runs would give too, but where a full run reports the
    posterior mean (a skewed posterior,
    :mod:`fgdoppler.estimators.spread`): there the draft's end is the
    mode's, which the cost compared is the cost of.  With ``stages.join``
    the chosen draft first hears of the others' (the smoother: the tracks
    the zone wall held in any hypothesis, :meth:`SmootherDraft.joined
    <fgdoppler.estimators.smoother.SmootherDraft.joined>`), which a whole
    run from its hypothesis alone does not.
    """
    t_begin = time.perf_counter()
    n = len(hyps)
    drafts = [stages.draft(measurements, model, h, settings, progress=prefixed(progress, f"hypothesis {i + 1}/{n}"),
                           memo=memo)
              for i, h in enumerate(hyps)]
    costs = _costs([d.cost for d in drafts])
    best = int(np.argmin(costs))
    chosen = drafts[best] if stages.join is None else stages.join(drafts[best], drafts)
    results = [d.result() if i != best else
               stages.finish(measurements, model, chosen, progress=prefixed(progress, f"hypothesis {i + 1}/{n}"),
                             memo=memo)
               for i, d in enumerate(drafts)]
    return _lowest_cost(results, costs, best, t_begin)


def _ran(n: int) -> str:
    """The event's words for ``n`` hypotheses run."""
    return f"ambiguous initiation: {n} hypotheses run"


def _costs(costs: list[float | None]) -> NDArray[np.float64]:
    """The hypotheses' costs, a missing one as infinite."""
    return np.array([np.inf if c is None else c for c in costs], dtype=float)


def _lowest_cost(results: list[TrackResult], costs: NDArray[np.float64], best: int, t_begin: float) -> TrackResult:
    """``results[best]`` reported as the resolution by cost: the hypothesis it came from, an event, the
    ``competing`` finding."""
    r = results[best]
    event = Event(time=float(r.primary.times[-1]), message=f"{_ran(len(results))}; hypothesis {best} has the lowest cost")
    return replace(r, hypothesis=np.full(len(r.primary), best), events=(*r.events, event),
                   reasons=(*r.reasons, *_competing(costs, results, best)),
                   wall_time=time.perf_counter() - t_begin)


def _resolve_ranked(run: Runner, measurements: Measurements, model: TrackingModel, hyps: list[Initiation],
                    settings: TrackerSettings, progress: Progress | None, weights: NDArray[np.float64] | None,
                    note: str, t_begin: float) -> TrackResult:
    """Rank the hypotheses with one EKF each, then run ``run`` from each only while it can weigh anything.

    A hypothesis whose filtered weight stays below :data:`NEGLIGIBLE` from
    some scan on is run on the data up to that scan only: its filtered
    estimates up to there are what the full run gives (online), and after
    it, and in every estimate weighted by data beyond it, its weight is below
    :data:`NEGLIGIBLE`; its estimates there are its last state carried
    forward by the motion model (covariance marked indeterminate).
    """
    n = len(hyps)
    ekf_settings = EKFSettings.gating_as(settings)
    ekfs = [run_ekf(measurements, model, h, ekf_settings, progress=prefixed(progress, f"ranking {i + 1}/{n}"))
            for i, h in enumerate(hyps)]
    mix = _Weights.of(hyps, ekfs, weights)
    W = mix.at(mix.times)
    # weights the ranking could not settle (no finite likelihood anywhere) stop nothing
    alive = W >= NEGLIGIBLE if np.all(np.isfinite(W)) else np.ones(W.shape, dtype=bool)
    results, stops = [], []
    for i, h in enumerate(hyps):
        above = np.flatnonzero(alive[i])
        # one scan beyond the last that weighs, so the run is never empty
        last = min(int(above[-1]) + 1 if above.size else 1, mix.times.size - 1)
        cut = None if last == mix.times.size - 1 else float(mix.times[last])
        data = measurements if cut is None else measurements.subset(measurements.time <= cut)
        results.append(run(data, model, h, settings, progress=prefixed(progress, f"hypothesis {i + 1}/{n}")))
        if cut is not None:
            stops.append(f"hypothesis {i} stopped at {cut:.1f} s")
    full = next(r for r, s in zip(results, alive[:, -1], strict=True) if s)
    parts = [tuple(_carried(e, f, model.motion) for e, f in zip(r.estimates, full.estimates, strict=True))
             for r in results]
    if stops:
        note = f"{note} ({'; '.join(stops)}: weight below {NEGLIGIBLE:.0e} from then on)"
    return _mixed(results, mix, note, t_begin, parts, lag=_lag(settings))


def _carried(part: Estimates, full: Estimates, motion: ConstantVelocity) -> Estimates:
    """``part`` on ``full``'s time grid: its last state carried forward, covariances indeterminate."""
    m = len(part)
    if m == len(full):
        return part
    if not (0 < m < len(full) and np.array_equal(part.times, full.times[:m])):
        raise AssertionError("a stopped hypothesis's estimates must be a prefix of the full run's time grid")
    extra = full.times[m:]
    x = motion.propagate(part.states[-1], extra - part.times[-1])
    k = part.states.shape[1]
    return Estimates(kind=part.kind, times=full.times, states=np.concatenate([part.states, x]),
                     covariances=np.concatenate([part.covariances, np.zeros((extra.size, k, k))]),
                     cov_ok=np.concatenate([part.cov_ok, np.zeros(extra.size, dtype=bool)]))


def _mixed(results: list[TrackResult], mix: _Weights, note: str, t_begin: float,
           parts: list[tuple[Estimates, ...]] | None = None, *, lag: float | None = None) -> TrackResult:
    """One track from the hypotheses' runs: the mixture of their estimates under the weights ``mix``.

    ``parts`` are the runs' estimates on a common time grid (default: as they ran).  Each estimate is
    mixed with the weights of the data it has read (:func:`_read_weights`; ``lag``: the fixed-lag
    smoother's).
    """
    parts = parts if parts is not None else [r.estimates for r in results]
    weights = [_read_weights(mix, est, lag) for est in parts[0]]
    mixed = tuple(_mixture(est.kind, [p[j] for p in parts], weights[j]) for j, est in enumerate(parts[0]))
    W_end = mix.final(1)[:, 0]
    best = int(np.argmax(W_end))
    hyp = np.argmax(weights[0], axis=0)
    event = Event(time=float(mix.times[-1]), message=(
        f"{note}; the estimates are their mixture, weighted by the data (hypothesis {best} carries "
        f"{W_end[best]:.2f} at the end)"))
    ends = [p[0] for p in parts]
    return replace(results[best], estimates=mixed, hypothesis=np.asarray(hyp, dtype=np.int64),
                   events=(*results[best].events, event),
                   reasons=(*results[best].reasons, _modes_reason(W_end, ends)),
                   wall_time=time.perf_counter() - t_begin)


def _read_weights(mix: _Weights, est: Estimates, lag: float | None) -> NDArray[np.float64]:
    r"""The hypotheses' weights ``(H, n)`` given the data each of ``est``'s estimates has read.

    A filtered estimate at :math:`t` has read the scans up to :math:`t`; a
    lagged one (the fixed-lag smoother's) those up to :math:`t + \ell`,
    :math:`\ell` = ``lag``: it left the smoother's window at the first scan
    later than that, as estimated at the scan before; a smoothed one all of
    them.  Weighing a lagged estimate with all the data would make it an
    offline answer: in the paper's case a 5 km (100 runs, seed 2026) the
    fixed-lag smoother's RMSE is 1,164 m with the weights of the data it has
    read, and was 947 m with those of the whole recording.

    Raises
    ------
    ValueError
        For lagged estimates without a ``lag``.
    """
    if est.kind == "filtered":
        return mix.at(est.times)
    if est.kind == "lagged":
        if lag is None:
            raise ValueError("lagged estimates are mixed with the weights of the data up to one lag after "
                             "them: give the lag")
        return mix.at(est.times + lag)
    return mix.final(len(est))


#: A hypothesis weighing less than this (for good) takes no further part (:func:`resolve`).
NEGLIGIBLE = 1e-12


class _Weights:
    """Posterior weights of the hypotheses over time: prior weight times the data's predictive likelihood."""

    def __init__(self, logw0: NDArray[np.float64], loglik: NDArray[np.float64], times: NDArray[np.float64]) -> None:
        self.logw0, self.loglik, self.times = logw0, loglik, times

    @classmethod
    def of(cls, hyps: list[Initiation], ekfs: list[TrackResult], weights: NDArray[np.float64] | None) -> _Weights:
        r"""From the prior ``weights`` (default :math:`\propto e^{-c/2}` of the window costs) and one EKF each.

        A weight of exactly zero is a log weight of :math:`-\infty`: the
        hypothesis takes no share anywhere (a restart's running estimate whose
        cost puts it more than ~745 nats below the fit, where its share
        underflows).
        """
        if weights is None:
            logw0 = -0.5 * np.array([h.cost for h in hyps])
        else:
            with np.errstate(divide="ignore"):
                logw0 = np.log(np.asarray(weights, dtype=float))
        return cls(logw0, np.array([e.log_likelihood for e in ekfs]), ekfs[0].primary.times)

    def at(self, times: NDArray[np.float64]) -> NDArray[np.float64]:
        """Weights ``(H, n)`` at each of ``times`` (from the data up to then)."""
        idx = np.clip(np.searchsorted(self.times, times, side="right") - 1, 0, self.times.size - 1)
        lw = self.logw0[:, None] + self.loglik[:, idx]
        return np.exp(lw - logsumexp(lw, axis=0, keepdims=True))

    def final(self, n: int) -> NDArray[np.float64]:
        """The weights after all the data, repeated for ``n`` times (smoothed and lagged estimates)."""
        return np.repeat(self.at(self.times[-1:]), n, axis=1)


def mixture_moments(w: NDArray[np.float64], X: NDArray[np.float64], P: NDArray[np.float64] | None = None
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    r"""Mean and covariance of a Gaussian mixture, term by term along the leading axis.

    .. math::

        \bar{\mathbf x} = \sum_h w_h \mathbf x_h, \qquad
        \mathbf P = \sum_h w_h\big(\mathbf P_h + (\mathbf x_h - \bar{\mathbf x})(\mathbf x_h - \bar{\mathbf x})^\top\big)

    ``w`` ``(H, ...)`` are the weights (summing to one over ``H``), ``X``
    ``(H, ..., d)`` the terms' means, ``P`` ``(H, ..., d, d)`` their
    covariances (``None``: the mean only).  The covariance is symmetric to
    the last bit (files keep one triangle).
    """
    lead = X.shape[1:-1]
    h, d = X.shape[0], X.shape[-1]
    w2, X2 = w.reshape(h, -1), X.reshape(h, -1, d)
    mean = np.einsum("hn,hni->ni", w2, X2)
    if P is None:
        return mean.reshape(*lead, d), None
    dev = X2 - mean[None]
    cov = np.einsum("hn,hnij->nij", w2, P.reshape(h, -1, d, d) + np.einsum("hni,hnj->hnij", dev, dev))
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    return mean.reshape(*lead, d), cov.reshape(*lead, d, d)


def _mixture(kind: str, parts: list[Estimates], W: NDArray[np.float64]) -> Estimates:
    r"""The Gaussian mixture of the hypotheses' estimates: :math:`\bar x = \sum w_h x_h`,
    :math:`P = \sum w_h (P_h + (x_h - \bar x)(x_h - \bar x)')`.

    Hypotheses whose estimates are on another time grid (a tracker that
    stopped early) or indeterminate do not take part; their weight goes to
    the others.
    """
    ref = parts[0]
    same = np.array([p.times.shape == ref.times.shape and np.array_equal(p.times, ref.times) for p in parts])
    X = np.array([p.states if ok else ref.states for p, ok in zip(parts, same, strict=True)])
    P = np.array([p.covariances if ok else ref.covariances for p, ok in zip(parts, same, strict=True)])
    ok = np.array([p.cov_ok if s else np.zeros(len(ref), dtype=bool) for p, s in zip(parts, same, strict=True)])
    w = np.where(same[:, None], W, 0.0)
    w = w / np.maximum(np.sum(w, axis=0, keepdims=True), 1e-300)
    mean, cov = mixture_moments(w, X, P)
    cov_ok = np.all(ok | (w < 1e-9), axis=0)
    return Estimates(kind=kind, times=ref.times, states=mean, covariances=cov, cov_ok=cov_ok)  # type: ignore[arg-type]


def _density(x: NDArray[np.float64], w: NDArray[np.float64], means: NDArray[np.float64],
             covs: NDArray[np.float64]) -> float:
    """Gaussian-mixture density of the positions at ``x`` (the position block of each term)."""
    out = 0.0
    for wi, m, P in zip(w, means, covs, strict=True):
        d = x - m
        k = d.size
        S = P[:k, :k]
        norm = np.sqrt((2 * np.pi) ** k * np.linalg.det(S))
        out += wi * float(np.exp(-0.5 * d @ np.linalg.solve(S, d)) / norm)
    return out


def _modes_reason(w: NDArray[np.float64], ends: list[Estimates]) -> Reason:
    """A ``competing`` finding: ``"doubtful"`` when the final mixture has separate modes of real weight.

    Two terms with weight ≥ 5 % are separate modes when the mixture's density
    at the midpoint of their positions is below a tenth of the lower of the
    two peaks: the data then leave two places for the target, and the
    mixture's mean lies between them.
    """
    usable = [h for h in range(len(ends)) if ends[h].cov_ok[-1] and w[h] >= 0.05]
    means = np.array([e.states[-1, :e.dim] for e in ends])
    covs = np.array([e.covariances[-1] for e in ends])
    sel = np.array(usable, dtype=np.intp)
    for i in usable:
        for j in usable:
            if j <= i:
                continue
            args = (w[sel], means[sel], covs[sel])
            mid = _density(0.5 * (means[i] + means[j]), *args)
            low = min(_density(means[i], *args), _density(means[j], *args))
            if mid < 0.1 * low:
                apart = float(np.linalg.norm(means[i] - means[j]))
                return Reason(code="competing", status="doubtful", message=(
                    f"the data leave separate solutions {distance_text(apart)} apart at the end (weights "
                    f"{w[i]:.2f} and {w[j]:.2f}); the estimate is their mixture, its mean between them"))
    return Reason(code="competing", status="ok", message=(
        f"{len(ends)} hypotheses, carried as a mixture; no separate mode of weight >= 0.05 at the end"))


#: Two hypotheses closer than this in cost (χ²₁ at 95 %) cannot be told apart by the data.
COMPETING = float(chi2.ppf(0.95, 1))


def _distinct(a: TrackResult, b: TrackResult) -> bool:
    """Two tracks end at different places: farther apart than 50 m and three of ``a``'s standard deviations."""
    k = a.primary.dim
    d = b.primary.states[-1, :k] - a.primary.states[-1, :k]
    P = a.primary.covariances[-1, :k, :k]
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
    k = results[best].primary.dim
    apart = float(np.linalg.norm(results[second].primary.states[-1, :k] - results[best].primary.states[-1, :k]))
    if margin >= COMPETING:
        return (Reason(code="competing", status="ok", message=(
            f"{len(results)} hypotheses from an ambiguous initiation; the data prefer the one reported by "
            f"{margin:.1f} in cost (> {COMPETING:.2f}) over one ending {distance_text(apart)} away")),)
    return (Reason(code="competing", status="doubtful", message=(
        f"a competing solution explains the data about as well (cost higher by only {margin:.2f} < {COMPETING:.2f}) "
        f"and ends {distance_text(apart)} away: the data cannot tell them apart")),)
