"""Marginal covariances from GTSAM graphs, with indeterminate systems reported, not raised.

:class:`gtsam.Marginals` always factorises by Cholesky, which rejects the
information matrices of these graphs as "indeterminate" although they are
positive definite (condition numbers of 1e12 are common near the baseline).
The linearised graph is therefore eliminated here with Householder QR
(``gtsam.EliminateQR``), which works on the square-root information and
does not square the condition number.  For the chain-structured tracking
graphs the marginals are then read from the QR conditionals by an exact
backward recursion (:func:`chain_solve`); a QR Bayes tree's own
``marginalCovariance`` was measured to lose ~5e-5 relative accuracy at
cond(A) ≈ 2e6 (it works with information, i.e. squared, quantities), while
the recursion matched a dense SVD inverse to 3e-11.  Other graphs fall back
to the Bayes tree.

GTSAM signals a singular or numerically indefinite information matrix with a
plain :class:`RuntimeError` ("Indeterminant linear system").  These helpers
turn that, and any non-finite or non-positive-definite result, into a status
string that callers can report.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import gtsam
import numpy as np
from numpy.typing import NDArray

from fgdoppler._text import first_line

__all__ = ["BorderedChain", "MarginalResult", "bordered_chain_solve", "chain_solve", "marginal_covariances"]

Status = Literal["ok", "indeterminate"]


@dataclass(frozen=True, kw_only=True)
class MarginalResult:
    """Marginal covariances of some keys, or why they could not be computed.

    Attributes
    ----------
    covariances
        ``(n_keys, d, d)`` when ``status == "ok"``, otherwise ``None``.
    status
        ``"ok"`` or ``"indeterminate"`` (singular or numerically indefinite).
    message
        Empty when ok; otherwise what went wrong.
    """

    covariances: NDArray[np.float64] | None
    status: Status
    message: str = ""

    @property
    def ok(self) -> bool:
        """True when the covariances are available."""
        return self.status == "ok"


def check_covariances(covs: NDArray[np.float64]) -> str:
    """Empty string if every matrix is finite, symmetric and positive definite, else the problem."""
    if not np.all(np.isfinite(covs)):
        return "non-finite covariance"
    sym = 0.5 * (covs + np.swapaxes(covs, -1, -2))
    try:
        np.linalg.cholesky(sym)
    except np.linalg.LinAlgError:
        return "indeterminate: covariance not positive definite (information matrix numerically singular)"
    return ""


def marginal_covariances(
    graph: gtsam.NonlinearFactorGraph | gtsam.GaussianFactorGraph,
    values: gtsam.Values | gtsam.VectorValues,
    keys: Sequence[int],
) -> MarginalResult:
    """Marginal covariances of ``keys`` from a nonlinear graph at ``values`` (or a linear graph).

    The graph is linearised at ``values`` (unless already linear) and
    eliminated by QR.  Never raises for a singular system: returns
    ``status="indeterminate"`` with GTSAM's message instead.
    """
    try:
        if isinstance(graph, gtsam.GaussianFactorGraph):
            gfg = graph
        elif isinstance(values, gtsam.Values):
            gfg = graph.linearize(values)
        else:
            raise TypeError("a nonlinear graph needs gtsam.Values to linearise at")
        # Symbol keys x0, x1, ... sort in time order: try the exact chain recursion first.
        ordered = sorted(int(k) for k in gfg.keyVector())
        try:
            _, chain = chain_solve(gfg, ordered)
            assert chain is not None
            pos = {k: i for i, k in enumerate(ordered)}
            covs = np.array([chain[pos[int(k)]] for k in keys])
        except ValueError:  # not a chain: general Bayes tree
            tree = gfg.eliminateMultifrontal(gtsam.Ordering.ColamdGaussianFactorGraph(gfg), gtsam.EliminateQR)
            covs = np.array([tree.marginalCovariance(int(k)) for k in keys])
    except RuntimeError as exc:
        return MarginalResult(covariances=None, status="indeterminate", message=_short(exc))
    problem = check_covariances(covs)
    if problem:
        return MarginalResult(covariances=None, status="indeterminate", message=problem)
    return MarginalResult(covariances=covs, status="ok")


def _short(exc: BaseException) -> str:
    if "indetermin" in str(exc).lower():
        return "indeterminate linear system (singular information matrix): " + first_line(exc)
    return first_line(exc)


def chain_solve(
    gfg: gtsam.GaussianFactorGraph, keys: Sequence[int], *, covariances: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    r"""Solve a chain-structured linear graph and read every marginal covariance, in O(N).

    The graph is eliminated by QR in the order of ``keys`` (no fill-in on a
    chain), giving conditionals
    :math:`\mathbf R_k\mathbf x_k + \mathbf S_k\mathbf x_{k+1} = \mathbf d_k`.
    Marginals follow from the backward recursion

    .. math:: \boldsymbol\Sigma_k = \mathbf R_k^{-1}\mathbf R_k^{-\top}
              + \mathbf T_k\boldsymbol\Sigma_{k+1}\mathbf T_k^\top,\qquad
              \mathbf T_k = \mathbf R_k^{-1}\mathbf S_k,

    which needs only triangular solves (no Cholesky, so it survives the
    conditioning that makes ``gtsam.Marginals`` give up).

    Returns
    -------
    (solution, covariances)
        ``(n, d)`` and ``(n, d, d)`` (``None`` unless requested).

    Raises
    ------
    RuntimeError
        If elimination fails or a diagonal block of R is singular.
    ValueError
        If the graph is not a chain in the order of ``keys``.
    """

    ordering = gtsam.Ordering()
    for k in keys:
        ordering.push_back(int(k))
    bn = gfg.eliminateSequential(ordering, gtsam.EliminateQR)
    vv = bn.optimize()
    sol = np.array([vv.at(int(k)) for k in keys])
    if not covariances:
        return sol, None
    n = len(keys)
    d = sol.shape[1]
    covs = np.empty((n, d, d))
    for i in range(n - 1, -1, -1):
        c = bn.at(i)
        ck = list(c.keys())
        Ri = _inverse_r(c)
        covs[i] = Ri @ Ri.T
        if i < n - 1:
            if ck[1:] != [int(keys[i + 1])]:
                raise ValueError("chain_solve needs a chain: each state may depend only on the next one")
            T = Ri @ np.asarray(c.S())
            covs[i] += T @ covs[i + 1] @ T.T
        elif len(ck) > 1:
            raise ValueError("chain_solve: the last key must have no parents")
    return sol, covs


@dataclass(frozen=True, kw_only=True)
class BorderedChain:
    """Solution and covariances of a chain of states that all share one more variable (the border).

    Attributes
    ----------
    states
        The chain's solution ``(n, d)``.
    border
        The border's solution ``(p,)``.
    covariances
        Each state's marginal covariance, the border's uncertainty included ``(n, d, d)``.
    conditional
        Each state's covariance given the border ``(n, d, d)``: ``covariances - conditional`` is the border's
        share (positive semi-definite).
    border_covariance
        ``(p, p)``.

    The three covariances are ``None`` when not asked for.
    """

    states: NDArray[np.float64]
    border: NDArray[np.float64]
    covariances: NDArray[np.float64] | None = None
    conditional: NDArray[np.float64] | None = None
    border_covariance: NDArray[np.float64] | None = None


def _inverse_r(c: gtsam.GaussianConditional) -> NDArray[np.float64]:
    """The inverse of a QR conditional's R (:func:`upper_inverse`).

    Raises
    ------
    RuntimeError
        If a diagonal element of R vanishes (an indeterminate system).
    """
    R = np.asarray(c.R())
    if np.any(np.abs(np.diag(R)) <= 1e-300 * max(1.0, np.abs(R).max())):
        raise RuntimeError(f"singular conditional for key {next(iter(c.keys()))}: indeterminate system")
    return upper_inverse(R)


def upper_inverse(R: NDArray[np.float64]) -> NDArray[np.float64]:
    r"""The inverse of a small nonsingular upper-triangular matrix :math:`\mathbf R`.

    LU with partial pivoting leaves an upper-triangular matrix as it is
    (:math:`\mathbf L = \mathbf I`, no row exchange: every entry below the
    diagonal is zero), so :func:`numpy.linalg.inv` does the same triangular
    solves as a dedicated one.  It is used instead of
    :func:`scipy.linalg.solve_triangular` because that call, on the 4×4 and
    6×6 blocks here, may hand the work to OpenBLAS threads: on a loaded
    2-core machine it took about 3 ms per call against microseconds
    (``python -m benchmarks --only inverse``), a fifth of a whole
    tracker run's time.

    Parameters
    ----------
    R
        ``(d, d)`` upper triangular, nonzero diagonal.

    Returns
    -------
    numpy.ndarray
        :math:`\mathbf R^{-1}`, ``(d, d)``, upper triangular.
    """
    return np.triu(np.linalg.inv(R))


def bordered_chain_solve(gfg: gtsam.GaussianFactorGraph, keys: Sequence[int], border: int, *,
                         covariances: bool = True) -> BorderedChain:
    r"""Solve a chain-structured linear graph whose factors may also involve one shared ``border`` variable.

    Eliminated by QR in the order ``keys``, then ``border`` (the border's
    column is the only fill-in), giving
    :math:`\mathbf R_k\mathbf x_k + \mathbf S_k\mathbf x_{k+1} + \mathbf G_k\mathbf b = \mathbf d_k` and
    :math:`\mathbf R_b\mathbf b = \mathbf d_b`.  With
    :math:`\mathbf T_k = \mathbf R_k^{-1}\mathbf S_k`, :math:`\mathbf U_k = \mathbf R_k^{-1}\mathbf G_k`,
    :math:`\boldsymbol\Sigma_b = \mathbf R_b^{-1}\mathbf R_b^{-\top}` and
    :math:`\mathbf C_k = \mathrm{cov}(\mathbf x_k, \mathbf b)`, the backward recursion

    .. math:: \boldsymbol\Sigma_k = \mathbf R_k^{-1}\mathbf R_k^{-\top}
              + [\mathbf T_k\ \mathbf U_k]
              \begin{bmatrix}\boldsymbol\Sigma_{k+1} & \mathbf C_{k+1}\\
              \mathbf C_{k+1}^\top & \boldsymbol\Sigma_b\end{bmatrix}
              [\mathbf T_k\ \mathbf U_k]^\top,\qquad
              \mathbf C_k = -(\mathbf T_k\mathbf C_{k+1} + \mathbf U_k\boldsymbol\Sigma_b)

    gives every marginal; with :math:`\boldsymbol\Sigma_b = 0` the same recursion gives the covariances
    given the border.  As :func:`chain_solve`: triangular solves only.

    Raises
    ------
    RuntimeError
        If elimination fails or a diagonal block of R is singular.
    ValueError
        If the graph is not a chain in the order of ``keys`` with ``border`` beside it.
    """

    ordering = gtsam.Ordering()
    for k in (*keys, border):
        ordering.push_back(int(k))
    bn = gfg.eliminateSequential(ordering, gtsam.EliminateQR)
    vv = bn.optimize()
    sol = np.array([vv.at(int(k)) for k in keys])
    b = np.asarray(vv.at(int(border)), dtype=float)
    if not covariances:
        return BorderedChain(states=sol, border=b)
    n, d, p = len(keys), sol.shape[1], b.size
    Rb_inv = _inverse_r(bn.at(n))
    cov_b = Rb_inv @ Rb_inv.T
    covs = np.empty((n, d, d))
    cond = np.empty((n, d, d))
    cross = np.zeros((d, p))
    for i in range(n - 1, -1, -1):
        c = bn.at(i)
        parents = [int(k) for k in list(c.keys())[1:]]
        nxt = int(keys[i + 1]) if i < n - 1 else None
        if any(k not in (nxt, int(border)) for k in parents) or (nxt is not None and nxt not in parents):
            raise ValueError("bordered_chain_solve needs a chain beside one border: each state may depend only on "
                             "the next one and the border")
        Ri = _inverse_r(c)
        S = np.asarray(c.S())
        T = np.zeros((d, d))
        U = np.zeros((d, p))
        col = 0
        for k in parents:  # S stacks the parents' blocks in the conditional's key order
            width = p if k == int(border) else d
            blk = Ri @ S[:, col:col + width]
            if k == int(border):
                U = blk
            else:
                T = blk
            col += width
        base = Ri @ Ri.T
        if i < n - 1:
            covs[i] = base + T @ covs[i + 1] @ T.T + T @ cross @ U.T + U @ cross.T @ T.T + U @ cov_b @ U.T
            cond[i] = base + T @ cond[i + 1] @ T.T
            cross = -(T @ cross + U @ cov_b)
        else:
            covs[i] = base + U @ cov_b @ U.T
            cond[i] = base
            cross = -U @ cov_b
    return BorderedChain(states=sol, border=b, covariances=covs, conditional=cond, border_covariance=cov_b)
