r"""The offline smoother's problem and its solve: the whole recording's graph by Levenberg–Marquardt.

The graph has one state per distinct measurement time, a measurement factor
per state, a constant-velocity motion factor per step and (optionally) the
zone's weak prior and its wall on the first state.

Cost per iteration is O(N) in the number of states, with a small constant:

* the values live in numpy; all measurement rows are linearised in one
  vectorised call (no ``CustomFactor`` callbacks, which would copy the whole
  ``Values`` per call and make an iteration O(N²));
* each scan contributes **one** native :class:`gtsam.JacobianFactor` holding
  its motion rows, measurement rows and damping rows;
* GTSAM eliminates the linear system by QR in time order (no fill-in on the
  chain; robust to the ill-conditioning of Doppler-only graphs) and
  back-substitutes;
* per-time marginal covariances come from the QR conditionals of the final,
  undamped system by an O(N) backward recursion
  (:func:`~fgdoppler.estimators.marginals.chain_solve`).

Where the wall holds the first state, the solve's ``boundary`` test releases
it (a likelihood-ratio test of the wall); the searches beyond it are
:mod:`fgdoppler.estimators.smoother_zone`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from fgdoppler._text import distance_text, first_line
from fgdoppler.estimators.linearized import LinearRows, MotionBlocks, linearize_rows
from fgdoppler.estimators.marginals import chain_solve, check_covariances
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.verdict import Judged, Reason
from fgdoppler.factors import X
from fgdoppler.measurements import Measurements, Scans
from fgdoppler.models.observation import check_channels
from fgdoppler.models.robust import huber_rho
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance, start_task
from fgdoppler.zone import Zone

__all__ = ["WALL_GAIN", "SmootherSolution", "solve_smoother"]

FloatArray = NDArray[np.float64]
#: How much lower the cost of a track without the zone wall must be than that of the track the wall holds (or
#: that a held track gave way to) for a ``doubtful`` ``boundary`` finding: χ²₁ at 95 %.
WALL_GAIN = float(chi2.ppf(0.95, 1))


@dataclass(frozen=True, kw_only=True)
class SmootherSolution(Judged):
    """Result of :func:`solve_smoother`.

    Attributes
    ----------
    times
        Scan times ``(n,)``.
    states
        Smoothed states ``(n, 2d)``.
    covariances
        Marginal covariances ``(n, 2d, 2d)``, or ``None`` (not asked for, or
        indeterminate: a ``covariance`` reason says which).
    cost
        Final sum of squared whitened residuals (Huber-weighted where robust).
    iterations
        Levenberg–Marquardt iterations.
    reasons
        The verdict's findings (:mod:`fgdoppler.estimators.verdict`).
    notes
        Messages of what happened (failed linear solves, ...).
    released
        Where the zone wall holds the first state: the track the solver
        reaches without the wall from there (the ``boundary`` test's), as
        (states, cost); ``None`` where the wall does not hold.
    """

    times: FloatArray
    states: FloatArray
    covariances: FloatArray | None
    cost: float
    iterations: int
    reasons: tuple[Reason, ...] = ()
    notes: tuple[str, ...] = ()
    released: tuple[FloatArray, float] | None = None


def _scans_at(meas: Measurements, times: FloatArray) -> Scans:
    """Scans at the given times, some possibly without measurements (a state with motion factors only)."""
    t = np.asarray(times, dtype=float).reshape(-1)
    if t.size == 0 or np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing and not empty")
    bounds = np.searchsorted(meas.time, t, side="left")
    covered = np.searchsorted(meas.time, t, side="right") - bounds
    if int(covered.sum()) != len(meas):
        raise ValueError("every measurement time must be one of the given times")
    return Scans(times=t, bounds=np.append(bounds, len(meas)).astype(np.intp))


class _Problem:
    def __init__(self, model: TrackingModel, meas: Measurements, huber_k: float | None,
                 prior: tuple[FloatArray, FloatArray] | None, times: FloatArray | None = None,
                 wall: tuple[Zone, FloatArray] | None = None) -> None:
        self.model = model.observation
        self.wall = wall  # (zone, whitening [position, position, speed]) on the first state
        self.meas = meas
        self.huber_k = huber_k
        self.scans = meas.scans() if times is None else _scans_at(meas, times)
        self.times = self.scans.times
        self.scan_of = self.scans.scan_of
        self.motion = MotionBlocks(model.motion)
        self.nx = nx = model.n  # state length (4 or 6)
        self.n = len(self.scans)
        if prior is not None:
            Ri = np.linalg.inv(np.linalg.cholesky(prior[1]))
            self.prior: tuple[FloatArray, FloatArray] | None = (Ri, Ri @ prior[0])
        else:
            self.prior = None
        dts = np.diff(self.times)
        blocks = [self.motion(dt) for dt in dts]
        self.Ap = np.array([blk[0] for blk in blocks]).reshape(-1, nx, nx)
        self.An = np.array([blk[1] for blk in blocks]).reshape(-1, nx, nx)
        counts = np.diff(self.scans.bounds)
        self.m_max = int(counts.max()) if counts.size else 0
        self.row_in_scan = np.arange(len(meas)) - self.scans.bounds[self.scan_of]
        self.keys = [X(k) for k in range(self.n)]
        self.unit = gtsam.noiseModel.Unit.Create(2 * nx + self.m_max)
        self._damp = np.zeros((self.n, nx))

    def cost(self, states: FloatArray) -> float:
        """The objective: data, motion, weak prior and zone wall."""
        return self.data_cost(states) + self.wall_cost(states)

    def data_cost(self, states: FloatArray) -> float:
        """The objective without the zone wall."""
        return self._data_cost(states, self.meas.doppler)

    def _data_cost(self, states: FloatArray, doppler: FloatArray) -> float:
        """:meth:`data_cost` for the Doppler values ``doppler``."""
        h = self.model.predict(states[self.scan_of], self.meas.pair)
        rho = huber_rho((doppler - h) / self.meas.sigma, self.huber_k)
        c = float(np.sum(rho)) + float(np.sum(self.motion.residuals(states, self.times) ** 2))
        if self.prior is not None:
            e = self.prior[0] @ states[0] - self.prior[1]
            c += float(e @ e)
        return c

    def model_gap(self, states: FloatArray) -> float:
        r"""How far the cost exceeds its linear model's value at ``states`` (zero without the Huber loss).

        The measurement rows carry the IRLS weights :math:`w = \min(1, k/|r|)`
        (:func:`~fgdoppler.estimators.linearized.linearize_rows`), so at the
        linearisation point the model holds :math:`w r^2 = k|r|` for an
        outlier where the cost holds :math:`\rho(r) = 2k|r| - k^2`: the
        model lies :math:`\sum_{|r|>k} k(|r| - k)` below the cost.  The
        model's predicted decrease is measured from its own value, or every
        gross outlier adds about :math:`k|r|` to it — 6 outliers of 100 σ
        make it about 800 where a step gains a few — and the gain ratio
        falls to nothing, so that Levenberg–Marquardt raises its damping at
        every step and stops far from the minimum.
        """
        return self._model_gap(states, self.meas.doppler)

    def _model_gap(self, states: FloatArray, doppler: FloatArray) -> float:
        """:meth:`model_gap` for the Doppler values ``doppler``."""
        if self.huber_k is None:
            return 0.0
        h = self.model.predict(states[self.scan_of], self.meas.pair)
        excess = np.abs((doppler - h) / self.meas.sigma) - self.huber_k
        return float(self.huber_k * np.sum(excess[excess > 0.0]))

    def wall_rows(self, states: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Whitened wall error of the first state and its Jacobian (zero inside the zone)."""
        if self.wall is None:
            return np.zeros(self.nx // 2 + 1), np.zeros((self.nx // 2 + 1, self.nx))
        zone, w = self.wall
        e, J = zone.excess(states[0])
        return e / w, J / w[:, None]

    def wall_cost(self, states: FloatArray) -> float:
        e, _ = self.wall_rows(states)
        return float(e @ e)

    def system(self, states: FloatArray, lam: float, *, wall: bool = True) -> gtsam.GaussianFactorGraph:
        """The damped linear system in delta coordinates, one JacobianFactor per scan.

        Every scan's block has rows ``[motion (n); measurements (padded to the
        largest scan with zero rows, which add nothing); damping (n)]`` for
        states of ``n`` numbers; all
        blocks are filled in one vectorised pass and only the factor
        construction loops over scans.  The zone wall's rows join the first
        block where the wall is active (``wall``; the covariances leave them
        out: the wall bounds the solution, it does not measure it).
        """
        return self._factors(*self._blocks(states, lam, wall, self.meas.doppler)[:5])

    def _blocks(self, states: FloatArray, lam: float, wall: bool, doppler: FloatArray
                ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, LinearRows]:
        """The scans' damped blocks ``(A_prev, A_next, b, first-state rows, their right-hand side)`` of
        :meth:`system` for the Doppler values ``doppler``, and the measurement rows they hold."""
        nx = self.nx
        e_wall, J_wall = self.wall_rows(states) if wall else (np.zeros(nx // 2 + 1), np.zeros((nx // 2 + 1, nx)))
        active = bool(np.any(e_wall != 0.0))
        n, m = self.n, self.m_max
        lin = linearize_rows(self.model, states[self.scan_of], self.meas.pair, doppler,
                             self.meas.sigma, self.huber_k)
        # Marquardt scaling: the diagonal of J'J per state
        diag = np.zeros((n, nx))
        np.add.at(diag, self.scan_of, lin.A**2)
        if n > 1:
            diag[1:] += np.sum(self.An**2, axis=1)
            diag[:-1] += np.sum(self.Ap**2, axis=1)
        if self.prior is not None:
            diag[0] += np.sum(self.prior[0] ** 2, axis=0)
        if active:
            diag[0] += np.sum(J_wall**2, axis=0)
        damp = np.sqrt(lam * np.maximum(diag, 1e-12))
        self._damp = damp
        rows = 2 * nx + m
        A_next = np.zeros((n, rows, nx))
        A_prev = np.zeros((n, rows, nx))
        b = np.zeros((n, rows))
        A_next[self.scan_of, nx + self.row_in_scan] = lin.A
        b[self.scan_of, nx + self.row_in_scan] = lin.b
        A_next[:, nx + m:, :] = damp[:, :, None] * np.eye(nx)
        if n > 1:
            A_next[1:, :nx] = self.An
            A_prev[1:, :nx] = self.Ap
            b[1:, :nx] = -self.motion.residuals(states, self.times)
        first_rows = [A_next[0, nx:]]
        first_b = [b[0, nx:]]
        if self.prior is not None:
            first_rows.append(self.prior[0])
            first_b.append(self.prior[1] - self.prior[0] @ states[0])
        if active:
            first_rows.append(J_wall)
            first_b.append(-e_wall)
        return A_prev, A_next, b, np.vstack(first_rows), np.concatenate(first_b), lin

    def _factors(self, A_prev: FloatArray, A_next: FloatArray, b: FloatArray, A0: FloatArray, b0: FloatArray
                 ) -> gtsam.GaussianFactorGraph:
        """One JacobianFactor per scan from :meth:`_blocks`' arrays."""
        gfg = gtsam.GaussianFactorGraph()
        keys = self.keys
        unit = self.unit
        gfg.add(gtsam.JacobianFactor(keys[0], A0, b0, gtsam.noiseModel.Unit.Create(A0.shape[0])))
        for k in range(1, self.n):
            gfg.add(gtsam.JacobianFactor(keys[k - 1], A_prev[k], keys[k], A_next[k], b[k], unit))
        return gfg

    def model_cost(self, gfg: gtsam.GaussianFactorGraph, dx: FloatArray, lam: float) -> float:
        """Cost predicted by the undamped linear model for step ``dx``."""
        vv = gtsam.VectorValues()
        for k, key in enumerate(self.keys):
            vv.insert(key, dx[k])
        damped = 2.0 * gfg.error(vv)
        return damped - float(np.sum(self._damp**2 * dx**2))

    def solve(self, gfg: gtsam.GaussianFactorGraph, covariances: bool = False) -> tuple[FloatArray, FloatArray | None]:
        return chain_solve(gfg, self.keys, covariances=covariances)


def solve_smoother(
    measurements: Measurements,
    model: TrackingModel,
    initial: ArrayLike,
    settings: SmootherSettings | None = None,
    *,
    prior: tuple[ArrayLike, ArrayLike] | None = None,
    times: ArrayLike | None = None,
    progress: Progress | None = None,
) -> SmootherSolution:
    """Levenberg–Marquardt on the full trajectory graph.

    Parameters
    ----------
    measurements
        The whole recording.
    model
        Observation and motion model.
    initial
        Initial states, one per distinct measurement time, ``(n, 2d)``.
    settings
        Huber threshold, iteration cap, whether to compute covariances.
    prior
        Optional ``(mean, covariance)`` on the first state.
    times
        The states' times, strictly increasing, a superset of the
        measurement times (default: the distinct measurement times).  A
        time without measurements keeps a state tied by motion alone, as in
        a tracker whose gate rejected a whole scan.
    progress
        Told of a task "Levenberg-Marquardt" advanced once per iteration
        (:mod:`fgdoppler.progress`).

    Raises
    ------
    ValueError
        If ``initial`` does not have one state per time, or ``times`` does
        not cover every measurement time.
    """
    settings = settings or SmootherSettings()
    check_channels(model.observation, measurements)
    pr = None if prior is None else (np.asarray(prior[0], float), np.asarray(prior[1], float))
    ts = None if times is None else np.asarray(times, dtype=float)
    wall = None
    if settings.region_bound and model.zone is not None:
        sp, sv = settings.wall_sigma
        wall = (model.zone, np.array([sp] * model.zone.dim + [sv]))
    prob = _Problem(model, measurements, settings.huber_k, pr, ts, wall)
    x = np.array(initial, dtype=float).reshape(-1, model.n)
    if x.shape[0] != prob.n:
        raise ValueError(f"{x.shape[0]} initial states for {prob.n} measurement times")
    start_task(progress, "Levenberg-Marquardt", None)
    x, cost, it, stop, notes = _levenberg_marquardt(prob, x, settings.max_iterations, progress)
    reasons = [] if stop is None else [Reason(code="not-converged", status="doubtful", message=stop)]
    boundary, released = _boundary_test(prob, x, settings.max_iterations)
    reasons += boundary
    covs = None
    if settings.covariances:
        covs, problem = _covariances(prob, x)
        if problem:
            reasons.append(Reason(code="covariance", status="doubtful",
                                  message=f"marginal covariances indeterminate: {problem}"))
    return SmootherSolution(times=prob.times, states=x, covariances=covs, cost=cost, iterations=it,
                            reasons=tuple(reasons), notes=tuple(notes), released=released)


def _levenberg_marquardt(prob: _Problem, x: FloatArray, max_iterations: int, progress: Progress | None = None
                         ) -> tuple[FloatArray, float, int, str | None, list[str]]:
    """LM with Nielsen's damping update; returns (states, cost, iterations, why it did not converge, notes)."""
    notes: list[str] = []
    cost = prob.cost(x)
    # Nielsen's damping update driven by the gain ratio rho = actual / predicted decrease.
    lam, nu = 1e-6, 2.0
    it = 0
    for it in range(1, max_iterations + 1):
        advance(progress)
        try:
            gfg = prob.system(x, lam)
            dx, _ = prob.solve(gfg)
        except RuntimeError as exc:
            lam *= nu
            nu *= 2.0
            notes.append(f"iteration {it}: linear solve failed ({first_line(exc)}); damping raised")
            continue
        predicted = cost - prob.model_gap(x) - prob.model_cost(gfg, dx, lam)
        try:
            new_cost = prob.cost(x + dx)
        except ValueError:  # stepped onto a sensor
            new_cost = np.inf
        rho = (cost - new_cost) / predicted if predicted > 0 else -1.0
        if rho > 0:
            x = x + dx
            decrease = cost - new_cost
            cost = new_cost
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            # converged when the model predicts (and we got) a negligible decrease
            if predicted <= 1e-12 * max(cost, 1.0) or decrease <= 1e-13 * max(cost, 1.0):
                return x, cost, it, None, notes
        else:
            if predicted <= 1e-12 * max(cost, 1.0):
                return x, cost, it, None, notes  # at the optimum up to round-off
            lam *= nu
            nu *= 2.0
            if lam > 1e16:
                return x, cost, it, "LM stopped: no step reduces the cost (damping exhausted)", notes
    return x, cost, it, f"LM reached {max_iterations} iterations without converging", notes


def _boundary_test(prob: _Problem, x: FloatArray, max_iterations: int
                   ) -> tuple[list[Reason], tuple[FloatArray, float] | None]:
    """A ``boundary`` finding when the zone wall holds the first state: a likelihood-ratio test of the wall.

    As in the initiation: the solution is re-solved without the wall from
    where it stopped; ``"doubtful"`` when that lowers the objective by more
    than the χ²₁ 95 % quantile (the data prefer a start outside the zone),
    informational otherwise.  In 2-D :func:`~fgdoppler.estimators.smoother.run_smoother` also searches the
    data's modes beyond the wall (:func:`~fgdoppler.estimators.smoother_zone._beyond_wall_2d`).  Returns the
    findings and the released track (states, cost; ``None`` where the wall
    does not hold), which a track that replaces this one is tested against
    (:func:`~fgdoppler.estimators.smoother_zone._released_reason`).
    """
    if prob.wall_cost(x) == 0.0:
        return [], None
    inside = prob.data_cost(x)
    wall, prob.wall = prob.wall, None
    try:
        free, free_cost, *_ = _levenberg_marquardt(prob, x, max_iterations)
    finally:
        prob.wall = wall
    assert wall is not None
    return [_wall_reason(wall[0], x, inside, free, free_cost)], (free, free_cost)


def _wall_reason(zone: Zone, x: FloatArray, inside: float, free: FloatArray, free_cost: float,
                 searched: str = "", advise: Callable[[], tuple[str, Zone]] | None = None,
                 offsets: Callable[[FloatArray, FloatArray], float] | None = None) -> Reason:
    """The ``boundary`` finding for a track ``x`` held by the wall (data cost ``inside``) and the best track
    found without it (``free``, cost ``free_cost``; ``searched`` says where it was looked for, and whether the
    start found lies at its edge; ``advise`` gives the zone to try, asked only when the finding is
    ``doubtful`` — by default the one that holds ``free``'s start).  With calibration offsets declared,
    ``offsets`` gives the statistic with them in the model
    (:func:`~fgdoppler.estimators.smoother_offsets.joint_wall_gain`), which then decides."""
    gain = inside - free_cost
    limit = WALL_GAIN
    d = zone.dim
    held = (f"the track's first state is held at the zone's boundary ({zone.excess_text(x[0])}); without the "
            f"bound{searched} the cost is {free_cost:.2f} "
            f"instead of {inside:.2f}, {distance_text(np.linalg.norm(free[0, :d] - x[0, :d]))} away"
            f" (speed {np.linalg.norm(free[0, d:]):.0f} m/s)")
    joint = _offsets_gain(offsets, x, free, gain, limit)
    said = _offsets_text(joint, gain)
    gain = gain if joint is None else joint
    if gain > limit:
        text, advised = advise() if advise else _held_start(zone.reaching(free[0]))
        return Reason(code="boundary", status="doubtful", message=(
            f"{held}: the data prefer a start outside the zone (lower by {gain:.1f}{said} > {limit:.2f}); widen "
            f"the zone to hold that start, {text}"), zone=advised.box())
    return Reason(code="boundary", status="ok", message=(
        f"{held}: the data do not prefer a start outside it" + (f" (lower by {gain:.1f}{said})" if said else "")))


def _offsets_gain(offsets: Callable[[FloatArray, FloatArray], float] | None, held: FloatArray, free: FloatArray,
                  gain: float, limit: float) -> float | None:
    """The wall test's statistic with the declared calibration offsets in the model, where ``offsets`` is given
    and the test without them fails (``gain > limit``); ``None`` otherwise, or where the joint solves fail (the
    test without the offsets then stands)."""
    if offsets is None or gain <= limit or free.shape != held.shape:
        return None
    try:
        joint = float(offsets(held, free))
    except (RuntimeError, np.linalg.LinAlgError):
        return None
    return joint if np.isfinite(joint) else None


def _offsets_text(joint: float | None, gain: float) -> str:
    """What the wall test with the offsets in the model (statistic ``joint``; none: ``None``) adds to a finding."""
    return "" if joint is None else f" with the declared calibration offsets free in the model ({gain:.1f} without)"


def _data_cost(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
               sol: SmootherSolution) -> float:
    """``sol``'s cost without the zone wall (data, motion and the model's weak prior)."""
    return _Problem(model, measurements, settings.huber_k, model.prior(), sol.times).data_cost(sol.states)


def _held_start(advised: Zone) -> tuple[str, Zone]:
    """The words of :func:`~fgdoppler.estimators.smoother_zone._zone_advice` for a zone that holds one start,
    and the zone."""
    return "e.g. " + advised.options(), advised


def _covariances(prob: _Problem, x: FloatArray) -> tuple[FloatArray | None, str]:
    """Marginal covariances of the undamped system at ``x`` (without the zone wall), or ``None`` and why not."""
    try:
        _, covs = prob.solve(prob.system(x, 0.0, wall=False), covariances=True)
    except RuntimeError as exc:
        return None, first_line(exc)
    assert covs is not None
    problem = check_covariances(covs)
    return (None, problem) if problem else (covs, "")
