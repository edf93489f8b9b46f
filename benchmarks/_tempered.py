r"""The exact posterior by tempered sequential Monte Carlo: a reference where importance sampling fails.

:func:`benchmarks._exact.exact_posterior` samples the posterior of the first
state about its least-squares optimum, and refuses where that proposal misses
the mass: on random 3-D layouts over ground sensors most of the time
(``studies/exact_sampler_ess.py``), because there the Doppler is even in the
height, the posterior is cut by the zone's altitude band at the ground, and
its valleys run kilometres in height.  This sampler makes no assumption
about where the mass lies.  It targets the same density,

.. math::

    \pi(\mathbf x_0) \propto p(\mathbf x_0)\,\mathbb 1_{\mathcal Z}(\mathbf x_0)\,
        e^{-c(\mathbf x_0)/2},\qquad
    c(\mathbf x_0) = \sum_{t_j \le T} \big(z_j - h_{c_j}(\mathbf F(t_j - t_0)\mathbf x_0)\big)^2/\sigma_j^2,

with :math:`p` the model's weak Gaussian prior and :math:`\mathcal Z` the
zone, through the bridge :math:`\pi_\beta \propto p\,\mathbb 1_{\mathcal Z}\,
e^{-\beta c/2}` from :math:`\beta = 0` (the prior cut to the zone, sampled
exactly by rejection) to :math:`\beta = 1`.  Each step (Del Moral, Doucet
and Jasra 2006, *Sequential Monte Carlo samplers*, JRSS B 68:411):

1. the next :math:`\beta'` is the largest at which the incremental weights
   :math:`w_i \propto e^{-(\beta' - \beta)c(\mathbf x_i)/2}` keep an
   effective sample size of :data:`ESS_FRACTION` of the particles
   (bisection on :math:`\beta'`);
2. the particles are resampled (systematic) by those weights;
3. each takes Metropolis–Hastings steps invariant for :math:`\pi_{\beta'}`:
   a Gaussian random walk whose covariance is :math:`s^2` times that of the
   particle's cluster (:data:`CLUSTERS` found by k-means, :func:`_clusters`;
   :math:`s` starts at :math:`2.38/\sqrt{n}` and is scaled to keep the
   acceptance rate near :data:`TARGET_ACCEPTANCE`), for as many steps as
   give a particle a chance of :math:`1 -` :data:`STAY` to have moved at
   least once, :math:`\lceil \log(\text{STAY}) / \log(1 - a)\rceil` with
   :math:`a` the last acceptance rate (within :data:`MIN_MOVES` and
   :data:`MAX_MOVES`).

Separate modes keep the mass the tempering gave them, because no step
moves particles between them except by resampling; the moments are read
from the final, equally weighted particles.  Whether the moves mixed is
not assumed: :data:`BRIDGES` independent bridges are run and their moments
must agree (:data:`AGREE_MEAN`, :data:`AGREE_COVARIANCE`) before they are
pooled, else :class:`ValueError`.  Measured: on the paper's hardest
posterior it agrees with the importance sampler to 0.04 standard
deviations and variances within 0.86-1.04 (``tests/test_benchmarks.py``);
on random 3-D layouts over ground sensors the bridges agree on some
posteriors and not on others (``studies/exact_3d.py``).  The price is time:
seconds to tens of seconds a posterior where the importance sampler takes a
fraction of one.  No code shared with the library's samplers, which it is
used to judge.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.cluster.vq import kmeans2, vq
from scipy.special import logsumexp
from scipy.stats import chi2

import fgdoppler as fd
from benchmarks._exact import TAIL_LEVEL, ExactPosterior, posterior_costs

__all__ = ["AGREE_COVARIANCE", "AGREE_MEAN", "BRIDGES", "PARTICLES", "tempered_posterior"]

FloatArray = NDArray[np.float64]

#: Particles carried through each bridge.
PARTICLES = 4_000
#: Independent bridges, whose moments must agree before they are pooled.
BRIDGES = 2
#: Largest shift between two bridges' means, in standard deviations of a whitened coordinate ...
AGREE_MEAN = 0.5
#: ... and largest factor between their variances in any direction.
AGREE_COVARIANCE = 2.0
#: Each tempering step keeps this share of the particles as effective samples.
ESS_FRACTION = 0.5
#: The random walk's scale is adapted towards this acceptance rate.
TARGET_ACCEPTANCE = 0.25
#: Chance that a particle has not moved in a step's Metropolis-Hastings sweeps ...
STAY = 0.01
#: ... within these many sweeps.
MIN_MOVES, MAX_MOVES = 5, 60
#: Clusters whose own covariances shape the random walk's steps, and the k-means iterations that find them.
CLUSTERS = 8
KMEANS_ITERATIONS = 10
#: Prior draws tried per particle before the zone is declared too small a share of the prior to sample.
MAX_REJECTION = 1_000
#: Tempering steps after which the bridge is abandoned.
MAX_STEPS = 2_000


def tempered_posterior(measurements: fd.Measurements, model: fd.TrackingModel, t_end: float,
                       rng: np.random.Generator, *, particles: int = PARTICLES, bridges: int = BRIDGES
                       ) -> ExactPosterior:
    r"""Sample :math:`p(\mathbf x_0 \mid z_{t_j \le t_\mathrm{end}})` by tempering from the prior (module
    docstring), ``bridges`` times independently; the moments of the pooled particles, in the same
    :class:`~benchmarks._exact.ExactPosterior` as the importance sampler returns, with ``ess`` the sum of the
    bridges' last effective sample sizes before resampling and ``other_mode`` False (separate modes are sampled, not
    flagged).

    Raises :class:`ValueError` when the model has no weak prior or no zone (nothing to start the bridge from),
    when the zone holds too small a share of the prior to draw from it, or when the bridge does not reach
    :math:`\beta = 1` in :data:`MAX_STEPS` steps, or when the bridges' moments disagree (:data:`AGREE_MEAN`,
    :data:`AGREE_COVARIANCE`): the sampler's own test that it has mixed.
    """
    prior = model.prior()
    zone = model.zone
    if prior is None or zone is None:
        raise ValueError("the tempered posterior starts from the model's weak prior on its zone: the model has none")
    if particles < 10 or bridges < 1:
        raise ValueError(f"need at least 10 particles and one bridge, not {particles} and {bridges}")
    mean0, cov0 = prior
    chol0 = np.asarray(np.linalg.cholesky(cov0), dtype=np.float64)
    data_cost, prior_cost = posterior_costs(measurements, model, t_end)
    t0 = float(np.min(measurements.time))

    runs = [_bridge(mean0, chol0, zone, particles, rng, data_cost, prior_cost, t_end) for _ in range(bridges)]
    _agree([x for x, _ in runs], t_end)
    x = np.concatenate([x for x, _ in runs])
    centre = x.mean(axis=0)
    dev = x - centre
    cov = dev.T @ dev / len(x)
    far = np.einsum("ij,ij->i", dev, np.linalg.solve(cov, dev.T).T) > chi2.ppf(TAIL_LEVEL, centre.size)
    return ExactPosterior(t0=t0, t_end=float(t_end), mean=centre, covariance=cov,
                          ess=float(sum(e for _, e in runs)), tail_mass=float(np.mean(far)), other_mode=False)


def _bridge(mean0: FloatArray, chol0: FloatArray, zone: fd.Zone, particles: int, rng: np.random.Generator,
            data_cost: Callable[[FloatArray], FloatArray], prior_cost: Callable[[FloatArray], FloatArray],
            t_end: float) -> tuple[FloatArray, float]:
    """One tempering bridge from the prior on the zone to the posterior: its final particles, and the effective
    sample size of its last reweighting."""
    x = _prior_draws(mean0, chol0, zone, particles, rng)
    c = data_cost(x)
    pc = prior_cost(x)
    beta, ess, scale = 0.0, float(particles), 2.38 / np.sqrt(mean0.size)
    for _ in range(MAX_STEPS):
        if beta >= 1.0:
            return x, ess
        new = _next_beta(c, beta, ESS_FRACTION * particles)
        w = _weights(c, new - beta)
        ess = float(1.0 / np.sum(w * w))
        beta = new
        keep = _systematic(w, rng)
        x, c, pc, scale = _move(x[keep], c[keep], pc[keep], beta, scale, rng, data_cost, prior_cost)
    raise ValueError(f"the tempering bridge given the data up to {t_end:g} s did not reach the posterior in "
                     f"{MAX_STEPS} steps (at beta = {beta:.3g})")


def _agree(samples: list[FloatArray], t_end: float) -> None:
    r"""Raise :class:`ValueError` unless independent bridges give the same moments: every pair's means within
    :data:`AGREE_MEAN` standard deviations (whitened by the first's covariance) and the eigenvalues of
    :math:`\mathbf P_1^{-1}\mathbf P_2` within :math:`[1/`:data:`AGREE_COVARIANCE`, :data:`AGREE_COVARIANCE`:math:`]`."""
    moments = [(x.mean(axis=0), np.cov(x, rowvar=False)) for x in samples]
    for i, (m1, p1) in enumerate(moments):
        chol = np.linalg.cholesky(p1)
        for m2, p2 in moments[i + 1:]:
            shift = float(np.max(np.abs(np.linalg.solve(chol, m2 - m1))))
            ratio = np.linalg.eigvalsh(np.linalg.solve(chol, np.linalg.solve(chol, p2).T))
            if shift > AGREE_MEAN or ratio.max() > AGREE_COVARIANCE or ratio.min() < 1.0 / AGREE_COVARIANCE:
                raise ValueError(f"independent tempering bridges given the data up to {t_end:g} s disagree (means "
                                 f"{shift:.2f} standard deviations apart, covariance ratios {ratio.min():.2f}-"
                                 f"{ratio.max():.2f}): the sampler has not mixed and the moments cannot be read")


def _prior_draws(mean: FloatArray, chol: FloatArray, zone: fd.Zone, n: int, rng: np.random.Generator
                 ) -> FloatArray:
    """``n`` exact draws of the Gaussian prior cut to the zone, by rejection."""
    kept: list[FloatArray] = []
    have = 0
    for _ in range(MAX_REJECTION):
        x = mean + rng.standard_normal((n, mean.size)) @ chol.T
        x = x[zone.contains(x)]
        kept.append(x)
        have += len(x)
        if have >= n:
            return np.concatenate(kept)[:n]
    raise ValueError(f"the zone holds too small a share of the prior to draw from it ({have} of "
                     f"{n * MAX_REJECTION} draws inside)")


def _next_beta(cost: FloatArray, beta: float, target: float) -> float:
    r"""The largest :math:`\beta' \le 1` whose incremental weights keep ``target`` effective samples."""

    def ess(b: float) -> float:
        w = _weights(cost, b - beta)
        return float(1.0 / np.sum(w * w))

    if ess(1.0) >= target:
        return 1.0
    lo, hi = beta, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ess(mid) >= target else (lo, mid)
        if hi - lo < 1e-12 * max(hi, 1e-300):
            break
    # a step that keeps nothing would stall the bridge: move at least by a minimal amount
    return max(lo, beta + 1e-15)


def _weights(cost: FloatArray, step: float) -> FloatArray:
    r"""The normalised incremental weights :math:`w_i \propto e^{-\Delta\beta\,c_i/2}` of a tempering step
    ``step`` = :math:`\Delta\beta` (zero where the cost is infinite: outside the support)."""
    lw = -0.5 * step * cost
    lw = np.where(np.isfinite(lw), lw, -np.inf)
    return np.exp(lw - logsumexp(lw))


def _systematic(w: FloatArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Systematic resampling: indices with counts within one of :math:`n w_i`."""
    n = w.size
    edges = np.cumsum(w)
    edges[-1] = 1.0
    return np.searchsorted(edges, (rng.random() + np.arange(n)) / n)


def _move(x: FloatArray, c: FloatArray, pc: FloatArray, beta: float, scale: float, rng: np.random.Generator,
          data_cost: Callable[[FloatArray], FloatArray], prior_cost: Callable[[FloatArray], FloatArray]
          ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    r"""Random-walk Metropolis–Hastings sweeps invariant for :math:`\pi_\beta`, each particle's step drawn with
    :math:`s^2` times the covariance of its cluster (:func:`_clusters`); returns the moved particles, their costs
    and the adapted :math:`s`.

    The cluster is a function of the state (its nearest centre, the centres fixed for the step), so with
    :math:`\mathbf C_k` the Cholesky factor of cluster :math:`k`'s covariance the proposal density is
    :math:`q(\mathbf x' \mid \mathbf x) = N(\mathbf x'; \mathbf x, s^2\mathbf C_{k(\mathbf x)}
    \mathbf C_{k(\mathbf x)}^\top)` and the acceptance ratio carries
    :math:`q(\mathbf x \mid \mathbf x') / q(\mathbf x' \mid \mathbf x)`, one where both lie in one
    cluster.  Steps shaped by the local spread follow a curved valley where one covariance of all the
    particles, as wide as the whole valley, accepts almost nothing.
    """
    assign, chols = _clusters(x)
    logdet = np.sum(np.log(np.diagonal(chols, axis1=1, axis2=2)), axis=1)
    sweeps, done = MIN_MOVES, 0
    here = assign(x)
    while done < sweeps:
        xi = rng.standard_normal(x.shape)
        prop = x + scale * np.einsum("nij,nj->ni", chols[here], xi)
        there = assign(prop)
        back = np.linalg.solve(chols[there], ((x - prop) / scale)[..., None])[..., 0]
        log_q = (-0.5 * np.sum(back * back, axis=1) - logdet[there]) - (-0.5 * np.sum(xi * xi, axis=1) - logdet[here])
        pp = prior_cost(prop)
        cp = np.where(np.isfinite(pp), data_cost(prop), np.inf)
        log_a = -0.5 * ((pp + beta * cp) - (pc + beta * c)) + log_q
        accept = np.log(rng.random(len(x))) < np.where(np.isfinite(log_a), log_a, -np.inf)
        x, c, pc = np.where(accept[:, None], prop, x), np.where(accept, cp, c), np.where(accept, pp, pc)
        here = np.where(accept, there, here)
        rate = float(np.mean(accept))
        scale *= float(np.exp(rate - TARGET_ACCEPTANCE))
        done += 1
        if done == MIN_MOVES:
            sweeps = int(np.clip(np.ceil(np.log(STAY) / np.log1p(-min(max(rate, 1e-3), 0.999))), MIN_MOVES, MAX_MOVES))
    return x, c, pc, scale


def _clusters(x: FloatArray) -> tuple[Callable[[FloatArray], NDArray[np.intp]], FloatArray]:
    """:data:`CLUSTERS` centres of the particles by k-means (scipy's ``kmeans2`` from evenly spaced particles, so no
    random numbers) in the coordinates their covariance whitens, the map
    from a state to its nearest centre, and each cluster's covariance's Cholesky factor ``(CLUSTERS, k, k)`` (the
    covariance of all the particles for a cluster with too few to estimate its own)."""
    n, k = x.shape
    cov = np.cov(x, rowvar=False)
    try:
        whole = np.linalg.cholesky(cov + 1e-12 * np.trace(cov) / k * np.eye(k))
    except np.linalg.LinAlgError:
        raise ValueError("the tempered particles collapsed onto too few distinct states to span the state") from None
    inv = np.linalg.inv(whole)
    start = x[np.linspace(0, n - 1, CLUSTERS).astype(int)] @ inv.T
    with warnings.catch_warnings():
        # an empty cluster keeps its centre, which is what the walk needs; scipy warns of it all the same
        warnings.simplefilter("ignore", UserWarning)
        centres, _ = kmeans2(x @ inv.T, start, iter=KMEANS_ITERATIONS, minit="matrix", missing="warn")

    def assign(states: FloatArray) -> NDArray[np.intp]:
        return vq(states @ inv.T, centres, check_finite=False)[0].astype(np.intp)

    near = assign(x)
    chols = np.repeat(whole[None], CLUSTERS, axis=0)
    for j in range(CLUSTERS):
        members = x[near == j]
        if len(members) >= 10 * k:
            local = np.cov(members, rowvar=False)
            try:
                chols[j] = np.linalg.cholesky(local + 1e-12 * np.trace(local) / k * np.eye(k))
            except np.linalg.LinAlgError:
                pass
    return assign, chols
