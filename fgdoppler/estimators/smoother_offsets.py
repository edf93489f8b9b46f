r"""The smoother's track and the pairs' calibration offsets estimated together.

With ``SmootherSettings(bias_sigma=..., estimate_offsets=True)`` each pair
declared uncertain gets one offset variable :math:`b_p` with the prior
:math:`N(0, \sigma_{b,p}^2)`, and the objective of the smoother becomes

.. math:: \sum_j \rho\Big(\frac{z_j - h_j(\mathbf x_{k(j)}) - b_{p(j)}}{\sigma_j}\Big)
          + \sum_k \lVert\mathbf x_{k+1} - \mathbf F\mathbf x_k\rVert^2_{\mathbf Q^{-1}}
          + \sum_p \frac{b_p^2}{\sigma_{b,p}^2} + \text{(prior, wall)}.

Every scan's factor touches the offsets, so the linear system is a chain
with a border: eliminated by QR in time order with the offsets last it
costs :math:`O(N(d+P)^3)`, and the marginals, with and without the
offsets' uncertainty, follow from one backward recursion
(:func:`~fgdoppler.estimators.marginals.bordered_chain_solve`).  Levenberg–
Marquardt runs over the states and the offsets together, from the track the
smoother chose without offsets (its mode searches and mode choice stay
those of the model without offsets: the offsets refine an answer, they do
not choose one).  The verdict's tests take the offsets in: the fit test
reads the residuals less the estimated offsets
(:mod:`fgdoppler.estimators.judge`), the split test of the motion model
compares one track and the offsets with two tracks that share them
(:func:`joint_split_statistics`), and in 2-D the joint mode found from the
track's mirror image across the sensors' line, which free offsets can make
as likely as the reported one, is a ``competing`` finding where it is a
rival (:func:`mirror_solution`), and the zone wall's likelihood-ratio test
compares the held and the released track in the joint objective
(:func:`joint_wall_gain`).  Those three tests of the model run with the
offsets only considered too (``bias_sigma`` without ``estimate_offsets``):
the joint solution is then found for the verdict alone.

What the smoother reports is that track moved by the joint solution's shift,
:math:`\hat{\mathbf x}_k + (\tilde{\mathbf x}_k - \hat{\mathbf x}_k)` with
:math:`\tilde{\mathbf x}` the joint mode (so a posterior mean the smoother
reports where its posterior is skewed, :mod:`fgdoppler.estimators.spread`,
moves with it), and its covariance widened by the offsets' share: with
:math:`\hat{\mathbf b}` the offsets at the joint mode and
:math:`\boldsymbol\Sigma_b = \sum_j \mathbf d_j\mathbf d_j^\top` their
covariance there (:meth:`~fgdoppler.estimators.results.OffsetEstimate.square_root`),

.. math:: \mathbf P_k \;\to\; \mathbf P_k + \sum_j \sum_i w_i\,
          \mathbf f_{j,k}(u_i)\,\mathbf f_{j,k}(u_i)^\top,

:math:`\mathbf f_j(u)` the change of the track fitted to the data less
:math:`\hat{\mathbf b} + u\,\mathbf d_j` — the consider covariance's
five-point Gauss–Hermite rule
(:func:`~fgdoppler.estimators.calibration.with_bias_uncertainty`) about the
estimated offsets, along their posterior's principal axes.  Not the joint
Laplace covariance (:attr:`JointSolution.covariances`, the first-order
share :math:`\mathbf T_k\boldsymbol\Sigma_b\mathbf T_k^\top`): the track
responds to the offsets far from linearly where the data observe it
poorly, and on case a 45 km (12 recordings, offsets drawn with σ 1 m/s) the
Laplace share left the final mean NEES 10.2 where the rule gives 6.2 (5.6
with the offsets only considered; one recording 2.3–2.8 km off sets most
of each).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import gtsam
import numpy as np
from numpy.typing import NDArray

from fgdoppler._text import first_line
from fgdoppler.estimators.calibration import bias_sigmas
from fgdoppler.estimators.marginals import bordered_chain_solve, check_covariances
from fgdoppler.estimators.results import OffsetEstimate
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.smoother_solve import _levenberg_marquardt, _Problem
from fgdoppler.geometry import mirrored
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance
from fgdoppler.zone import Zone

__all__ = ["JointSolution", "joint_split_statistics", "joint_wall_gain", "mirror_solution", "mirrored",
           "solve_with_offsets"]

FloatArray = NDArray[np.float64]

#: The offsets' key in the linear system (the states are ``x0, x1, ...``).
BORDER = gtsam.symbol("b", 0)


@dataclass(frozen=True, kw_only=True)
class JointSolution:
    """The joint mode of a track and the pairs' offsets, with its Laplace covariances.

    Attributes
    ----------
    times
        The states' times ``(n,)``.
    states
        The track at the joint mode ``(n, 2d)``.
    offsets
        The offsets at the joint mode, their covariance and their pairs.
    covariances
        Each state's marginal covariance, the offsets' uncertainty included ``(n, 2d, 2d)``.
    conditional
        Each state's covariance given the offsets ``(n, 2d, 2d)``.
    cost
        The joint objective at the mode.
    notes
        What happened (a Levenberg–Marquardt stop short of convergence, failed linear solves).
    """

    times: FloatArray
    states: FloatArray
    offsets: OffsetEstimate
    covariances: FloatArray
    conditional: FloatArray
    cost: float
    notes: tuple[str, ...] = ()


class _JointProblem(_Problem):
    """:class:`~fgdoppler.estimators.smoother_solve._Problem` over the packed point ``[states.ravel(), offsets]``."""

    def __init__(self, model: TrackingModel, meas: Measurements, settings: SmootherSettings,
                 times: FloatArray, sigmas: FloatArray, *, bare: bool = False, cut: int | None = None) -> None:
        """``bare``: without the zone's weak prior and wall (the cost the split test compares); ``cut``: without
        the motion link from state ``cut`` to the next (two tracks that share the offsets)."""
        prior = None if bare else model.prior()
        wall: tuple[Zone, FloatArray] | None = None
        if settings.region_bound and model.zone is not None and not bare:
            sp, sv = settings.wall_sigma
            wall = (model.zone, np.array([sp] * model.zone.dim + [sv]))
        super().__init__(model, meas, settings.huber_k, prior, times, wall)
        self.cut = cut
        self._link = (np.zeros((self.nx, self.nx)), np.zeros((self.nx, self.nx)))
        if cut is not None:
            if not 0 <= cut < self.n - 1:
                raise ValueError(f"cut must name a state before the last (0..{self.n - 2}), got {cut}")
            self._link = (self.Ap[cut].copy(), self.An[cut].copy())
            self.Ap[cut] = 0.0
            self.An[cut] = 0.0
        self.pairs = np.flatnonzero(sigmas > 0).astype(np.int64)
        column = np.full(sigmas.size, -1, dtype=np.intp)
        column[self.pairs] = np.arange(self.pairs.size)
        self.column = column[meas.pair]  # each measurement's offset, -1 for calibrated pairs
        self.uncertain = self.column >= 0
        self.inv_sb = 1.0 / sigmas[self.pairs]
        self.p = self.pairs.size
        self._damp_b = np.zeros(self.p)

    def split(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """States ``(n, 2d)`` and offsets ``(P,)`` of a packed point."""
        return z[: self.n * self.nx].reshape(self.n, self.nx), z[self.n * self.nx:]

    def doppler(self, b: FloatArray) -> FloatArray:
        """The data less the offsets: the Doppler values the track alone must explain."""
        return self.meas.doppler - np.where(self.uncertain, b[np.maximum(self.column, 0)], 0.0)

    def data_cost(self, states: FloatArray) -> float:  # the packed point, named as the base class's
        x, b = self.split(states)
        cost = self._data_cost(x, self.doppler(b)) + float(np.sum((b * self.inv_sb) ** 2))
        if self.cut is not None:  # the removed link's motion term
            r = self._link[0] @ x[self.cut] + self._link[1] @ x[self.cut + 1]
            cost -= float(r @ r)
        return cost

    def wall_cost(self, states: FloatArray) -> float:
        return super().wall_cost(self.split(states)[0])

    def model_gap(self, states: FloatArray) -> float:
        x, b = self.split(states)
        return self._model_gap(x, self.doppler(b))

    def system(self, states: FloatArray, lam: float, *, wall: bool = True) -> gtsam.GaussianFactorGraph:
        """The damped linear system: the scans' blocks with the offsets' columns, and the offsets' prior."""
        x, b = self.split(states)
        A_prev, A_next, rhs, A0, b0, lin = self._blocks(x, lam, wall, self.doppler(b))
        nx, p = self.nx, self.p
        if self.cut is not None:  # its rows are zero (Ap, An), and so their right-hand side
            rhs[self.cut + 1, :nx] = 0.0
        A_b = np.zeros((self.n, A_next.shape[1], p))
        rows = np.flatnonzero(self.uncertain)
        A_b[self.scan_of[rows], nx + self.row_in_scan[rows], self.column[rows]] = lin.scale[rows]
        diag = np.zeros(p)
        np.add.at(diag, self.column[rows], lin.scale[rows] ** 2)
        diag += self.inv_sb**2
        self._damp_b = np.sqrt(lam * np.maximum(diag, 1e-12))
        A_b0 = np.zeros((A0.shape[0], p))
        A_b0[: A_next.shape[1] - nx] = A_b[0, nx:]
        gfg = gtsam.GaussianFactorGraph()
        keys = self.keys
        gfg.add(gtsam.JacobianFactor(keys[0], A0, BORDER, A_b0, b0, gtsam.noiseModel.Unit.Create(A0.shape[0])))
        for k in range(1, self.n):
            gfg.add(gtsam.JacobianFactor(keys[k - 1], A_prev[k], keys[k], A_next[k], BORDER, A_b[k], rhs[k], self.unit))
        gfg.add(gtsam.JacobianFactor(BORDER, np.vstack([np.diag(self.inv_sb), np.diag(self._damp_b)]),
                                     np.concatenate([-b * self.inv_sb, np.zeros(p)]),
                                     gtsam.noiseModel.Unit.Create(2 * p)))
        return gfg

    def model_cost(self, gfg: gtsam.GaussianFactorGraph, dx: FloatArray, lam: float) -> float:
        dstates, db = self.split(dx)
        vv = gtsam.VectorValues()
        for k, key in enumerate(self.keys):
            vv.insert(key, dstates[k])
        vv.insert(BORDER, db)
        damped = 2.0 * gfg.error(vv)
        return damped - float(np.sum(self._damp**2 * dstates**2)) - float(np.sum(self._damp_b**2 * db**2))

    def solve(self, gfg: gtsam.GaussianFactorGraph, covariances: bool = False) -> tuple[FloatArray, FloatArray | None]:
        sol = bordered_chain_solve(gfg, self.keys, BORDER, covariances=False)
        return np.concatenate([sol.states.ravel(), sol.border]), None


