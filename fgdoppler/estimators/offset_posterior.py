r"""Calibration offsets integrated out of a sampled track's likelihood (the particle estimators' ``bias_sigma``).

Each pair :math:`p` may measure with an unknown constant offset
:math:`b_p` (m/s): :math:`z_j = h_j(\mathbf x) + b_{p_j} + \varepsilon_j`,
:math:`\varepsilon_j \sim N(0, \sigma_j^2)`.  Given the state the offsets
enter linearly, so for a sample :math:`\mathbf x` of the track they can be
integrated out exactly.  With the offsets' prior given the state
:math:`\mathbf b \mid \mathbf x \sim N(\boldsymbol\mu_0(\mathbf x), \mathbf S)`,
:math:`\boldsymbol\mu_0(\mathbf x) = \mathbf m_b + \mathbf K(\mathbf x - \mathbf m_x)`
(at the start :math:`\mathbf m_b = \mathbf 0`, :math:`\mathbf K = \mathbf 0`,
:math:`\mathbf S = \operatorname{diag}\sigma_{b,p}^2`), and the data's
per-pair statistics

.. math::

    s_p(\mathbf x) = \sum_{j:\,p_j = p} \frac{z_j - h_j(\mathbf x)}{\sigma_j^2},
    \qquad
    a_p = \sum_{j:\,p_j = p} \frac{1}{\sigma_j^2},

the offsets' posterior given the state is Gaussian with precision
:math:`\boldsymbol\Lambda = \mathbf S^{-1} + \operatorname{diag}\mathbf a`
and mean :math:`\boldsymbol\Lambda^{-1}\boldsymbol\eta`,
:math:`\boldsymbol\eta = \mathbf S^{-1}\boldsymbol\mu_0 + \mathbf s`, and
the data's likelihood with the offsets integrated out is

.. math::

    \log p(\mathbf z \mid \mathbf x) = -\tfrac12\sum_j \frac{(z_j - h_j)^2}{\sigma_j^2}
        - \tfrac12\boldsymbol\mu_0^\top\mathbf S^{-1}\boldsymbol\mu_0
        + \tfrac12\boldsymbol\eta^\top\boldsymbol\Lambda^{-1}\boldsymbol\eta
        - \tfrac12\log\lvert\mathbf S\boldsymbol\Lambda\rvert + \text{const},

whose first term is the likelihood without offsets and whose next two,
:meth:`OffsetPrior.extra`, depend on the state only through
:math:`\mathbf s` and :math:`\boldsymbol\mu_0`; the log-determinant does
not depend on the state at all (it enters only the evidence,
:meth:`OffsetPrior.log_det`).  The same value is the joint log density of
:math:`(\mathbf x, \mathbf b)` at the offsets' conditional mode, so a
Gauss–Newton climb over both finds the marginal's mode in
:math:`\mathbf x` (:meth:`OffsetPrior.profile`).

Pairs with :math:`\sigma_{b,p} = 0` are calibrated: they carry no offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.calibration import bias_sigmas

__all__ = ["OffsetPrior"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class OffsetPrior:
    r"""The offsets' Gaussian prior given the state, :math:`N(\mathbf m_b + \mathbf K(\mathbf x - \mathbf m_x), \mathbf S)`.

    Attributes
    ----------
    channel
        For each channel (pair) of the model, the index of its offset among
        the uncertain ones, or -1 for a calibrated pair ``(n_channels,)``.
    m_b, m_x, K
        The prior mean's offset ``(P,)``, centre ``(n,)`` and slope ``(P, n)``.
    S_inv
        The prior precision ``(P, P)``.
    """

    channel: NDArray[np.intp]
    m_b: FloatArray
    m_x: FloatArray
    K: FloatArray
    S_inv: FloatArray

    @classmethod
    def independent(cls, bias_sigma: float | tuple[float, ...], n_channels: int, n: int) -> OffsetPrior | None:
        """Independent offsets :math:`N(0, \\sigma_{b,p}^2)`; ``None`` when every pair is calibrated.

        Raises
        ------
        ValueError
            If ``bias_sigma`` has neither one value nor one per channel, or a value is negative.
        """
        sb = bias_sigmas(bias_sigma, n_channels)
        uncertain = sb > 0
        if not np.any(uncertain):
            return None
        channel = np.where(uncertain, np.cumsum(uncertain) - 1, -1).astype(np.intp)
        p = int(np.count_nonzero(uncertain))
        return cls(channel=channel, m_b=np.zeros(p), m_x=np.zeros(n), K=np.zeros((p, n)),
                   S_inv=np.diag(1.0 / sb[uncertain] ** 2))

    @property
    def size(self) -> int:
        """Number of uncertain offsets :math:`P`."""
        return int(self.m_b.size)

    def incidence(self, pair: NDArray[np.intp], sigma: FloatArray) -> FloatArray:
        r"""``(m, P)``: :math:`1/\sigma_j` where measurement :math:`j` is of the offset's pair, else 0.

        Whitened residuals times this matrix give :math:`\mathbf s`'s terms;
        its column sums of squares give :math:`\mathbf a`'s.
        """
        out = np.zeros((pair.size, self.size))
        col = self.channel[pair]
        rows = np.flatnonzero(col >= 0)
        out[rows, col[rows]] = 1.0 / sigma[rows]
        return out

    def mean(self, x: FloatArray) -> FloatArray:
        r""":math:`\boldsymbol\mu_0(\mathbf x)` for every row of ``x`` ``(N, P)``."""
        return self.m_b + (x - self.m_x) @ self.K.T

    def precision(self, a: FloatArray) -> FloatArray:
        r""":math:`\boldsymbol\Lambda = \mathbf S^{-1} + \operatorname{diag}\mathbf a`."""
        return self.S_inv + np.diag(a)

    def extra(self, x: FloatArray, s: FloatArray, a: FloatArray) -> FloatArray:
        r"""The state-dependent terms the offsets add to the log-likelihood, one per row of ``x``.

        :math:`-\tfrac12\boldsymbol\mu_0^\top\mathbf S^{-1}\boldsymbol\mu_0
        + \tfrac12\boldsymbol\eta^\top\boldsymbol\Lambda^{-1}\boldsymbol\eta` (module docstring);
        zero without data (:math:`\mathbf s = \mathbf a = \mathbf 0`).
        """
        mu = self.mean(x)
        eta = mu @ self.S_inv + s
        L = np.linalg.cholesky(self.precision(a))
        u = np.linalg.solve(L, eta.T)
        return np.asarray(0.5 * np.sum(u * u, axis=0) - 0.5 * np.einsum("ij,jk,ik->i", mu, self.S_inv, mu),
                          dtype=float)

    def posterior(self, x: FloatArray, s: FloatArray, a: FloatArray) -> tuple[FloatArray, FloatArray]:
        r"""The offsets' posterior given each state: means :math:`\boldsymbol\Lambda^{-1}\boldsymbol\eta` ``(N, P)`` and
        the common covariance :math:`\boldsymbol\Lambda^{-1}` ``(P, P)``."""
        cov = np.asarray(np.linalg.inv(self.precision(a)), dtype=float)
        return np.asarray((self.mean(x) @ self.S_inv + s) @ cov, dtype=float), cov

    def log_det(self, a: FloatArray) -> float:
        r""":math:`-\tfrac12\log\lvert\mathbf S\boldsymbol\Lambda\rvert`: the offsets' share of the evidence."""
        _, logdet_lam = np.linalg.slogdet(self.precision(a))
        _, logdet_sinv = np.linalg.slogdet(self.S_inv)
        return float(-0.5 * (logdet_lam - logdet_sinv))

    def profile(self, x: FloatArray, r: FloatArray, J: FloatArray, E: FloatArray) -> tuple[FloatArray, FloatArray]:
        r"""Residuals and Jacobian of the joint least-squares problem in :math:`(\mathbf x, \mathbf b)` at the
        offsets' conditional mode.

        ``r`` are the whitened residuals :math:`(h_j - z_j)/\sigma_j` at the
        single state ``x``, ``J`` their Jacobian ``(m, n)`` and ``E``
        :meth:`incidence`.  With :math:`\hat{\mathbf b}` the conditional mode,
        the residuals are :math:`r_j + \hat b_{p_j}/\sigma_j` and the prior's
        :math:`\mathbf L(\hat{\mathbf b} - \boldsymbol\mu_0)`
        (:math:`\mathbf L^\top\mathbf L = \mathbf S^{-1}`); their half sum of
        squares is the marginal's negative log-likelihood (module docstring).
        The Jacobian's columns are :math:`\mathbf x`'s, then :math:`\mathbf b`'s.
        """
        s = -(r @ E)
        a = np.sum(E * E, axis=0)
        b, _ = self.posterior(x[None], s[None], a)
        b = b[0]
        L = np.linalg.cholesky(self.S_inv).T
        rows = np.concatenate([r + E @ b, L @ (b - self.mean(x[None])[0])])
        jac = np.block([[J, E], [-L @ self.K, L]])
        return rows, jac

    def reanchored(self, x_old: FloatArray, x_new: FloatArray, s: FloatArray, a: FloatArray,
                   w: FloatArray) -> OffsetPrior:
        r"""The prior after the anchor moves: the joint Gaussian of the new anchor states and the offsets, conditioned.

        Each particle's offsets given its old anchor state ``x_old`` are
        :math:`N(\hat{\mathbf b}_i, \boldsymbol\Lambda^{-1})`; with its new
        anchor state ``x_new`` (propagated, with process noise) and weight,
        the cloud's moments give :math:`\mathbf C_{xx}, \mathbf C_{bx}` and
        :math:`\mathbf C_{bb} = \operatorname{Cov}\hat{\mathbf b} + \boldsymbol\Lambda^{-1}`,
        and the new prior is
        :math:`\mathbf K = \mathbf C_{bx}\mathbf C_{xx}^{-1}`,
        :math:`\mathbf S = \mathbf C_{bb} - \mathbf K\mathbf C_{xb}` about the
        means — the same moment matching that summarises the older data for
        the state.
        """
        b, cov = self.posterior(x_old, s, a)
        ws = w / np.sum(w)
        mx = ws @ x_new
        mb = ws @ b
        dx, db = x_new - mx, b - mb
        Cxx = (dx * ws[:, None]).T @ dx
        Cbx = (db * ws[:, None]).T @ dx
        Cbb = (db * ws[:, None]).T @ db + cov
        K = np.linalg.solve(Cxx, Cbx.T).T
        S = Cbb - K @ Cbx.T
        S = 0.5 * (S + S.T)
        return OffsetPrior(channel=self.channel, m_b=mb, m_x=mx, K=K, S_inv=np.linalg.inv(S))
