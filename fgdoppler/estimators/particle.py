r"""Particle estimator: the Bayesian posterior of a constant-velocity track by sequential Monte Carlo.

Where the Doppler likelihood is a thin curved valley (far from the
baseline, near it at the ends, a short window) no Gaussian describes the
posterior, and every Gaussian estimator — EKF, UKF, iSAM2 — is
overconfident there.  This estimator carries the posterior as weighted
samples instead.

Over a short span the target moves at constant velocity (the model's
process noise is small: :math:`q = 10^{-3}` m²/s³ moves a 30 s track by
3 m), so the posterior of the state at any time is the posterior of the
state :math:`\mathbf x_a` at an *anchor* time mapped by
:math:`\mathbf F(t - t_a)`; the anchor moves on before the noise left out
matters (*Re-anchoring*, below).
The particles are samples of :math:`\mathbf x_a`; the target density after
the measurements :math:`z_{1:k}` since the anchor is

.. math::

    \pi_k(\mathbf x_a) \propto p(\mathbf x_a)\,
        \exp\!\Big(-\tfrac12\sum_{j\le k}\rho\big((z_j - h_j(\mathbf F(t_j - t_a)\mathbf x_a))/\sigma_j\big)\Big),

with :math:`\rho` the squared or Huber loss and :math:`p(\mathbf x_a)` the
zone as support (the initiation's assumption; within it the half plane the
initiation was given, :attr:`~fgdoppler.estimators.initiation.Initiation.half_plane`)
times the model's weak prior.
This is iterated batch importance sampling (Chopin 2002):

1. **Start** — the window's posterior :math:`\pi_0`, sampled from a
   Gaussian mixture on the initiation's solutions (its estimate, its
   alternatives, the grid's best candidates; covariances doubled in
   standard deviation) by adaptive tempering — a sequence of targets from
   the mixture to :math:`\pi_0`, each step reweighting, resampling and
   moving the samples (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.sample_from`) so that distant
   modes keep their due mass — then ``start_move_steps`` Metropolis steps
   so the samples fill the curved valleys.
2. **Each later scan** — every measurement is gated against the particles'
   predictive distribution (mean and variance of :math:`h` over the
   particles plus :math:`\sigma^2`, :class:`~fgdoppler.estimators.gating.NISGate`),
   the accepted ones reweight the particles; when the effective sample
   size falls below ``ess_threshold`` × N the particles are resampled
   (systematic) and moved by ``move_steps`` random-walk Metropolis steps
   (5; 3 for the mode, :class:`~fgdoppler.estimators.settings.MapSettings`)
   targeting :math:`\pi_k`, each particle with the covariance of its own
   cluster (the mixture component it descends from, so a mirror mode keeps
   its own scale).
3. **Estimates** — the weighted mean and covariance of
   :math:`\mathbf F(t - t_a)\mathbf x_a`, plus the process noise
   :math:`\mathbf Q(t - t_a)` accumulated since the anchor
   (:func:`run_particle`); or, the filtered MAP (:func:`run_map`), the
   posterior's mode :math:`\arg\max_{\mathbf x_a}\pi_k` found by
   Levenberg–Marquardt from the previous mode (and from the best particle
   where that stands higher), with the particles' second moment about it as
   covariance — or, where the posterior is skewed rather than curved
   (:func:`mean_is_the_better_point`), the mean and covariance.  Where
   the best particle falls further below that mode than a sample of the
   posterior can (:func:`rescue_shortfall`), ``map`` samples the particles
   again about it first (``MapSettings.mode_rescue``); so does the mean's
   estimator in space, where it climbs to the mode for that alone
   (``ParticleSettings.mode_rescue``).

**Re-anchoring.** When the anchor moves to the current scan, the
particles are propagated with process-noise samples and the older data are
summarised by the moment-matched Gaussian of the propagated cloud (exact for
a Gaussian posterior), and from then on each resampling is followed by one
Metropolis step instead of ``move_steps``.  It happens at a resampling
(:meth:`~fgdoppler.estimators.particle_posterior._Posterior.should_reanchor`):

- when the process noise the likelihood leaves out, :math:`\mathbf Q(t - t_a)`,
  exceeds ``max_noise_share`` of the posterior's variance in the direction
  it affects most (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.noise_share`, :math:`\lambda`) *and*
  costs more than the Gaussian summary would lose
  (:math:`\lambda^2/4 \ge \operatorname{Var}_\pi[r]/2`,
  :meth:`~fgdoppler.estimators.particle_posterior._Posterior.misfit`): once or twice in the paper's well-observed
  30 s recordings (case a 45 km, case b 5 km), never in its poorly observed
  ones, every 15–25 s in the 600 s and 2 h recordings measured once the
  posterior is tight — not
  while it is curved or multimodal and the noise is small against its
  spread.  Without it the particles'
  posterior over a long span is that of a rigid track, too narrow along the
  track's weak direction, and the process noise added when they are read
  out widens the thin direction instead (400 s recordings of the paper's
  pairs: variances 0.18–0.25 and 12–14 times the offline smoother's in two
  directions, and the verdict's check against it ``doubtful``;
  docs/concepts.md, "Long recordings");
- after ``max_span`` seconds in any case: a move needs the likelihood of
  every measurement since the anchor, so its cost grows with the span.

The run's closing event counts the re-anchorings.

With ``settings.bias_sigma`` each pair's constant Doppler offset,
prior :math:`N(0, \sigma_{b,p}^2)`, is part of the model and integrated
out of every particle's likelihood in closed form
(:mod:`fgdoppler.estimators.offset_posterior`): each particle carries the
per-pair sums :math:`s_p` of its whitened residuals, the gate predicts with
the offsets' conditional mean and variance, the mode's climb solves for
the state and the offsets together, and a re-anchoring summarises the
offsets jointly with the state.  A clock offset does not integrate out so:
with ``settings.clock_sigma`` the registry adds what such offsets would do
to the track to its covariances, from reruns with the same random numbers
(:func:`~fgdoppler.estimators.clock_offsets.clock_shares`), as for the
filters.

**Restarts.** :func:`~fgdoppler.estimators.registry.run_estimator`
tests the run at the filters' checkpoints where the data since the last
one surprise it or a solution of its initiation, refined on all the data
so far, fits them better than its own basin
(:mod:`fgdoppler.estimators.basin_screen`), or where the particles were
sampled again about a mode they had missed since the last one
(:func:`rescued`: the peak they found may lie in a wrong basin, which the
later data then leave too slowly to surprise them), and starts it again from the best fit of all the data so
far where that and the running estimate each lie outside the other's
99.9 % region (:mod:`fgdoppler.estimators.restart`, "The particle
estimators"; ``restarts=False`` in the settings turns this off): a start
sampled in the wrong basin is otherwise never left.

Random numbers come from ``numpy.random.default_rng(settings.seed)``: the
same input and settings give the same track.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fgdoppler.estimators.gating import NISGate
from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.local import in_computation_frame
from fgdoppler.estimators.log_sum_exp import log_sum_exp
from fgdoppler.estimators.particle_posterior import _Posterior, _weighted_cov
from fgdoppler.estimators.results import Estimates, OffsetEstimate, TrackResult
from fgdoppler.estimators.settings import MapSettings, ParticleSettings
from fgdoppler.estimators.spread import SAMPLING_LIMIT
from fgdoppler.estimators.verdict import Event
from fgdoppler.estimators.window import split_window
from fgdoppler.estimators.window_posterior import (
    WindowPosterior,
    _window_posterior,
    window_posterior,
)
from fgdoppler.geometry import pair_labels
from fgdoppler.measurements import Measurements
from fgdoppler.models.observation import check_channels, predict_along
from fgdoppler.models.robust import huber_rho
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance, start_task

__all__ = ["MEAN_SHIFT_FAR", "MEAN_SHIFT_NOISE", "RESCUE_DRAWS", "RESCUE_EVENT", "RESCUE_LEVEL", "WindowPosterior",
           "mean_is_the_better_point", "rescue_shortfall", "rescued", "run_map", "run_particle", "window_posterior"]

FloatArray = NDArray[np.float64]

#: Squared Mahalanobis shift of the particles' mean from the mode below which ``map`` reports the mode: the mean's
#: Monte Carlo scatter about a Gaussian posterior's mode (the accuracy benchmark's well-observed scenarios, 100 runs
#: each, seed 2026: 0.015 at the median, 0.11 at the 95th percentile of their reports).
MEAN_SHIFT_NOISE = 0.1
#: Squared shift beyond which, in a valley that bends (probe ratio above the smoother's ``SAMPLING_LIMIT``), the
#: mean lies off the ridge and ``map`` reports the mode: one standard deviation (the same runs: the curved valleys
#: of case a 5 km and case b 45 km 1.7 at their 5th percentile, the lopsided ones of the 25 km scenarios 0.72 at
#: their 95th).
MEAN_SHIFT_FAR = 1.0
#: ``map`` (and the particle estimator in space) samples its particles again about the mode when the best of them
#: falls so far short of it that this many independent draws of a posterior near Gaussian about the mode would all
#: fall as short with probability :data:`RESCUE_LEVEL` (:func:`rescue_shortfall`); resampling repeats particles, so
#: fewer count as independent than there are.
RESCUE_DRAWS = 20
#: See :data:`RESCUE_DRAWS`.
RESCUE_LEVEL = 1e-6
#: How the event of a rescue begins (:func:`rescued` reads it).
RESCUE_EVENT = "the particles had missed the posterior's peak"


@in_computation_frame
def run_particle(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: ParticleSettings | None = None,
    *,
    progress: Progress | None = None,
) -> TrackResult:
    """The particle estimator over a recording (module docstring); filtered estimates from the window's end on.

    Each estimate is the posterior mean with the posterior covariance.  In
    space (``ParticleSettings.mode_rescue``; by default not in the plane) it
    also climbs to the posterior's mode at every report, as :func:`run_map`
    does, and where its best particle falls further below that mode than a
    sample of the posterior can (:func:`rescue_shortfall`) samples the
    particles again about it, with an event (docs/concepts.md, "Particles
    that miss the peak").

    Raises
    ------
    ValueError
        If the window cannot be explained by any start inside the zone.
    """
    return _run(measurements, model, init, settings or ParticleSettings(), progress, mode=False)


@in_computation_frame
def run_map(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: ParticleSettings | None = None,
    *,
    progress: Progress | None = None,
) -> TrackResult:
    r"""The filtered MAP: at each scan the most probable state given all the data so far.

    The particle estimator's posterior read at its mode instead of its mean
    (with the same settings, the same particles and random numbers as
    :func:`run_particle`; its defaults, :class:`MapSettings`, hold half
    as many particles and move them less after each resampling, since the
    mode needs less of the posterior's detail than the mean):
    at each report time :math:`t`, Levenberg–Marquardt from the previous
    report's mode, and from the particle of highest posterior density where
    that stands higher
    (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.mode`),
    finds :math:`\hat{\mathbf x}_a`, the most probable anchor state of
    the most probable basin, and
    the estimate is :math:`\mathbf F(t - t_a)\hat{\mathbf x}_a` with the
    particles' second moment about it
    (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.spread_about`)
    as covariance — the posterior's mean-square error of that point, never less than the
    posterior covariance, so the covariance also describes the distance from
    the mode to the bulk of the mass.

    Where the data pin the state to a thin *curved* valley, its mean lies
    inside the curve, off the valley, and the mode on it; where the data
    leave a long, nearly flat valley that the zone truncates, the mode can
    lie anywhere along it and the mean, which weighs the whole truncated
    valley, is the better point.  So by default (``MapSettings.posterior_mean``)
    each report tells the two apart, as the offline smoother does: with
    :math:`\hat{\mathbf x}_a` the mode, :math:`\mathbf I` the Gauss–Newton
    information of :math:`-2\log\pi_k` there and :math:`\bar{\mathbf x}_a`
    the particles' mean, the squared shift
    :math:`w = (\bar{\mathbf x}_a - \hat{\mathbf x}_a)^\top\mathbf I\,(\bar{\mathbf x}_a - \hat{\mathbf x}_a)`
    and the curvature probe's ratio :math:`\rho` along the major axis of
    :math:`\mathbf I^{-1}`
    (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.mean_shift`)
    decide: the mean and the particles' covariance where
    :math:`w > 0.1` (:data:`MEAN_SHIFT_NOISE`) and either :math:`w \le 1`
    (:data:`MEAN_SHIFT_FAR`) or :math:`\rho \le 3` (a valley near-quadratic
    three standard deviations out), the mode elsewhere
    (:func:`mean_is_the_better_point`).  The closing event counts the
    reports at the mean.  With calibration offsets integrated out
    (``bias_sigma``) the mode is reported at every scan: the offsets leave a
    ridge of tracks along which the prior pulls the mean toward the zone's
    centre (docs/concepts.md, "Calibration offsets"), and in the paper's
    well-observed scenarios the rule's track was 91-153 m farther from the
    truth than the mode's (time-averaged RMSE, 100 runs each, seeds 2026
    and 7).  So is it given plain :class:`ParticleSettings`, which have no
    such choice.  docs/concepts.md ("The filtered mode") says which scenario
    is which, measured.  When the mode leaves one peak
    of the posterior for another (one that a particle revealed, standing
    higher and holding more of the posterior by the Laplace approximation:
    :meth:`~fgdoppler.estimators.particle_posterior._Posterior.basin_log_mass`;
    a narrow peak at the zone's walls can stand higher than the broad valley
    that holds nearly every particle, and is not taken), the run says so in
    an event — where, how far, and how much more probable the new basin is —
    since such a jump can be kilometres for a probability ratio of a few.  After a re-anchoring
    (``max_span``) the older data are a Gaussian summary centred on the
    particles' mean, so on long recordings the two read-outs converge.

    Where the best particle falls further below the mode than a sample of
    the posterior can (:func:`rescue_shortfall`), the particles have missed
    the peak (in space, for tens of seconds) and ``MapSettings.mode_rescue``
    samples them again about it, with an event; on the paper's scenarios it
    never acts (docs/concepts.md, "Particles that miss the peak").

    Raises
    ------
    ValueError
        If the window cannot be explained by any start inside the zone.
    """
    return _run(measurements, model, init, settings or MapSettings(), progress, mode=True)


def _run(measurements: Measurements, model: TrackingModel, init: Initiation, settings: ParticleSettings,
         progress: Progress | None, *, mode: bool) -> TrackResult:
    name = "map" if mode else "particle"
    check_channels(model.observation, measurements)
    t_begin = time.perf_counter()
    rng = np.random.default_rng(settings.seed)
    n_particles = settings.particles(model.dim)
    post, rate = _window_posterior(measurements, model, init, settings, rng)
    _, stream = split_window(measurements, init.t_end)
    events: list[Event] = []
    gate = NISGate(settings.gate_probability, events, label=pair_labels(model.observation))
    rates = [rate]
    scans = stream.scans()
    start_task(progress, name, len(scans))
    # with calibration offsets integrated out the mean is pulled along the offsets' ridge by the prior (module
    # docstring of run_map): the mode throughout
    skewed_mean = isinstance(settings, MapSettings) and settings.posterior_mean and post.offsets is None
    rescue = rng if settings.rescues(model.dim) else None
    # the particle estimator climbs to the mode only to see whether its particles have missed it, and reports the mean
    reader = (_ModeReadOut(post, events, skewed_mean=skewed_mean, rescue=rescue, read_mode=mode)
              if mode or rescue is not None else None)

    def report(t: float) -> tuple[FloatArray, FloatArray]:
        return post.moments(t) if reader is None else reader.report(t)

    times, states, covs, loglik = [init.t_end], [], [], [0.0]
    point, cov = report(init.t_end)
    states.append(point)
    covs.append(cov)
    total = 0.0
    n_resample = n_reanchor = 0
    for k in range(len(scans)):
        sl = scans.rows(k)
        t = float(scans.times[k])
        total += _update(post, gate, t, stream.pair[sl].astype(np.intp), stream.doppler[sl], stream.sigma[sl])
        if post.ess() < settings.ess_threshold * n_particles:
            if post.should_reanchor(t):
                post.reanchor(t, rng)
                n_reanchor += 1
            post.resample(rng)
            # Past the first anchor the older data are a Gaussian summary and the posterior is close to
            # Gaussian: one Metropolis step per resampling restores diversity at a fifth of the cost
            # (a 2-hour, 3-pair recording otherwise spends 80 % of its time in moves).
            rates.append(post.move(settings.move_steps if post.gauss is None else 1, rng))
            n_resample += 1
        point, cov = report(t)
        times.append(t)
        states.append(point)
        covs.append(cov)
        loglik.append(total)
        advance(progress)
    mode_reader = reader if mode else None  # the particle estimator's reader (its rescue) reports the mean
    read_out, jumps = ("", []) if mode_reader is None else (mode_reader.phrase(len(times)), mode_reader.jumps)
    events.append(Event(time=times[-1], message=_summary(n_particles, rates, n_resample, n_reanchor, read_out,
                                                         jumps)))
    offsets = None
    if post.offsets is not None:
        last = None if mode_reader is None else mode_reader.last_mode
        offsets = _offsets_at_end(post, None if last is None else last[1])
        events.append(Event(time=times[-1], message="calibration offsets at the end: " + offsets.describe(pair_labels(model.observation))))
    return TrackResult(
        estimator=name,
        settings=settings,
        estimates=(Estimates.from_lists("filtered", times, states, covs),),
        reasons=(),
        events=tuple(events),
        nis=gate.as_array(),
        log_likelihood=np.array(loglik),
        iterations=n_resample,
        wall_time=time.perf_counter() - t_begin,
        offsets=offsets,
    )


class _ModeReadOut:
    """``map``'s read-out at each report: the mode (and its jumps between peaks), or the mean where skewed.

    Holds what one report leaves to the next: the previous mode (anchor time and state), the gains of the mode's
    jumps to another peak, and how many reports were read at the mean.  With ``read_mode=False`` (the particle
    estimator's rescue) it follows the mode the same way, says nothing of its jumps and reports the mean.
    """

    def __init__(self, post: _Posterior, events: list[Event], *, skewed_mean: bool,
                 rescue: np.random.Generator | None = None, read_mode: bool = True) -> None:
        self.post, self.events, self.skewed_mean, self.read_mode = post, events, skewed_mean, read_mode
        self.last_mode: tuple[float, FloatArray] | None = None
        self.jumps: list[float] = []  # log-density gains of the mode's moves to another peak
        self.means = 0
        # the run's generator where the particles are sampled again about a mode they have missed (else None)
        self.rescue = rescue
        self.limit = rescue_shortfall(post.model.n)

    def report(self, t: float) -> tuple[FloatArray, FloatArray]:
        """The estimate and covariance at ``t`` (:func:`run_map`)."""
        post = self.post
        previous = None
        if self.last_mode is not None:
            ta, xa = self.last_mode
            previous = post.model.motion.propagate(xa, post.t_anchor - ta) if ta != post.t_anchor else xa
        x_mode, gain = post.mode_and_switch(previous)
        if gain is not None and previous is not None and self.read_mode:
            self.jumps.append(gain)
            here, there = (post.model.motion.propagate(v, t - post.t_anchor) for v in (previous, x_mode))
            self.events.append(Event(time=t, message=(
                f"the mode moved to another peak of the posterior, "
                f"{float(np.linalg.norm((there - here)[:post.model.dim])):.0f} m away, "
                f"its basin more probable by a factor {_factor(gain)} (log mass +{_log_gain(gain)})")))
        self.last_mode = (post.t_anchor, x_mode)
        if self.rescue is not None:
            short = post.shortfall(x_mode)
            if short > self.limit and post.resample_about(x_mode, self.rescue):
                self.events.append(Event(time=t, message=(
                    f"{RESCUE_EVENT}: the best stood {short:.2f} below the mode in "
                    f"log density, where a sample of the posterior stays within {self.limit:.2f}; sampled again "
                    "about the mode")))
        if not self.read_mode:
            return post.moments(t)
        if self.skewed_mean and mean_is_the_better_point(*post.mean_shift(x_mode, probe_beyond=MEAN_SHIFT_FAR)):
            self.means += 1
            return post.moments(t)
        return post.spread_about(x_mode, t)

    def phrase(self, reports: int) -> str:
        """The closing event's words on the read-out, of ``reports`` reports."""
        return "; estimates at the posterior mode" + (
            f", or at its mean where the posterior is skewed ({self.means} of {reports})" if self.skewed_mean else "")


def rescue_shortfall(d: int) -> float:
    r"""The shortfall of the best particle below the mode beyond which ``map`` samples again about the mode.

    Where the posterior of the :math:`d` state dimensions is near Gaussian
    about its mode, a draw :math:`\mathbf x` of it falls short by
    :math:`s = \log\pi(\hat{\mathbf x}) - \log\pi(\mathbf x) \sim \tfrac12\chi^2_d`, and the
    best of :math:`n` independent draws falls short by more than :math:`c` with
    probability :math:`(1 - F_{\chi^2_d}(2c))^n`.  Setting that to
    :data:`RESCUE_LEVEL` (:math:`\alpha`) with :math:`n` = :data:`RESCUE_DRAWS`,

    .. math::

        c = \tfrac12 F^{-1}_{\chi^2_d}\big(1 - \alpha^{1/n}\big),

    1.68 for the plane's four dimensions and 2.67 for space's six.
    """
    return float(0.5 * chi2.ppf(1.0 - RESCUE_LEVEL ** (1.0 / RESCUE_DRAWS), d))


def rescued(result: TrackResult, t_from: float, t_to: float) -> bool:
    r"""Whether the particles of ``result`` were sampled again about a mode they had missed in :math:`[t_\mathrm{from}, t_\mathrm{to}]`.

    The interval is closed at :math:`t_\mathrm{from}`, the previous
    checkpoint or the window's end: a rescue at the run's first report, or
    at a restart's, follows the test there (or precedes every test), so the
    next one makes it.  A rescue before the test at a checkpoint is then
    counted by the next one as well, which only tests once more.

    The registry then tests the run at the checkpoint :math:`t_\mathrm{to}`
    whether or not the data since surprise it
    (:func:`~fgdoppler.estimators.restart.surprise_check`).  A rescue means the
    particles had not described the posterior, and the peak they are sampled
    about is the posterior's of the data so far, which early in a recording
    can lie in a wrong basin; the particles then sit on the best fit of the
    data they have seen, and the data that follow leave that basin too
    slowly to surprise them.  On draw 13 of ``studies/random_layouts_3d.py``
    (60 s) ``particle``'s rescue at 4.5 s took its particles to a peak 104.5
    higher in log density than their best, 9 km from the truth, where they
    stayed (RMS error 8,521 m; 4,765 m without the rescue, whose particles
    the check at 7 s restarted); tested at 7 s, it restarts there and ends
    at 5,983 m.  No other of 40 draws, at 60 s or 30 s, moved, for ``map``
    none (``python studies/particle_anchor_3d.py --draws 40``).
    """
    return any(t_from - 1e-9 <= ev.time <= t_to + 1e-9 and ev.message.startswith(RESCUE_EVENT)
               for ev in result.events)


def _offsets_at_end(post: _Posterior, x_mode: FloatArray | None) -> OffsetEstimate:
    r"""The offsets' posterior after the last scan: mean and covariance, or their value at the mode and the second moment.

    Given each particle's state the offsets are :math:`N(\hat{\mathbf b}_i, \boldsymbol\Lambda^{-1})`, so over
    the particles their mean is :math:`\sum_i w_i\hat{\mathbf b}_i` and their second moment about a centre
    :math:`\mathbf c` is :math:`\boldsymbol\Lambda^{-1} + \sum_i w_i(\hat{\mathbf b}_i - \mathbf c)(\cdot)^\top`.
    With ``x_mode`` (the filtered MAP's anchor state) the centre is :math:`\hat{\mathbf b}` at the mode.
    """
    off = post.offsets
    assert off is not None
    b, cov = off.posterior(post.x, post.s, post.a)
    w = post.weights()
    if x_mode is None:
        centre = w @ b
    else:
        d = post.data
        _, s_mode = post.loglik_and_sums(x_mode[None], d.t, d.pair, d.z, d.sigma)
        centre = off.posterior(x_mode[None], s_mode, post.a)[0][0]
    return OffsetEstimate(pairs=np.flatnonzero(off.channel >= 0).astype(np.int64), values=np.asarray(centre, dtype=float),
                          covariance=cov + _weighted_cov(b, w, centre=centre))


def mean_is_the_better_point(w: float, ratio: float) -> bool:
    r"""Whether ``map`` reports the posterior mean rather than the mode (module docstring of :func:`run_map`).

    ``w`` and ``ratio`` are :meth:`~fgdoppler.estimators.particle_posterior._Posterior.mean_shift`'s: the mean's
    squared Mahalanobis distance from the mode in the Laplace covariance, and the curvature probe's ratio.  The
    mean, where it lies beyond the particles' Monte Carlo scatter about a Gaussian posterior's mode
    (:data:`MEAN_SHIFT_NOISE`) and either within one standard deviation of the mode (:data:`MEAN_SHIFT_FAR`) or
    in a valley that stays near-quadratic three standard deviations out (the smoother's
    :data:`~fgdoppler.estimators.spread.SAMPLING_LIMIT`): a skewed, lopsided valley.  Where the valley bends
    and the mean lies farther, the mean sits inside the curve, off the ridge of high likelihood, and the mode
    is the better point.
    """
    return w > MEAN_SHIFT_NOISE and (w <= MEAN_SHIFT_FAR or ratio <= SAMPLING_LIMIT)


def _summary(n_particles: int, rates: list[float], n_resample: int, n_reanchor: int, read_out: str,
             jumps: list[float]) -> str:
    """The run's closing event: particles, moves, acceptance, re-anchorings, ``read_out`` and the mode's jumps."""
    finite = [r for r in rates if np.isfinite(r)]
    return (f"{n_particles} particles, {n_resample} resample-move steps, mean Metropolis acceptance "
            f"{np.mean(finite) if finite else float('nan'):.2f}"
            + (f"; {n_reanchor} re-anchoring(s), the older data summarised by a Gaussian each time" if n_reanchor
               else "")
            + read_out
            + (f"; the mode moved to another peak {len(jumps)} time(s), the closest call a factor "
               f"{_factor(min(jumps))} in probability" if jumps else ""))


def _update(post: _Posterior, gate: NISGate, t: float, pair: NDArray[np.intp], z: FloatArray,
            sigma: FloatArray) -> float:
    """Gate and apply one scan; returns the log predictive likelihood of the accepted measurements."""
    tr = np.full(pair.size, t - post.t_anchor)
    h = predict_along(post.model.observation, post.x, tr, pair)
    off = post.offsets
    if off is not None:  # each particle predicts with its offsets' conditional mean, and their variance adds
        b, b_cov = off.posterior(post.x, post.s, post.a)
        col = off.channel[pair]
        uncertain = col >= 0  # a calibrated pair (-1) has no offset
        h_pred = h + np.where(uncertain, b[:, np.maximum(col, 0)], 0.0)
        var_b: FloatArray | float = np.where(uncertain, np.diag(b_cov)[np.maximum(col, 0)], 0.0)
    else:
        h_pred, var_b = h, 0.0
    w = post.weights()
    ok = np.all(np.isfinite(h), axis=1)
    wk = np.where(ok, w, 0.0)
    wk = wk / max(float(np.sum(wk)), 1e-300)
    hm = wk @ np.where(ok[:, None], h_pred, 0.0)
    hv = wk @ (np.where(ok[:, None], h_pred, hm) - hm) ** 2
    nis = (z - hm) ** 2 / (hv + var_b + sigma**2)
    keep = np.array([gate.accept(t, int(c), float(v)) for c, v in zip(pair, nis, strict=True)], dtype=bool)
    if not np.any(keep):
        return 0.0
    r = (z[keep] - h[:, keep]) / sigma[keep]
    with np.errstate(invalid="ignore"):
        ll = -0.5 * huber_rho(r, post.settings.huber_k).sum(axis=1)
    norm = float(np.sum(np.log(sigma[keep] * np.sqrt(2 * np.pi))))
    if off is not None:  # the offsets' terms before and after these measurements
        E = off.incidence(pair[keep], sigma[keep])
        s_new = post.s + np.where(np.isfinite(r), r, 0.0) @ E
        a_new = post.a + np.sum(E * E, axis=0)
        with np.errstate(invalid="ignore"):
            ll = ll + off.extra(post.x, s_new, a_new) - off.extra(post.x, post.s, post.a)
        norm -= off.log_det(a_new) - off.log_det(post.a)
        post.s, post.a = s_new, a_new
    ll = np.where(np.isfinite(ll), ll, -np.inf)
    before = log_sum_exp(post.logw)
    post.logw = post.logw + ll
    post.logpost = post.logpost + ll
    post.data.add(tr[keep], pair[keep], z[keep], sigma[keep])
    return float(log_sum_exp(post.logw) - before) - norm


def _small_gain_places(log_gain: float) -> int:
    """Decimal places down to a gain's first significant digit where it is below 0.01 (else 0)."""
    return math.ceil(-math.log10(log_gain)) if 0.0 < log_gain < 1e-2 else 0


def _factor(log_gain: float) -> str:
    """:math:`e^g` as text, also where it overflows a float (a mode switch across a gain of thousands).

    Three significant digits, and as many more as it takes to show a small gain's excess over 1 (a gain of
    4e-4 is ``1.0004``, not ``1``: the mode moved for a probability that is larger, if barely).
    """
    decimal = log_gain / math.log(10.0)
    if decimal >= 300.0:
        return f"10^{decimal:.0f}"
    places = _small_gain_places(log_gain)
    return f"{math.exp(log_gain):.{2 + places if places else 3}g}"


def _log_gain(log_gain: float) -> str:
    """A positive log gain as text: two decimals, or to its first significant digit below 0.01 (``0.0004``, not
    ``0.00``)."""
    return f"{log_gain:.{_small_gain_places(log_gain) or 2}f}"