def solve_with_offsets(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                       times: FloatArray, states: FloatArray) -> JointSolution | str:
    r"""The joint mode of the track and the offsets of the pairs ``settings.bias_sigma`` declares uncertain.

    Levenberg–Marquardt from ``states`` (at ``times``) with every offset 0, then the Laplace covariances at the
    mode (the zone wall left out, as the smoother's are).

    Returns
    -------
    JointSolution or str
        The solution, or why the covariances could not be had (an indeterminate system).

    Raises
    ------
    ValueError
        If no pair is declared uncertain, or ``bias_sigma`` has the wrong count.
    """
    sigmas = bias_sigmas(settings.bias_sigma, model.observation.n_channels)
    if not np.any(sigmas > 0):
        raise ValueError("no pair has an uncertain offset (bias_sigma is 0 for every pair)")
    prob = _JointProblem(model, measurements, settings, np.asarray(times, dtype=float), sigmas)
    z0 = np.concatenate([np.asarray(states, dtype=float).ravel(), np.zeros(prob.p)])
    z, cost, _, stop, notes = _levenberg_marquardt(prob, z0, settings.max_iterations)
    if stop is not None:
        notes.append(f"offsets: {stop}")
    try:
        sol = bordered_chain_solve(prob.system(z, 0.0, wall=False), prob.keys, BORDER)
    except RuntimeError as exc:
        return f"the joint system of track and offsets is indeterminate: {first_line(exc)}"
    assert sol.covariances is not None and sol.conditional is not None and sol.border_covariance is not None
    for what in (sol.covariances, sol.conditional, sol.border_covariance[None]):
        problem = check_covariances(what)
        if problem:
            return f"the joint covariance of track and offsets: {problem}"
    x, b = prob.split(z)
    return JointSolution(times=prob.times, states=x.copy(), offsets=OffsetEstimate(pairs=prob.pairs, values=b.copy(),
                                                                 covariance=sol.border_covariance),
                         covariances=sol.covariances, conditional=sol.conditional, cost=cost, notes=tuple(notes))


