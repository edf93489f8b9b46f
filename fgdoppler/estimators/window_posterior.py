r"""The initiation window's posterior, sampled: the particle estimator's start and a Gaussian sum from it.

The window's posterior :math:`\pi_0` (:mod:`fgdoppler.estimators.particle_posterior`,
no data before the window) is sampled from a Gaussian mixture on the
initiation's solutions — its estimate, its alternatives, the grid's best
candidates, each with its covariance, or the inverse of the window's
information there where the initiation gives none — by adaptive
tempering and Metropolis moves (:mod:`fgdoppler.estimators.particle`,
step 1).  :func:`window_posterior` returns the samples;
:meth:`WindowPosterior.components` clusters them into a Gaussian sum for
the filters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.particle_posterior import (
    _along_jacobian,
    _Data,
    _Posterior,
    _safe_cholesky,
    _weighted_cov,
)
from fgdoppler.estimators.settings import ParticleSettings
from fgdoppler.estimators.window import split_window
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel, as_tracking_model

__all__ = ["WindowPosterior", "window_posterior"]

FloatArray = NDArray[np.float64]


def _components(post: _Posterior, init: Initiation, window: _Data, *, alike: bool = False
                ) -> list[tuple[FloatArray, FloatArray]]:
    """Gaussian components of the start's proposal: the initiation's solutions and grid candidates.

    ``alike``: each alternative solution is proposed with the window's
    covariance there *with* the weak prior, as the estimate's own
    (Levenberg–Marquardt's) covariance has it.  The initiation gives an
    alternative the data's covariance alone, which with sensors on one line
    is 6.6 times wider across the line than its mirror twin's: proposed that
    thinly, the mirror mode lost its mass.
    """
    points = [init.x_start, *(a.state for a in init.alternatives), *(c.state for c in init.candidates)]
    covs = [init.P_start, *(a.covariance for a in init.alternatives), *(None for _ in init.candidates)]
    if alike and init.method == "lm":
        covs[1:1 + len(init.alternatives)] = [_window_covariance(post, a.state, window, with_prior=True)
                                              for a in init.alternatives]
    out: list[tuple[FloatArray, FloatArray]] = []
    for x, P in zip(points, covs, strict=True):
        x = np.asarray(x, dtype=float)
        cov = np.asarray(P, dtype=float) if P is not None else _window_covariance(post, x, window)
        if cov is not None and np.all(np.isfinite(cov)):
            out.append((x, cov))
    if not out:
        zone_prior = post.model.prior()
        if zone_prior is None:
            raise ValueError("the particle estimator needs an initiation covariance or a zone to start from")
        out.append((np.asarray(init.x_start, dtype=float), zone_prior[1]))
    return out

def _window_covariance(post: _Posterior, x: FloatArray, window: _Data, *, with_prior: bool = False
                       ) -> FloatArray | None:
    r"""Inverse Fisher information of the window about the start state ``x`` (analytic Jacobian of the model).

    ``with_prior`` adds the weak prior's information.

    Along a constant-velocity track :math:`\mathbf x(t) = \mathbf F(t)\mathbf x`, so the row of a
    measurement at :math:`t` is :math:`\mathbf H(\mathbf x(t))\,\mathbf F(t)`.
    """
    d = window
    if d.t.size == 0:
        return None
    try:
        _, J = _along_jacobian(post.model, x, d.t, d.pair)
    except ValueError:  # the track passes through a sensor
        return None
    Jw = J / d.sigma[:, None]
    info = Jw.T @ Jw
    prior = post.model.prior() if with_prior else None
    if prior is not None:
        info = info + np.linalg.inv(prior[1])
    s = np.linalg.svd(info, compute_uv=False)
    if not np.all(np.isfinite(s)) or s[-1] <= s[0] * 1e-14:
        return None
    return np.asarray(np.linalg.inv(info), dtype=float)


def _start(post: _Posterior, init: Initiation, rng: np.random.Generator) -> float:
    """Sample the window's posterior (module docstring, step 1); returns the moves' acceptance rate."""
    st = post.settings
    tempered = st.tempered_start
    rate = post.sample_from(_components(post, init, post.data, alike=tempered), st.particles(post.model.dim),
                            st.start_move_steps, rng, tempered=tempered)
    if rate is None:
        raise ValueError("no start sample has a finite posterior: the window cannot be explained inside the zone")
    return rate


def _window_posterior(measurements: Measurements, model: TrackingModel, init: Initiation,
                      settings: ParticleSettings, rng: np.random.Generator) -> tuple[_Posterior, float]:
    window, _ = split_window(measurements, init.t_end)
    t0 = init.t_start
    data = _Data(t=window.time - t0, pair=window.pair.astype(np.intp), z=window.doppler.copy(),
                 sigma=window.sigma.copy())
    post = _Posterior(model, settings, t0, data, half_plane=init.half_plane)
    return post, _start(post, init, rng)


@dataclass(frozen=True, kw_only=True)
class WindowPosterior:
    """Weighted samples of the initiation window's posterior (:func:`window_posterior`).

    Attributes
    ----------
    t_start, t_end
        The window's first and last measurement times.
    states
        Samples of the state at ``t_start`` ``(n, 2d)``.
    weights
        Their normalised weights ``(n,)``.
    acceptance
        Mean Metropolis acceptance of the moves that spread them.
    """

    t_start: float
    t_end: float
    states: FloatArray
    weights: FloatArray
    acceptance: float

    def at(self, t: float, model: TrackingModel) -> FloatArray:
        """The samples propagated to time ``t`` (constant velocity, no process noise)."""
        return model.motion.propagate(self.states, t - self.t_start)

    def components(self, k: int, model: TrackingModel, seed: int = 0) -> list[tuple[float, FloatArray, FloatArray]]:
        r"""A Gaussian sum of at most ``k`` terms at the window's end: ``(weight, mean, covariance)``, heaviest first.

        The samples at :math:`t_\mathrm{end}` are clustered by k-means in
        coordinates whitened by their overall covariance (so that metres and
        metres per second weigh alike); each cluster gives a term with its
        weight, weighted mean and covariance plus the process noise over the
        window, :math:`\mathbf Q(t_\mathrm{end} - t_\mathrm{start})`.  A curved
        valley becomes a chain of short, nearly straight pieces, each of which
        a Kalman filter linearises well.  Clusters of fewer than 20 samples
        are dropped (their weight goes to the others).
        """
        x = self.at(self.t_end, model)
        w = self.weights
        cov = _weighted_cov(x, w)
        L = _safe_cholesky(cov, cov)
        z = np.linalg.solve(L, (x - w @ x).T).T
        labels = _kmeans(z, w, min(k, x.shape[0]), np.random.default_rng(seed))
        Q = model.motion.Q(self.t_end - self.t_start)
        out = []
        for c in range(int(labels.max()) + 1):
            sel = labels == c
            if np.count_nonzero(sel) < 20:
                continue
            wc = float(np.sum(w[sel]))
            if wc <= 0:
                continue
            out.append((wc, w[sel] @ x[sel] / wc, _weighted_cov(x[sel], w[sel]) + Q))
        total = sum(c[0] for c in out)
        return sorted(((wc / total, m, P) for wc, m, P in out), key=lambda c: -c[0])


def _kmeans(z: FloatArray, w: FloatArray, k: int, rng: np.random.Generator, iterations: int = 25) -> NDArray[np.intp]:
    """Weighted k-means (Lloyd) labels of the rows of ``z``, seeded by k-means++ on the weights."""
    n = z.shape[0]
    centres = [z[rng.choice(n, p=w / np.sum(w))]]
    for _ in range(1, k):
        d2 = np.min(np.sum((z[:, None, :] - np.array(centres)[None]) ** 2, axis=-1), axis=1) * w
        if np.sum(d2) <= 0:
            break
        centres.append(z[rng.choice(n, p=d2 / np.sum(d2))])
    C = np.array(centres)
    labels = np.zeros(n, dtype=np.intp)
    for it in range(iterations):
        new = np.argmin(np.sum((z[:, None, :] - C[None]) ** 2, axis=-1), axis=1)
        if it > 0 and np.array_equal(new, labels):
            break
        labels = new
        for c in range(C.shape[0]):
            sel = labels == c
            if np.any(sel) and np.sum(w[sel]) > 0:
                C[c] = w[sel] @ z[sel] / np.sum(w[sel])
    return labels


def window_posterior(measurements: Measurements, model: TrackingModel | Geometry, init: Initiation,
                     settings: ParticleSettings | None = None) -> WindowPosterior:
    """Sample the initiation window's posterior (the particle estimator's start, module docstring step 1).

    ``settings.tempered_start=False``: importance sampling in one step
    instead of the tempered sequence (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.sample_from`).

    Raises
    ------
    ValueError
        If no start inside the zone explains the window.
    """
    model = as_tracking_model(model)
    settings = settings or ParticleSettings()
    post, rate = _window_posterior(measurements, model, init, settings, np.random.default_rng(settings.seed))
    return WindowPosterior(t_start=init.t_start, t_end=init.t_end, states=post.x.copy(), weights=post.weights(),
                           acceptance=rate)

