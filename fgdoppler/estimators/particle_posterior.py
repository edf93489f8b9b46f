r"""The particle estimator's posterior: weighted samples of the anchor state and the target they follow.

The samples are of the state :math:`\mathbf x_a` at an anchor time
:math:`t_a`; after the measurements :math:`z_{1:k}` since the anchor their
target is

.. math::

    \pi_k(\mathbf x_a) \propto p(\mathbf x_a)\,
        \exp\!\Big(-\tfrac12\sum_{j\le k}\rho\big((z_j - h_j(\mathbf F(t_j - t_a)\mathbf x_a))/\sigma_j\big)\Big),

with :math:`\rho` the squared or Huber loss and :math:`p(\mathbf x_a)` the
zone (and the initiation's half plane) as support times the model's weak
prior, or after a re-anchoring the moment-matched Gaussian of the older
data.  ``_Posterior`` holds the samples, their weights and log-posteriors,
and the operations of iterated batch importance sampling on them: the
tempered start from a Gaussian mixture (``sample_from``), reweighting,
systematic resampling, random-walk Metropolis moves per cluster, the
re-anchoring test and step, the moments, and the climb to the posterior's
mode.  :mod:`fgdoppler.estimators.particle` runs them over a recording
(the algorithm, the re-anchoring rule and the calibration offsets are
described there); :mod:`fgdoppler.estimators.window_posterior` samples the
initiation window with them, and :mod:`fgdoppler.estimators.spread` samples
a smoothed track's posterior.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.curvature import probe_rises
from fgdoppler.estimators.grid import HalfPlane
from fgdoppler.estimators.log_sum_exp import log_sum_exp
from fgdoppler.estimators.offset_posterior import OffsetPrior
from fgdoppler.estimators.settings import ParticleSettings
from fgdoppler.models.observation import predict_along
from fgdoppler.models.robust import huber_rho, huber_weights
from fgdoppler.models.tracking import TrackingModel

__all__: list[str] = []

FloatArray = NDArray[np.float64]

#: (Particle, measurement) entries of the likelihood evaluated at once: bounds the memory of a move and keeps
#: its arrays small.
CHUNK_ROWS = 1 << 15
#: Smallest tempering step of the start (:meth:`_Posterior.sample_from`): at most 100 stages.
MIN_TEMPER_STEP = 0.01
#: Random-walk Metropolis scale per state dimension (Roberts, Gelman & Gilks: 2.38²/d for d unknowns).
RW_SCALE_NUMERATOR = 2.38**2
#: Levenberg–Marquardt iterations of one climb to the posterior mode (:meth:`_Posterior.mode`); a climb from the
#: previous scan's mode usually ends after one to three.
MODE_ITERATIONS = 30
#: Damping increases tried per iteration before a climb gives up.
MODE_DAMPING_TRIES = 12
#: A climb stops when a step raises the log posterior by less than this (then it lies about
#: :math:`\sqrt{2\cdot 10^{-6}}` ≈ 0.0014 standard deviations from the optimum).
MODE_TOLERANCE = 1e-6
#: Draws of a peak's Laplace Gaussian that measure the share of it inside the prior's support
#: (:meth:`_Posterior.basin_log_mass`; as many as the initiation's evidence takes).
BASIN_DRAWS = 4096


@dataclass
class _Data:
    """The measurements since the anchor (times relative to it)."""

    t: FloatArray
    pair: NDArray[np.intp]
    z: FloatArray
    sigma: FloatArray

    def add(self, t: FloatArray, pair: NDArray[np.intp], z: FloatArray, sigma: FloatArray) -> None:
        self.t = np.concatenate([self.t, t])
        self.pair = np.concatenate([self.pair, pair])
        self.z = np.concatenate([self.z, z])
        self.sigma = np.concatenate([self.sigma, sigma])


class _Posterior:
    """The particles of :math:`\\mathbf x_a`, their weights and log-posteriors, and the target they follow."""

    def __init__(self, model: TrackingModel, settings: ParticleSettings, t_anchor: float, data: _Data, *,
                 half_plane: HalfPlane | None = None) -> None:
        self.model = model
        self.half_plane = half_plane  # the start's side, given by the user: part of the prior's support
        self.settings = settings
        self.t_anchor = t_anchor
        self.data = data
        self.gauss: tuple[FloatArray, FloatArray] | None = None  # moment-matched prior after re-anchoring
        self.x = np.empty((0, model.n))
        self.logw = np.empty(0)
        self.logpost = np.empty(0)
        self.label = np.empty(0, dtype=np.intp)
        # Kish's effective sample size of the last one-step importance draw (sample_from with tempered=False)
        self.proposal_ess = float("nan")
        # calibration offsets integrated out (None: calibrated): each particle's per-pair statistics s and the
        # data's information a since the anchor (:mod:`fgdoppler.estimators.offset_posterior`)
        self.offsets = OffsetPrior.independent(settings.bias_sigma, model.observation.n_channels, model.n)
        n_off = 0 if self.offsets is None else self.offsets.size
        self.s = np.empty((0, n_off))
        self.a = np.zeros(n_off) if self.offsets is None else self._info(data.pair, data.sigma)
        # the information at the ends of the last climbs (:meth:`_information`), with what it was computed from
        self._peaks: list[_PeakInformation] = []

    def _info(self, pair: NDArray[np.intp], sigma: FloatArray) -> FloatArray:
        """The offsets' information :math:`a_p` of the given measurements."""
        assert self.offsets is not None
        E = self.offsets.incidence(pair, sigma)
        return np.asarray(np.sum(E * E, axis=0), dtype=float)

    # -- target -------------------------------------------------------------------------
    def log_prior(self, x: FloatArray, *, bounded: bool = True) -> FloatArray:
        """The prior's log density of every row of ``x``: its Gaussian terms, ``-inf`` off the support unless not
        ``bounded`` (then the Gaussian terms alone, as if the zone had no walls)."""
        if self.gauss is not None:
            m, Li = self.gauss
            e = (x - m) @ Li.T
            return -0.5 * np.einsum("ij,ij->i", e, e)
        out = np.where(self.supported(x) | (not bounded), 0.0, -np.inf)
        prior = self.model.prior()
        if prior is not None:
            Li = np.linalg.inv(np.linalg.cholesky(prior[1]))
            e = (x - prior[0]) @ Li.T
            out -= 0.5 * np.einsum("ij,ij->i", e, e)
        return out

    def supported(self, x: FloatArray) -> NDArray[np.bool_]:
        """Whether each anchor state lies in the first anchor's prior support (the zone, the half plane)."""
        ok = np.ones(x.shape[0], dtype=bool)
        if self.gauss is not None:  # after a re-anchoring the prior is the Gaussian summary alone
            return ok
        if self.model.zone is not None:
            ok &= self.model.zone.contains(x)
        if self.half_plane is not None:
            ok &= self.half_plane.contains(x)
        return ok

    def loglik(self, x: FloatArray, t: FloatArray, pair: NDArray[np.intp], z: FloatArray,
               sigma: FloatArray) -> FloatArray:
        """:math:`-\\tfrac12\\sum\\rho` of the given measurements for every row of ``x`` (``-inf`` if undefined)."""
        return self.loglik_and_sums(x, t, pair, z, sigma)[0]

    def loglik_and_sums(self, x: FloatArray, t: FloatArray, pair: NDArray[np.intp], z: FloatArray,
                        sigma: FloatArray) -> tuple[FloatArray, FloatArray]:
        r""":meth:`loglik`, and with offsets their statistics :math:`\mathbf s` ``(N, P)`` for every row of ``x``.

        :math:`s_p = \sum_{j\in p}(z_j - h_j)/\sigma_j^2` (:mod:`fgdoppler.estimators.offset_posterior`;
        ``(N, 0)`` without offsets).  The offsets' own terms are not added here.
        """
        out = np.empty(x.shape[0])
        E = None if self.offsets is None else self.offsets.incidence(pair, sigma)
        sums = np.zeros((x.shape[0], 0 if E is None else E.shape[1]))
        step = max(1, CHUNK_ROWS // max(t.size, 1))
        for a in range(0, x.shape[0], step):
            h = predict_along(self.model.observation, x[a:a + step], t, pair)
            r = (z - h) / sigma
            with np.errstate(invalid="ignore"):
                ll = -0.5 * huber_rho(r, self.settings.huber_k).sum(axis=1)
            out[a:a + step] = np.where(np.isfinite(ll), ll, -np.inf)
            if E is not None:
                sums[a:a + step] = np.where(np.isfinite(r), r, 0.0) @ E
        return out, sums

    def log_target(self, x: FloatArray, *, bounded: bool = True) -> FloatArray:
        return self.log_target_and_stats(x, bounded=bounded)[0]

    def log_target_and_stats(self, x: FloatArray, *, bounded: bool = True) -> tuple[FloatArray, FloatArray]:
        r"""The log target of every row of ``x`` and, with offsets, their statistics :math:`\mathbf s` ``(N, P)``.

        Not ``bounded``: without the prior's support (:meth:`log_prior`).
        """
        lp = self.log_prior(x, bounded=bounded)
        ok = np.isfinite(lp)
        out = np.full(x.shape[0], -np.inf)
        s = np.zeros((x.shape[0], self.s.shape[1]))
        if np.any(ok):
            d = self.data
            ll, s[ok] = self.loglik_and_sums(x[ok], d.t, d.pair, d.z, d.sigma)
            out[ok] = lp[ok] + ll
            if self.offsets is not None:
                out[ok] += self.offsets.extra(x[ok], s[ok], self.a)
        return out, s

    # -- particle operations -------------------------------------------------------------
    def sample_from(self, comps: list[tuple[FloatArray, FloatArray]], n: int, moves: int,
                    rng: np.random.Generator, *, tempered: bool = True) -> float | None:
        r"""Sample the target by adaptive tempering from an equal-weight Gaussian mixture, then move.

        The proposal :math:`q` is the mixture with each covariance inflated
        4× (doubled standard deviations: it must cover a valley's
        curvature).  ``n`` draws of :math:`q` on the target's support are
        carried through the tempered targets
        :math:`\pi_\beta \propto q^{1-\beta}\,\pi^{\beta}`,
        :math:`0 = \beta_0 < \beta_1 < \dots < \beta_m = 1`: each next
        :math:`\beta` is the largest whose incremental weights
        :math:`\exp\big((\beta_{j+1} - \beta_j)(\log\pi - \log q)\big)`
        keep the effective sample size at ``ess_threshold`` × ``n``
        (bisection), after which the particles are resampled and moved by
        ``move_steps`` Metropolis steps on :math:`\pi_{\beta_{j+1}}`
        (sequential Monte Carlo samplers, Del Moral, Doucet & Jasra 2006).
        Then ``moves`` steps on :math:`\pi`.  Importance sampling from
        :math:`q` in one step left an effective sample size of 15–100 of
        4,096 on the paper's windows, and with sensors on one line it put
        all the mass on one of two mirror modes of equal mass.
        ``tempered=False`` keeps that one step (importance weights
        :math:`\pi/q`, resampled; their effective sample size is left in
        ``proposal_ess``).  Returns the last moves' acceptance rate,
        or ``None`` when no draw has a finite posterior (the particles are
        then left unchanged).
        """
        inflate = 4.0
        chols = np.array([_safe_cholesky(inflate * P, inflate * P) for _, P in comps])
        means = np.array([m for m, _ in comps])
        k = len(comps)
        half_logdet = np.array([np.sum(np.log(np.diag(c))) for c in chols])

        def log_q(y: FloatArray) -> FloatArray:
            logq = np.empty((k, y.shape[0]))
            for c in range(k):
                sol = np.linalg.solve(chols[c], (y - means[c]).T).T
                logq[c] = -0.5 * np.sum(sol * sol, axis=1) - half_logdet[c]
            return np.asarray(log_sum_exp(logq, axis=0), dtype=float)

        label = rng.integers(0, k, n)
        x = means[label] + np.einsum("nij,nj->ni", chols[label], rng.standard_normal((n, means.shape[1])))
        logpost, s = self.log_target_and_stats(x)
        if not np.any(np.isfinite(logpost)):
            return None
        self.x, self.label, self.logpost, self.s = x, label, logpost, s
        if not tempered:
            self.logw = logpost - log_q(x)
            self.proposal_ess = self.ess()
            self.resample(rng)
            return self.move(moves, rng)
        self.logw = np.where(np.isfinite(logpost), 0.0, -np.inf)
        self.resample(rng)  # q on the target's support
        lq = log_q(self.x)
        beta = 0.0
        while beta < 1.0:
            delta = self.logpost - lq
            nxt = _next_temperature(delta, beta, self.settings.ess_threshold * n)
            self.logw = (nxt - beta) * delta
            beta = nxt
            lq = lq[self.resample(rng)]
            self.move(self.settings.move_steps, rng, tempering=(beta, log_q, lq))
        return self.move(moves, rng)

    def weights(self) -> FloatArray:
        return np.exp(self.logw - log_sum_exp(self.logw))

    def ess(self) -> float:
        w = self.weights()
        return float(1.0 / np.sum(w * w))

    def resample(self, rng: np.random.Generator) -> NDArray[np.intp]:
        """Systematic resampling to equal weights; returns the indices drawn."""
        n = self.x.shape[0]
        c = np.cumsum(self.weights())
        c[-1] = 1.0
        idx = np.searchsorted(c, (rng.random() + np.arange(n)) / n)
        self.x, self.logpost, self.label, self.s = self.x[idx], self.logpost[idx], self.label[idx], self.s[idx]
        self.logw = np.zeros(n)
        return idx

    def move(self, steps: int, rng: np.random.Generator, *,
             tempering: tuple[float, Callable[[FloatArray], FloatArray], FloatArray] | None = None) -> float:
        r"""Random-walk Metropolis on the target, each cluster with its own covariance; mean acceptance.

        ``tempering = (β, log q, log q of the particles)`` targets
        :math:`q^{1-\beta}\pi^\beta` instead (:meth:`sample_from`); the
        last array is updated in place.
        """
        if steps == 0:
            return float("nan")
        chol = self._cluster_chol()
        scale = RW_SCALE_NUMERATOR / self.model.n
        accepted = []
        for _ in range(steps):
            eps = rng.standard_normal(self.x.shape)
            prop = self.x + np.sqrt(scale) * np.einsum("nij,nj->ni", chol[self.label], eps)
            lt, s_prop = self.log_target_and_stats(prop)
            if tempering is None:
                ratio = lt - self.logpost
            else:
                beta, log_q, lq = tempering
                lq_prop = log_q(prop)
                with np.errstate(invalid="ignore"):  # -inf - -inf where both lie off the support
                    ratio = beta * (lt - self.logpost) + (1.0 - beta) * (lq_prop - lq)
            accept = np.log(rng.random(self.x.shape[0])) < ratio
            self.x[accept], self.logpost[accept], self.s[accept] = prop[accept], lt[accept], s_prop[accept]
            if tempering is not None:
                lq[accept] = lq_prop[accept]
            rate = float(np.mean(accept))
            accepted.append(rate)
            # keep the acceptance in the efficient range (a curved valley wants smaller steps)
            scale *= 0.5 if rate < 0.15 else (1.5 if rate > 0.5 else 1.0)
        return float(np.mean(accepted))

    def _cluster_chol(self) -> FloatArray:
        """Cholesky factor per cluster label ``(n_labels, n, n)`` of the particles' covariance in it."""
        n_labels = int(self.label.max()) + 1
        out = np.empty((n_labels, self.model.n, self.model.n))
        w = self.weights()
        everyone = _weighted_cov(self.x, w)
        for k in range(n_labels):
            sel = self.label == k
            cov = _weighted_cov(self.x[sel], w[sel]) if np.count_nonzero(sel) >= 20 else everyone
            out[k] = _safe_cholesky(cov, everyone)
        return out

    def moments(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Mean and covariance of the state at ``t``."""
        m = self.model.motion
        dt = t - self.t_anchor
        xs = m.propagate(self.x, dt) if dt != 0 else self.x
        w = self.weights()
        mean = w @ xs
        cov = _weighted_cov(xs, w)
        if dt > 0:
            cov = cov + m.Q(dt)
        return mean, cov

    def noise_share(self, t: float) -> float:
        r"""How much process noise the likelihood since the anchor leaves out: :math:`\lambda_{\max}`.

        The particles follow the track :math:`\mathbf F(t - t_a)\mathbf x_a`
        without the noise the motion model adds over the span, whose
        covariance is :math:`\mathbf Q(t - t_a)`.  Measured against the
        particles' own covariance at :math:`t`, :math:`\mathbf P_t = \mathbf L\mathbf L^\top`
        (without that noise), the share is the largest eigenvalue of
        :math:`\mathbf L^{-1}\mathbf Q(t - t_a)\mathbf L^{-\top}`, the largest
        generalised eigenvalue of :math:`(\mathbf Q, \mathbf P_t)`: the
        variance the noise adds, as a fraction of the posterior's variance,
        in the direction where that fraction is largest.
        """
        m = self.model.motion
        dt = t - self.t_anchor
        if dt <= 0:
            return 0.0
        Li = np.linalg.inv(_scaled_cholesky(_weighted_cov(m.propagate(self.x, dt), self.weights())))
        return float(np.max(np.linalg.eigvalsh(Li @ m.Q(dt) @ Li.T)))

    def misfit(self) -> float:
        r"""How far the particles' target is from the Gaussian of their moments: :math:`\operatorname{Var}_\pi[r]`.

        With :math:`\boldsymbol\mu`, :math:`\mathbf P` the particles'
        weighted mean and covariance and :math:`d_i^2` each particle's squared
        Mahalanobis distance from them,
        :math:`r_i = \log\pi(\mathbf x_i) + \tfrac12 d_i^2` is the log ratio of
        the target to that Gaussian up to a constant, so its weighted variance
        is 0 for a Gaussian target and, for a small departure, twice the
        Kullback–Leibler divergence :math:`\mathrm{KL}(\pi\,\|\,N(\boldsymbol\mu, \mathbf P))`:
        what a re-anchoring's Gaussian summary would lose.
        """
        w = self.weights()
        ok = np.isfinite(self.logpost) & (w > 0)
        w = w[ok] / np.sum(w[ok])
        x = self.x[ok]
        z = np.linalg.solve(_scaled_cholesky(_weighted_cov(x, w)), (x - w @ x).T).T
        r = self.logpost[ok] + 0.5 * np.sum(z * z, axis=1)
        return float(w @ (r - w @ r) ** 2)

    def should_reanchor(self, t: float) -> bool:
        r"""Whether to move the anchor to ``t`` (module docstring, "Re-anchoring").

        After ``max_span`` seconds (the moves' cost); before that when the
        process noise the likelihood leaves out exceeds ``max_noise_share``
        (:meth:`noise_share`, :math:`\lambda`) and costs more than a Gaussian
        summary would: :math:`\lambda^2/4 \ge \operatorname{Var}_\pi[r]/2`
        (:meth:`misfit`), the two Kullback–Leibler divergences to second
        order — of :math:`N(0, 1+\lambda)` from :math:`N(0, 1)` along the
        direction the noise affects most, and of the Gaussian summary from
        the particles' target.  So a curved or multimodal posterior keeps
        its anchor while the noise left out is small against its spread.
        """
        st = self.settings
        if t - self.t_anchor > st.max_span:
            return True
        share = self.noise_share(t)
        return share > st.max_noise_share and share**2 >= 2.0 * self.misfit()

    def spread_about(self, x_anchor: FloatArray, t: float) -> tuple[FloatArray, FloatArray]:
        r"""The state at ``t`` of the track from anchor state ``x_anchor``, and the particles' second moment about it.

        :math:`\hat{\mathbf x}_t = \mathbf F(t - t_a)\,\mathbf x_a` and
        :math:`\sum_i w_i(\mathbf x_{i,t} - \hat{\mathbf x}_t)(\mathbf x_{i,t} - \hat{\mathbf x}_t)^\top
        + \mathbf Q(t - t_a)`: the posterior mean-square error of reporting :math:`\hat{\mathbf x}_t`, which is
        the posterior covariance plus the outer product of the point's distance from the posterior mean.
        """
        m = self.model.motion
        dt = t - self.t_anchor
        xs = m.propagate(self.x, dt) if dt != 0 else self.x
        point = m.propagate(x_anchor, dt) if dt != 0 else np.array(x_anchor, dtype=float)
        cov = _weighted_cov(xs, self.weights(), centre=point)
        if dt > 0:
            cov = cov + m.Q(dt)
        return point, cov

    def mode(self, previous: FloatArray | None = None) -> FloatArray:
        r"""The posterior mode (an anchor state) by Levenberg–Marquardt, warm-started from ``previous``.

        Each climb minimises :math:`-\log\pi_k`: Gauss–Newton on the
        whitened residuals :math:`r_j = (h_j(\mathbf F(t_j - t_a)\mathbf x) - z_j)/\sigma_j`
        (rows :func:`_along_jacobian`, Huber by its IRLS weights) and the
        prior's quadratic term, each step damped by
        :math:`\lambda\,\mathrm{diag}(\mathbf A)` and kept only if it raises
        :math:`\log\pi_k` itself — so a step off the prior's support (the zone,
        the half plane: both convex) is never kept.  Stops when a step gains
        less than :data:`MODE_TOLERANCE` or after :data:`MODE_ITERATIONS`.

        The climb from ``previous`` (the last report's mode, which the new data
        move a little) ends on a local maximum of value :math:`v`; a particle
        standing higher than :math:`v` lies in another basin, and only then is
        a second climb run from the highest particle.  Its end is kept if it
        stands higher and its basin holds more of the posterior
        (:meth:`basin_log_mass`): a narrow peak at the zone's edge can top the
        broad one that holds nearly all the particles.  Without ``previous``
        (the first report) there is no basin to keep to: one climb starts from
        the highest particle and one from the particles' weighted mean, which
        lies where most of the posterior is; where they end on different peaks
        (more than a standard deviation of the first one's Laplace covariance
        apart) the one whose basin holds more of the posterior is kept,
        whichever stands higher.
        """
        return self.mode_and_switch(previous)[0]

    def mode_and_switch(self, previous: FloatArray | None = None) -> tuple[FloatArray, float | None]:
        r""":meth:`mode`, and by how much more of the posterior the new basin holds when the mode left ``previous``'s.

        The second element is ``None`` when the mode stayed in the basin of
        ``previous`` (or there was none); otherwise the gain
        :math:`\log Z_\text{new} - \log Z_\text{old}` of the basins' masses
        (:meth:`basin_log_mass`; their peaks' log densities where a mass is
        undefined), so :math:`e^{\text{gain}}` is how much more probable the
        new basin is: a small gain means two peaks the data barely tell apart.
        """
        best = np.array(self.x[int(np.argmax(self.logpost))], dtype=float)
        if previous is None:
            # no basin to keep to yet: the highest particle's, or that of the particles' mean if it holds more
            x, value = self._climb(best)
            y, other = self._climb(np.asarray(self.weights() @ self.x, dtype=float))
            if self._same_peak(x, y):
                return x, None
            return (y if self._log_mass_gain(x, value, y, other) > 0.0 else x), None
        x, value = self._climb(np.array(previous, dtype=float))
        if float(np.max(self.logpost)) > value:
            y, other = self._climb(best)
            if other > value:
                gain = self._log_mass_gain(x, value, y, other)
                if gain > 0.0:
                    return y, gain
        return x, None

    def shortfall(self, x_mode: FloatArray) -> float:
        r"""How far every particle falls short of the mode: :math:`\log\pi_k(\hat{\mathbf x}) - \max_i \log\pi_k(\mathbf x_i)`.

        A sample of a posterior near Gaussian about its mode has
        :math:`2(\log\pi_k(\hat{\mathbf x}) - \log\pi_k(\mathbf x_i)) \sim \chi^2_d`, so its best
        particle stands close to the mode; a large shortfall says the particles
        sit away from the posterior's peak (:meth:`resample_about`).
        """
        finite = self.logpost[np.isfinite(self.logpost)]
        if finite.size == 0:
            return np.inf
        x = np.asarray(x_mode, dtype=float)
        # a report's mode is the end of the climb just made, whose value is kept: no second evaluation
        value = next((peak.value for peak in self._peaks if peak.holds(self, x)), None)
        if value is None:
            value = float(self.log_target(x[None])[0])
        return float(value - np.max(finite))

    def resample_about(self, x_mode: FloatArray, rng: np.random.Generator) -> bool:
        r"""Sample the target again from the mode's Laplace Gaussian and the particles' own: ``True`` if done.

        The tempered draw of :meth:`sample_from` from the equal-weight mixture
        of :math:`N(\hat{\mathbf x}, (\mathbf A^{-1})_{xx})` at the mode
        (:meth:`_state_laplace`) and the particles' weighted mean and
        covariance, with as many particles and ``move_steps`` moves: it keeps
        whatever mass the particles held and adds the peak they had missed.
        ``False`` (the particles unchanged) where the mode's information is
        singular or no draw has a finite posterior.
        """
        laplace = self._state_laplace(np.asarray(x_mode, dtype=float))
        if laplace is None:
            return False
        w = self.weights()
        comps = [(np.asarray(x_mode, dtype=float), laplace[0]), (w @ self.x, _weighted_cov(self.x, w))]
        return self.sample_from(comps, self.x.shape[0], self.settings.move_steps, rng) is not None

    def _same_peak(self, x: FloatArray, y: FloatArray) -> bool:
        """Whether two climbs ended on one peak: within a standard deviation of its Laplace covariance at ``x``."""
        laplace = self._state_laplace(x)
        if laplace is None:
            return bool(np.array_equal(x, y))
        d = y - x
        return float(d @ laplace[1] @ d) <= 1.0

    def _log_mass_gain(self, x: FloatArray, value: float, y: FloatArray, other: float) -> float:
        """How much more of the posterior the basin of the peak ``y`` holds than that of ``x`` (log; densities if undefined)."""
        if not np.isfinite(other):
            return -np.inf
        if not np.isfinite(value):
            return np.inf
        here, there = self.basin_log_mass(x, value), self.basin_log_mass(y, other)
        return other - value if here is None or there is None else there - here

    def basin_log_mass(self, x_peak: FloatArray, value: float) -> float | None:
        r"""The log of the posterior's mass in the basin of the peak ``x_peak`` (Laplace), up to a shared constant.

        With :math:`v = \log\pi_k(\hat{\mathbf x})` (``value``) and the
        Gauss–Newton information :math:`\mathbf A` there (:meth:`mean_shift`),

        .. math::

            \log Z \approx v - \tfrac12\log\det\mathbf A
            + \log\Pr_{\mathbf x\sim\mathcal N(\hat{\mathbf x},\,(\mathbf A^{-1})_{xx})}
              [\mathbf x \in \text{support}],

        the last term from :data:`BASIN_DRAWS` draws (at least half a draw):
        what the zone's walls leave of the basin, as in the initiation's
        evidence (:func:`~fgdoppler.estimators.initiation.window_log_evidence`).
        A narrow peak can stand higher than a broad one and yet hold far less
        of the posterior.  ``None`` where the information is singular.
        """
        A = self._information(x_peak)
        if A is None:
            return None
        sign, logdet = np.linalg.slogdet(A)
        if sign <= 0:
            return None
        n = x_peak.size
        C = np.linalg.inv(A)[:n, :n]
        try:
            L = np.linalg.cholesky(0.5 * (C + C.T))
        except np.linalg.LinAlgError:
            return None
        draws = x_peak + np.random.default_rng(0).standard_normal((BASIN_DRAWS, n)) @ L.T
        share = max(float(np.mean(self.supported(draws))), 0.5 / BASIN_DRAWS)
        return float(value - 0.5 * logdet + np.log(share))

    def _state_laplace(self, x: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        r"""The state's Laplace covariance :math:`(\mathbf A^{-1})_{xx}` at ``x`` and its inverse (offsets profiled out).

        ``None`` off the support or where :math:`\mathbf A` (:meth:`_information`) is singular.
        """
        A = self._information(x)
        if A is None:
            return None
        try:
            P = np.asarray(np.linalg.inv(A)[:x.size, :x.size], dtype=float)
            return P, np.asarray(np.linalg.inv(P), dtype=float)
        except np.linalg.LinAlgError:
            return None

    def _information(self, x: FloatArray) -> FloatArray | None:
        r""":math:`\mathbf A = \mathbf J^\top\mathbf W\mathbf J` + the prior's quadratic term at ``x`` (joint with offsets).

        ``None`` off the support.  At the end of one of the last two climbs
        (:meth:`_climb`), with the same data, prior and offsets, it is that
        climb's last linearisation, not a new one: a report asks for the
        information at its mode once or twice (:meth:`mean_shift`,
        :meth:`basin_log_mass`, :meth:`_same_peak`) right after climbing there.
        """
        for peak in self._peaks:
            if peak.holds(self, x):
                return None if peak.A is None else peak.A.copy()
        quad = self._prior_quadratic()
        value, r, Jw = self._linearised(x, quad)
        return self._information_from(x, value, r, Jw, quad)

    def _information_from(self, x: FloatArray, value: float, r: FloatArray, Jw: FloatArray,
                          quad: tuple[FloatArray, FloatArray] | None) -> FloatArray | None:
        """:meth:`_information` from a linearisation at ``x`` (:meth:`_linearised`'s value, residuals and Jacobian)."""
        if not np.isfinite(value):
            return None
        A = Jw.T @ (huber_weights(r, self.settings.huber_k)[:, None] * Jw)
        if quad is not None:
            A[:x.size, :x.size] += quad[1].T @ quad[1]
        return np.asarray(A, dtype=float)

    def mean_shift(self, x_mode: FloatArray, probe_beyond: float = 0.0) -> tuple[float, float]:
        r"""How far the particles' mean lies from the mode ``x_mode``, and how the cost bends about the mode.

        With the cost :math:`c(\mathbf x) = -2\log\pi_k(\mathbf x)` and its
        Gauss–Newton information at the mode,
        :math:`\mathbf A = \mathbf J^\top\mathbf W\mathbf J` of the whitened
        residuals (Huber weights :math:`\mathbf W`) plus the prior's quadratic
        term — with calibration offsets the joint problem's, the state's
        information then being :math:`\mathbf I = ((\mathbf A^{-1})_{xx})^{-1}`,
        the offsets profiled out —, returns

        * :math:`w = \mathbf d^\top\mathbf I\,\mathbf d`, the squared
          Mahalanobis length of :math:`\mathbf d = \bar{\mathbf x} - \hat{\mathbf x}`,
          the particles' weighted mean less the mode, in the Laplace covariance
          :math:`\mathbf I^{-1}`;
        * the curvature probe's ratio
          (:func:`~fgdoppler.estimators.curvature.probe_rises`): the smaller
          cost rise three standard deviations of :math:`\mathbf I^{-1}` to
          either side of the mode along the position's major axis, over the
          quadratic model's :math:`9`; above 1 the valley bends away from the
          straight line.  The probe's cost leaves out the prior's support (the
          zone's walls and the half plane: :meth:`log_prior` not ``bounded``),
          as the smoother's probe does (:mod:`~fgdoppler.estimators.spread`):
          a wall truncates the valley, which is what the mean then corrects
          for, and says nothing of how it bends; infinite only where a side's
          track passes through a sensor.

        The probe costs five evaluations of the target; it is made only where
        :math:`w` exceeds ``probe_beyond`` (else the ratio is NaN).  ``(inf, inf)``
        where the information is singular.
        """
        x_mode = np.asarray(x_mode, dtype=float)
        laplace = self._state_laplace(x_mode)
        if laplace is None:
            return np.inf, np.inf
        P, info = laplace
        d = self.weights() @ self.x - x_mode
        w = float(d @ info @ d)

        if w <= probe_beyond:
            return w, np.nan

        def cost(x: FloatArray) -> FloatArray:
            return -2.0 * self.log_target(x, bounded=False)

        lo, hi, rise, _ = probe_rises(cost, x_mode, P, info, rows=True)
        return w, (min(lo, hi) / rise if rise > 0 else np.inf)

    def _prior_quadratic(self) -> tuple[FloatArray, FloatArray] | None:
        """``(m, L^{-1})`` of the prior's Gaussian factor (the re-anchored summary or the weak prior), if any."""
        if self.gauss is not None:
            return self.gauss
        prior = self.model.prior()
        if prior is None:
            return None
        return prior[0], np.asarray(np.linalg.inv(np.linalg.cholesky(prior[1])), dtype=float)

    def _linearised(self, x: FloatArray, quad: tuple[FloatArray, FloatArray] | None
                    ) -> tuple[float, FloatArray, FloatArray]:
        r""":math:`\log\pi_k(\mathbf x)` (``-inf`` off the support), whitened residuals and their Jacobian."""
        d = self.data
        empty = np.empty(0), np.empty((0, self.model.n))
        if not self.supported(x[None])[0]:
            return -np.inf, *empty
        try:
            h, J = _along_jacobian(self.model, x, d.t, d.pair)
        except ValueError:  # the track passes through a sensor
            return -np.inf, *empty
        r = (h - d.z) / d.sigma
        Jw = J / d.sigma[:, None]
        if self.offsets is not None:  # the joint problem in (x, b) at the offsets' conditional mode
            r, Jw = self.offsets.profile(x, r, Jw, self.offsets.incidence(d.pair, d.sigma))
        value = -0.5 * float(np.sum(huber_rho(r, self.settings.huber_k)))
        if quad is not None:
            e = quad[1] @ (x - quad[0])
            value -= 0.5 * float(e @ e)
        return (value if np.isfinite(value) else -np.inf), r, Jw

    def _climb(self, x: FloatArray) -> tuple[FloatArray, float]:
        # each trial is scored by the evaluation that also linearises there: one model call per step
        quad = self._prior_quadratic()
        value, r, Jw = self._linearised(x, quad)
        if not np.isfinite(value):
            return x, value
        lam = 1e-3
        for _ in range(MODE_ITERATIONS):
            wr = huber_weights(r, self.settings.huber_k)
            A = Jw.T @ (wr[:, None] * Jw)
            g = Jw.T @ (wr * r)
            if quad is not None:
                m, Li = quad
                n = x.size  # with offsets the offsets' columns follow the state's
                A[:n, :n] += Li.T @ Li
                g[:n] += Li.T @ (Li @ (x - m))
            D = np.diag(np.maximum(np.diag(A), 1e-12 * max(float(np.max(np.diag(A))), 1e-300)))
            gain = 0.0
            for _ in range(MODE_DAMPING_TRIES):
                try:
                    # with offsets only the state's step is taken: the trial re-profiles the offsets
                    trial = x - np.linalg.solve(A + lam * D, g)[:x.size]
                except np.linalg.LinAlgError:
                    lam *= 4.0
                    continue
                v, r_t, J_t = self._linearised(trial, quad)
                if v > value:
                    gain = v - value
                    x, value, r, Jw = trial, v, r_t, J_t
                    lam = max(lam / 3.0, 1e-9)
                    break
                lam *= 4.0
            if gain < MODE_TOLERANCE:
                break
        self._remember(x, value, self._information_from(x, value, r, Jw, quad))
        return x, value

    def _remember(self, x: FloatArray, value: float, A: FloatArray | None) -> None:
        """Keep the log posterior ``value`` and information ``A`` at a climb's end ``x`` for :meth:`_information`
        and :meth:`shortfall` (the last two climbs')."""
        self._peaks = [*self._peaks[-1:], _PeakInformation(x=x.copy(), value=value, A=A, t=self.data.t,
                                                           gauss=self.gauss, offsets=self.offsets)]

    def reanchor(self, t: float, rng: np.random.Generator) -> None:
        """Move the anchor to ``t``: propagate with process noise, summarise the older data by a Gaussian."""
        m = self.model.motion
        dt = t - self.t_anchor
        L = np.linalg.cholesky(m.Q(dt))
        x_old = self.x
        self.x = m.propagate(self.x, dt) + rng.standard_normal(self.x.shape) @ L.T
        w = self.weights()
        mean = w @ self.x
        cov = _weighted_cov(self.x, w)
        self.gauss = (mean, np.asarray(np.linalg.inv(_scaled_cholesky(cov)), dtype=float))
        if self.offsets is not None:  # the offsets' joint Gaussian with the new anchor states, conditioned on them
            self.offsets = self.offsets.reanchored(x_old, self.x, self.s, self.a, w)
            self.s = np.zeros_like(self.s)
            self.a = np.zeros_like(self.a)
        self.t_anchor = t
        self.data = _Data(t=np.empty(0), pair=np.empty(0, dtype=np.intp), z=np.empty(0), sigma=np.empty(0))
        # no data since the anchor: the offsets add nothing (OffsetPrior.extra is 0 at s = a = 0)
        self.logpost = self.log_prior(self.x)


@dataclass(frozen=True, kw_only=True)
class _PeakInformation:
    """The log posterior and information at a climb's end ``x``, and the data, prior summary and offsets they were
    computed with.

    Held by reference, so an object :meth:`_Posterior.reanchor` or :meth:`_Data.add` has replaced cannot be
    mistaken for its successor.
    """

    x: FloatArray
    value: float
    A: FloatArray | None
    t: FloatArray
    gauss: tuple[FloatArray, FloatArray] | None
    offsets: object

    def holds(self, post: _Posterior, x: FloatArray) -> bool:
        """Whether this is the information of ``post`` at ``x`` as it stands now."""
        return (post.data.t is self.t and post.gauss is self.gauss and post.offsets is self.offsets
                and bool(np.array_equal(self.x, x)))


def _next_temperature(delta: FloatArray, beta: float, target_ess: float) -> float:
    r"""The largest :math:`\beta' \in (\beta, 1]` whose weights :math:`e^{(\beta'-\beta)\delta}` keep ``target_ess``.

    The effective sample size :math:`(\sum w)^2/\sum w^2` falls
    monotonically in :math:`\beta'`; bisection to 1e-6, and a step of at
    least :data:`MIN_TEMPER_STEP`, so that the schedule ends.
    """
    def ess(b: float) -> float:
        w = np.exp((b - beta) * (delta - np.max(delta)))
        return float(np.sum(w) ** 2 / np.sum(w * w))

    if ess(1.0) >= target_ess:
        return 1.0
    lo, hi = beta, 1.0
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ess(mid) >= target_ess else (lo, mid)
    return min(1.0, max(lo, beta + MIN_TEMPER_STEP))


def _weighted_cov(x: FloatArray, w: FloatArray, centre: FloatArray | None = None) -> FloatArray:
    """Weighted second moment of the rows of ``x`` about ``centre`` (default: their weighted mean, the covariance)."""
    s = float(np.sum(w))
    if x.shape[0] == 0 or s <= 0:
        return np.eye(x.shape[1])
    d = x - (w @ x / s if centre is None else centre)
    return (d * (w / s)[:, None]).T @ d


def _safe_cholesky(cov: FloatArray, fallback: FloatArray) -> FloatArray:
    for c in (cov, fallback):
        c = 0.5 * (c + c.T)
        scale = max(float(np.max(np.abs(np.diag(c)))), 1e-12)
        try:
            return np.linalg.cholesky(c + 1e-10 * scale * np.eye(c.shape[0]))
        except np.linalg.LinAlgError:
            continue
    return np.diag(np.sqrt(np.maximum(np.abs(np.diag(fallback)), 1e-6)))


def _scaled_cholesky(cov: FloatArray) -> FloatArray:
    r"""Cholesky factor of ``cov`` regularised relative to each variance: :math:`\mathbf D^{1/2}\mathbf L`.

    :math:`\mathbf L` factors the correlation matrix (plus :math:`10^{-10}`
    on its diagonal), :math:`\mathbf D` the variances.  A posterior known to
    hundreds of metres along the track and to millimetres per second in some
    velocity has variances ten orders of magnitude apart: a regularisation
    relative to the largest (:func:`_safe_cholesky`) would swamp the smallest
    and halve the shares measured against it.
    """
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return d[:, None] * _safe_cholesky(cov / np.outer(d, d), np.eye(d.size))


def _along_jacobian(model: TrackingModel, x: FloatArray, t: FloatArray, pair: NDArray[np.intp]
                    ) -> tuple[FloatArray, FloatArray]:
    r"""Doppler :math:`h_j` along the constant-velocity track from ``x`` and its Jacobian with respect to ``x``.

    Along the track :math:`\mathbf x(t) = \mathbf F(t)\mathbf x`, so the row of a measurement at
    :math:`t_j` is :math:`\mathbf H(\mathbf x(t_j))\,\mathbf F(t_j)`: with
    :math:`\mathbf H = [\mathbf H_p\ \mathbf H_v]`, :math:`[\mathbf H_p\ \ t_j\mathbf H_p + \mathbf H_v]`.
    Returns ``(h (m,), J (m, 2d))``.

    Raises
    ------
    ValueError
        If the track passes through a sensor (the model's Jacobian is undefined there).
    """
    n = model.n
    states = model.motion.propagate(np.broadcast_to(x, (t.size, n)), t)
    h, H = model.observation.predict_and_jacobian(states, pair)
    H = np.asarray(H, dtype=float).reshape(t.size, n)
    d = n // 2
    return np.asarray(h, dtype=float).reshape(t.size), np.concatenate([H[:, :d], H[:, :d] * t[:, None] + H[:, d:]],
                                                                       axis=1)