def joint_wall_gain(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                    times: FloatArray) -> Callable[[FloatArray, FloatArray], float]:
    r"""The zone wall's likelihood-ratio statistic with the calibration offsets in the model: a function of the
    held track and a track found without the wall (both at ``times``).

    The ``boundary`` test (:func:`~fgdoppler.estimators.smoother_zone._wall_reason`) compares the held track's
    cost :math:`c_h` with a free track's :math:`c_f`, both without the offsets.  With offsets declared
    (``settings.bias_sigma``) the model the user stated has them, and a start outside the zone that fits
    better only because the pairs disagree by a constant is not preferred by the data.  So both costs are
    those of the joint objective (module docstring, without the wall): :math:`\tilde c_h` at the joint mode
    from the held track with the wall, :math:`\tilde c_f` the lower of the joint modes without the wall from
    the free track (offsets 0) and from :math:`\tilde c_h`'s point; the function returns
    :math:`\tilde c_h - \tilde c_f`.  Three Levenberg–Marquardt solves, made only when the function is called
    (most runs with offsets declared never need it: the wall holds nothing).
    """
    sigmas = bias_sigmas(settings.bias_sigma, model.observation.n_channels)

    def gain(held: FloatArray, free: FloatArray) -> float:
        held_problem = _JointProblem(model, measurements, settings, times, sigmas)
        free_problem = _JointProblem(model, measurements, replace(settings, region_bound=False), times, sigmas)

        def packed(states: FloatArray) -> FloatArray:
            return np.concatenate([np.asarray(states, dtype=float).ravel(), np.zeros(held_problem.p)])

        z_held, *_ = _levenberg_marquardt(held_problem, packed(held), settings.max_iterations)
        c_free = min(free_problem.data_cost(_levenberg_marquardt(free_problem, z, settings.max_iterations)[0])
                     for z in (z_held, packed(free)))
        return held_problem.data_cost(z_held) - c_free

    return gain


def mirror_solution(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                    joint: JointSolution) -> JointSolution | None:
    r"""The joint mode of track and offsets found from the mirror image of ``joint``'s track (2-D).

    Near-collinear sensors tell a track from its mirror image across their
    line only through their small departures from it, a Doppler difference
    between the pairs that an offset per pair can supply: a mirror mode that
    the smoother without offsets does not have (it slides back to the
    reported track) can explain the data as well as the reported one once
    the offsets are free.  Measured on the paper's case b 45 km (60
    recordings, offsets drawn with σ 1 m/s, seed 2026): in four recordings
    the reported mode, about 2 km from the truth, was `ok` with a final NEES of
    4,100–15,500, and the mirror mode — the truth's, offsets of the right
    signs — cost 1.7–12.8 more.  Levenberg–Marquardt from
    :func:`mirrored` ``(joint.states)`` with the offsets 0 (the smoother
    judges it a rival by its cost and distance); ``None`` where that solve
    fails.
    """
    geometry = getattr(model.observation, "geometry", None)
    if geometry is None or model.dim != 2:
        return None
    try:
        sol = solve_with_offsets(measurements, model, settings, joint.times, mirrored(joint.states, geometry))
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        return None
    return None if isinstance(sol, str) else sol


def joint_split_statistics(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                           times: FloatArray, states: FloatArray, offsets: FloatArray, *,
                           progress: Progress | None = None) -> list[tuple[float, float]]:
    r"""The split test of the motion model (:mod:`fgdoppler.estimators.manoeuvre`) with the offsets in the model.

    :math:`D(t_c) = C - C_{12}`: :math:`C` the least cost of one track and the offsets, :math:`C_{12}` that of
    two tracks — the data up to :math:`t_c` and after it, the motion link across :math:`t_c` removed — that
    share the offsets, both re-fitted (without the zone's prior and wall, as there).  Under the model
    :math:`D \sim \chi^2_n` as without offsets; a test that fixed the offsets at the one-track values would
    be biased toward silence (the offsets can absorb part of a manoeuvre), and one without them fires on
    offsets alone (docs/concepts.md, "Calibration offsets").  The track ``states`` at ``times`` (one per scan) and
    the ``offsets`` of the pairs ``settings.bias_sigma`` declares uncertain, in their order (a
    :class:`JointSolution`'s), start every fit; the split times and the parts' minimum size are the module's.
    ``progress`` advances once per fit.

    Returns
    -------
    list of (float, float)
        As :func:`~fgdoppler.estimators.manoeuvre.split_statistics`: split time and statistic, for each split
        whose parts hold enough measurements and whose fits succeed.
    """
    from fgdoppler.estimators.manoeuvre import MIN_PART, SPLITS

    sigmas = bias_sigmas(settings.bias_sigma, model.observation.n_channels)
    times = np.asarray(times, dtype=float)
    bare = replace(settings, covariances=False)
    z = np.concatenate([np.asarray(states, dtype=float).ravel(), np.asarray(offsets, dtype=float)])
    try:
        whole = _JointProblem(model, measurements, bare, times, sigmas, bare=True)
        z, c_whole, *_ = _levenberg_marquardt(whole, z, settings.max_iterations)
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        return []
    finally:
        advance(progress)
    t0, t1 = float(times[0]), float(times[-1])
    need = MIN_PART * model.n
    out: list[tuple[float, float]] = []
    for f in SPLITS:
        k = int(np.searchsorted(times, t0 + f * (t1 - t0), side="right")) - 1
        tc = float(times[max(k, 0)])
        first = measurements.time <= tc
        if k >= times.size - 1 or min(int(first.sum()), int((~first).sum())) < need or (out and out[-1][0] == tc):
            continue
        try:
            parts = _JointProblem(model, measurements, bare, times, sigmas, bare=True, cut=k)
            _, c_parts, *_ = _levenberg_marquardt(parts, z, settings.max_iterations)
        except (RuntimeError, ValueError, np.linalg.LinAlgError):
            continue
        finally:
            advance(progress)
        out.append((tc, max(c_whole - c_parts, 0.0)))
    return out
