r"""Track initiation: multi-start grid search, then ILS or Levenberg–Marquardt over the window.

The paper (Section 3) estimates the initial state :math:`\mathbf x_0` of a
constant-velocity target from a window of Doppler measurements:

1. **Grid search** — :func:`fgdoppler.estimators.grid.grid_search` returns the K
   best distinct candidates.
2. **Refinement**, one of

   ``"ils"``
       The paper's iterated least squares (Gauss–Newton, Eq. 14) from the
       best candidate, stopped as soon as the residual passes the χ² test
       (Eq. 16).  Where :math:`\mathbf J'\mathbf R^{-1}\mathbf J` is too
       ill-conditioned to invert reliably (condition number above
       ``ils_condition_limit``) the grid estimate is kept — the paper's
       observation in Section 5 that forcing ILS there makes things worse.
   ``"lm"``
       Nonlinear least squares in GTSAM with Levenberg–Marquardt, started
       from *each* of the K candidates; the lowest final cost wins.  To keep
       Python callbacks few, LM first runs on the one-key batch factor from
       each candidate, then on the per-state graph from each distinct result.  The
       window is either one state per measurement time joined by
       constant-velocity motion factors (``window="states"``, the default) or
       the paper's batch factor on :math:`\mathbf x_0` alone
       (``window="batch"``, the same objective as ILS).  The linear systems
       are solved by multifrontal QR: GTSAM's default Cholesky rejects these
       ill-conditioned problems.
   ``"grid"``
       No refinement (the paper's grid-only estimate).

3. **Ambiguity** — every distinct refined solution whose cost passes the χ²
   test is reported as an alternative and the result is flagged ambiguous
   (near-collinear Tx/Rx admit a mirror-image trajectory).  A
   :class:`~fgdoppler.estimators.grid.HalfPlane` restricts the search to one
   side of a line.

4. **Detectable zone** — with ``region_bound`` (default) the grid's x/y box
   and ``speed_max`` bound the window's initial state (a steep wall,
   :func:`fgdoppler.factors.region_factor`), as the paper's candidates are
   drawn only from the detectable zone.  This removes a second likelihood
   mode outside the zone (a slower target near a sensor moving along the
   baseline) that otherwise wins in a few percent of well-observed windows.

The χ² test uses :math:`n_Z - 4` degrees of freedom at 95 % (scipy.stats)
and the data cost only (Doppler and motion terms, not the weak prior or the
wall).
With motion factors the total whitened cost has
:math:`n_Z + 4(N-1)` terms and :math:`4N` unknowns, so the same number of
degrees of freedom applies.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Literal

import gtsam
import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fgdoppler.estimators.common import region_prior
from fgdoppler.estimators.grid import GridResult, GridSpec, HalfPlane, grid_search
from fgdoppler.estimators.marginals import marginal_covariances
from fgdoppler.factors import (
    X,
    batch_factor,
    doppler_factor,
    motion_factor,
    prior_factor,
    region_excess,
    region_factor,
)
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import BatchTimes, batch_doppler, batch_doppler_and_jacobian
from fgdoppler.models.motion import ConstantVelocity

__all__ = ["Candidate", "Initiation", "InitiationSettings", "hypotheses", "initiate", "lm_params"]

FloatArray = NDArray[np.float64]
Method = Literal["lm", "ils", "grid"]


@dataclass(frozen=True, kw_only=True)
class InitiationSettings:
    """How to initiate a track.

    Parameters
    ----------
    method
        ``"lm"`` (default), ``"ils"`` or ``"grid"``.
    grid
        The candidate grid (default: the paper's).
    k_best
        Number of distinct grid candidates to refine (LM) and report.
    motion
        Motion model of the window graph (``window="states"``).
    window
        ``"states"``: a state per measurement time with motion factors;
        ``"batch"``: the paper's :math:`\\mathbf g(\\mathbf x_0)` on one state.
    weak_prior
        (default on) Add a weak Gaussian prior on :math:`\\mathbf x_0` centred on the grid
        region with standard deviations equal to its half-widths (positions)
        and ``grid.speed_max`` (velocity).  Regularises near-singular
        windows: without it LM can run off to non-physical speeds of several
        hundred m/s along the nearly flat cost valleys of a poorly observed
        window.  Its effect on a well-posed window is negligible.
    region_bound
        (default on) Treat the search region as the support of the window's
        initial state, as the paper does when it samples candidates only in
        the detectable zone: a steep wall (:func:`fgdoppler.factors.region_factor`,
        ``wall_sigma``) keeps the start position inside the grid's x/y box and
        the speed at most ``grid.speed_max``.  Without it, in a few percent of
        well-observed windows the lowest-cost solution is a second likelihood
        mode *outside* the zone — a slower target about 1-2 km from a sensor,
        moving along the baseline — about 4 km from the truth.
    wall_sigma
        Stiffness of the region wall: (position m, speed m/s).
    half_plane
        Restrict candidates and solutions to one side of a line.
    confidence
        χ² test level (0.95 in the paper).
    max_iterations
        Iteration cap for ILS and LM.
    ils_condition_limit
        ILS keeps the grid estimate where cond(J'R⁻¹J) exceeds this.
    ils_force
        Iterate ILS even when the grid estimate already passes the χ² test
        (the paper's "forced" experiment).
    same_solution_m, same_solution_mps
        Refined solutions closer than this (position, velocity at the window
        start) count as one.
    """

    method: Method = "lm"
    grid: GridSpec = field(default_factory=GridSpec)
    k_best: int = 5
    motion: ConstantVelocity = field(default_factory=lambda: ConstantVelocity(q=1e-3))
    window: Literal["states", "batch"] = "states"
    weak_prior: bool = True
    region_bound: bool = True
    wall_sigma: tuple[float, float] = (10.0, 0.1)
    half_plane: HalfPlane | None = None
    confidence: float = 0.95
    max_iterations: int = 100
    ils_condition_limit: float = 1e10
    ils_force: bool = False
    same_solution_m: float = 50.0
    same_solution_mps: float = 0.5

    def __post_init__(self) -> None:
        if self.method not in ("lm", "ils", "grid"):
            raise ValueError(f"method must be 'lm', 'ils' or 'grid', got {self.method!r}")
        if self.window not in ("states", "batch"):
            raise ValueError(f"window must be 'states' or 'batch', got {self.window!r}")
        if not 0 < self.confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if not (len(self.wall_sigma) == 2 and all(v > 0 for v in self.wall_sigma)):
            raise ValueError(f"wall_sigma must be two positive numbers, got {self.wall_sigma}")
        if self.k_best < 1 or self.max_iterations < 1:
            raise ValueError("k_best and max_iterations must be >= 1")


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """A state at the window start with its cost (sum of squared whitened residuals)."""

    state: FloatArray
    cost: float
    passes_chi2: bool = False
    #: Covariance of ``state`` (window Fisher information inverted), where computed.
    covariance: FloatArray | None = None

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"state": self.state.tolist(), "cost": self.cost, "passes_chi2": self.passes_chi2,
                "covariance": None if self.covariance is None else self.covariance.tolist()}


@dataclass(frozen=True, kw_only=True)
class Initiation:
    """Result of :func:`initiate`.

    Attributes
    ----------
    method
        Refinement used.
    t_start, t_end
        Times of the first and last measurement of the window.
    x_start, x_end
        Estimated state at those times.
    P_start, P_end
        Their covariances, or ``None`` with ``covariance_status ==
        "indeterminate"`` and the reason in ``covariance_message``.  The
        region wall does not enter them (it bounds the solution, it does not
        measure it).
    cost
        Sum of squared whitened data residuals at the solution (Doppler, and
        the motion factors' terms with ``window="states"``): the statistic of
        the χ² test, the paper's Eq. 16.
    objective
        What the refinement minimised and ranked the solutions by: ``cost``
        plus the weak prior and region wall terms (equal to ``cost`` for ILS
        and grid).
    chi2_threshold, dof, passes_chi2
        The χ² test of ``cost``.
    iterations
        ILS iterations, or LM iterations of the winning start.
    candidates
        The K best distinct grid candidates (grid cost).
    alternatives
        Other distinct refined solutions that pass the χ² test.
    ambiguous
        True if there are alternatives.
    notes
        Diagnostics (e.g. "ILS kept the grid estimate: cond(J'R^-1 J) = ...").
    wall_time
        Seconds for the whole initiation.
    """

    method: str
    t_start: float
    t_end: float
    x_start: FloatArray
    x_end: FloatArray
    P_start: FloatArray | None
    P_end: FloatArray | None
    covariance_status: str
    covariance_message: str
    cost: float
    objective: float
    chi2_threshold: float
    dof: int
    passes_chi2: bool
    iterations: int
    candidates: tuple[Candidate, ...]
    alternatives: tuple[Candidate, ...]
    ambiguous: bool
    n_measurements: int
    notes: tuple[str, ...] = ()
    wall_time: float = 0.0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        def mat(a: FloatArray | None) -> object:
            return None if a is None else a.tolist()
        return {
            "method": self.method,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "x_start": self.x_start.tolist(),
            "x_end": self.x_end.tolist(),
            "P_start": mat(self.P_start),
            "P_end": mat(self.P_end),
            "covariance_status": self.covariance_status,
            "covariance_message": self.covariance_message,
            "cost": self.cost,
            "objective": self.objective,
            "chi2_threshold": self.chi2_threshold,
            "dof": self.dof,
            "passes_chi2": self.passes_chi2,
            "iterations": self.iterations,
            "n_measurements": self.n_measurements,
            "candidates": [c.to_dict() for c in self.candidates],
            "alternatives": [c.to_dict() for c in self.alternatives],
            "ambiguous": self.ambiguous,
            "notes": list(self.notes),
            "wall_time": self.wall_time,
        }


def lm_params(max_iterations: int = 100) -> gtsam.LevenbergMarquardtParams:
    """LM parameters used throughout: multifrontal QR (survives ill-conditioning), tight tolerances."""
    p = gtsam.LevenbergMarquardtParams()
    p.setLinearSolverType("MULTIFRONTAL_QR")
    p.setMaxIterations(max_iterations)
    p.setRelativeErrorTol(1e-10)
    p.setAbsoluteErrorTol(1e-12)
    return p


@dataclass(frozen=True, kw_only=True)
class _Window:
    geometry: Geometry
    meas: Measurements
    t0: float
    bt: BatchTimes  # paper order, relative to t0
    z: FloatArray
    sigma: FloatArray
    scan_times: FloatArray  # distinct times relative to t0
    scan_of: NDArray[np.intp]  # per measurement (time order)

    @classmethod
    def build(cls, meas: Measurements, geometry: Geometry) -> _Window:
        order = meas.batch_order()
        t0 = float(meas.time[0])
        times, scan = meas.scan_index()
        return cls(
            geometry=geometry, meas=meas, t0=t0,
            bt=BatchTimes(pair=meas.pair[order], t=meas.time[order] - t0),
            z=meas.doppler[order], sigma=meas.sigma[order],
            scan_times=times - t0, scan_of=scan,
        )

    def cost(self, x0: FloatArray) -> float:
        r = (self.z - batch_doppler(x0, self.geometry, self.bt)) / self.sigma
        return float(r @ r)


def _graph(w: _Window, settings: InitiationSettings) -> tuple[gtsam.NonlinearFactorGraph, int]:
    """The window graph and the number of its data factors (Doppler and motion).

    The regularisers (weak prior, region wall) come last, so the data cost —
    the statistic of the χ² test — is the error of the first factors.
    """
    g = gtsam.NonlinearFactorGraph()
    if settings.window == "batch":
        g.add(batch_factor(X(0), w.geometry, w.bt, w.z, w.sigma))
    else:
        m = w.meas
        bounds = np.searchsorted(w.scan_of, np.arange(w.scan_times.size + 1))
        for k in range(w.scan_times.size):
            sl = slice(bounds[k], bounds[k + 1])
            g.add(doppler_factor(X(k), w.geometry, m.pair[sl], m.doppler[sl], m.sigma[sl]))
            if k:
                g.add(motion_factor(X(k - 1), X(k), w.scan_times[k] - w.scan_times[k - 1], settings.motion))
    n_data = int(g.size())
    spec = settings.grid
    if settings.weak_prior:
        g.add(prior_factor(X(0), *region_prior(spec)))
    if settings.region_bound:
        g.add(region_factor(X(0), spec.x[:2], spec.y[:2], spec.speed_max, wall_sigma=settings.wall_sigma))
    return g, n_data


def _values(w: _Window, x0: FloatArray, settings: InitiationSettings) -> gtsam.Values:
    v = gtsam.Values()
    if settings.window == "batch":
        v.insert(X(0), np.asarray(x0, dtype=float))
    else:
        states = settings.motion.propagate(x0, w.scan_times)
        for k, s in enumerate(states):
            v.insert(X(k), s)
    return v


@dataclass(frozen=True)
class _Solution:
    objective: float  # what LM minimised: data + regularisers (ranks the solutions)
    cost: float  # data part only: the χ² statistic
    x0: FloatArray
    values: gtsam.Values
    iterations: int


def _lm(graph: gtsam.NonlinearFactorGraph, n_data: int, values: gtsam.Values, settings: InitiationSettings
        ) -> _Solution | str:
    try:
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(settings.max_iterations))
        res = opt.optimize()
    except (RuntimeError, ValueError) as exc:  # ValueError: a step onto a sensor position
        return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    objective = 2.0 * graph.error(res)
    regularisers = 2.0 * sum(graph.at(i).error(res) for i in range(n_data, int(graph.size())))
    if not np.isfinite(objective):
        return "non-finite cost"
    return _Solution(objective, max(objective - regularisers, 0.0), res.atVector(X(0)), res, int(opt.iterations()))


def _without_wall(graph: gtsam.NonlinearFactorGraph, settings: InitiationSettings) -> gtsam.NonlinearFactorGraph:
    """The graph without the region wall (the last factor when ``region_bound``).

    The wall is an inequality constraint: it says where the solution may be,
    not how precisely it is known.  Left in, an active wall (σ 0.1 m/s on the
    speed) would claim the speed to 0.1 m/s and a filter started from that
    covariance diverges (measured: one of 200 runs of case a at 45 km).
    """
    if not settings.region_bound:
        return graph
    out = gtsam.NonlinearFactorGraph()
    for i in range(int(graph.size()) - 1):
        out.add(graph.at(i))
    return out


def _refine_lm(
    w: _Window, settings: InitiationSettings, grid: GridResult
) -> tuple[list[_Solution], gtsam.NonlinearFactorGraph, list[str]]:
    """LM from every grid candidate; returns solutions sorted by final objective.

    With ``window="states"`` this runs in two stages to keep Python callbacks
    few: LM on the one-key batch factor from each candidate, then LM on the
    per-state graph from each *distinct* stage-1 solution.
    """
    batch_settings = settings if settings.window == "batch" else replace(settings, window="batch")
    batch_graph, n_batch = _graph(w, batch_settings)
    notes: list[str] = []
    stage1: list[_Solution] = []
    for x0 in grid.states:
        out = _lm(batch_graph, n_batch, _values(w, x0, batch_settings), batch_settings)
        if isinstance(out, str):
            notes.append(f"LM from {np.round(x0, 1).tolist()} failed: {out}")
            continue
        if not any(_same(out.x0, s.x0, settings) for s in stage1):
            stage1.append(out)
    if settings.window == "batch":
        return sorted(stage1, key=lambda s: s.objective), batch_graph, notes
    graph, n_data = _graph(w, settings)
    sols = []
    for first in stage1:
        out = _lm(graph, n_data, _values(w, first.x0, settings), settings)
        if isinstance(out, str):
            notes.append(f"window LM from {np.round(first.x0, 1).tolist()} failed: {out}")
            continue
        sols.append(replace(out, iterations=first.iterations + out.iterations))
    return sorted(sols, key=lambda s: s.objective), graph, notes


def _refine_ils(
    w: _Window, settings: InitiationSettings, x_grid: FloatArray, threshold: float
) -> tuple[FloatArray, int, list[str], FloatArray | None]:
    """The paper's ILS (Eq. 14) with its χ² stop and a conditioning guard; returns (x, iters, notes, info)."""
    x = x_grid.copy()
    W = 1.0 / w.sigma
    cost = w.cost(x)
    notes: list[str] = []
    it = 0
    info = None
    for it in range(1, settings.max_iterations + 1):
        if cost <= threshold and not settings.ils_force:
            it -= 1
            break
        g, J = batch_doppler_and_jacobian(x, w.geometry, w.bt)
        Jw = J * W[:, None]
        info = Jw.T @ Jw
        s = np.linalg.svd(Jw, compute_uv=False)
        cond = float((s[0] / s[-1]) ** 2) if s[-1] > 0 else np.inf
        if cond > settings.ils_condition_limit:
            notes.append(f"ILS kept the grid estimate: cond(J'R^-1 J) = {cond:.3g} > {settings.ils_condition_limit:.3g}")
            return x_grid.copy(), it - 1, notes, None
        dx = np.linalg.solve(info, Jw.T @ ((w.z - g) * W))
        try:
            new_cost = w.cost(x + dx)
        except ValueError as exc:  # stepped onto a sensor
            notes.append(f"ILS stopped: {exc}")
            break
        x = x + dx
        converged = np.all(np.abs(dx) <= 1e-9 * (1.0 + np.abs(x)))
        cost = new_cost
        if converged:
            break
    else:
        notes.append(f"ILS reached {settings.max_iterations} iterations")
    if info is None:
        _, J = batch_doppler_and_jacobian(x, w.geometry, w.bt)
        Jw = J * W[:, None]
        info = Jw.T @ Jw
    return x, it, notes, info


def _same(a: FloatArray, b: FloatArray, settings: InitiationSettings) -> bool:
    return bool(
        np.linalg.norm(a[:2] - b[:2]) < settings.same_solution_m
        and np.linalg.norm(a[2:] - b[2:]) < settings.same_solution_mps
    )


def initiate(
    measurements: Measurements,
    geometry: Geometry,
    settings: InitiationSettings | None = None,
    *,
    grid_result: GridResult | None = None,
) -> Initiation:
    """Estimate the state of a constant-velocity target from a window of Doppler measurements.

    Parameters
    ----------
    measurements
        The initiation window (e.g. ``meas.first_per_pair(10)``, the paper's
        20-measurement batch).  Synchronous or asynchronous, any number of pairs.
    geometry
        Sensor pairs.
    settings
        Method and grid; defaults follow the paper with LM refinement.
    grid_result
        A grid search already run on this window with these settings (lets
        several refinement methods share one search).

    Returns
    -------
    Initiation
        Never raises for ill-conditioned or indeterminate windows: they are
        reported through ``covariance_status`` and ``notes``.

    Raises
    ------
    ValueError
        For invalid input: fewer than 5 measurements (4 unknowns plus one
        degree of freedom for the test), pair indices outside the geometry.
    """
    settings = settings or InitiationSettings()
    t_begin = time.perf_counter()
    measurements.check(geometry)
    if len(measurements) < 5:
        raise ValueError(f"initiation needs at least 5 measurements (4 unknowns + 1 dof), got {len(measurements)}")
    w = _Window.build(measurements, geometry)
    dof = len(measurements) - 4
    threshold = float(chi2.ppf(settings.confidence, dof))
    grid = grid_result if grid_result is not None else grid_search(
        geometry, w.bt, w.z, w.sigma, settings.grid, k_best=settings.k_best, half_plane=settings.half_plane
    )
    candidates = tuple(
        Candidate(state=s, cost=float(c), passes_chi2=bool(c <= threshold))
        for s, c in zip(grid.states, grid.costs, strict=True)
    )
    notes: list[str] = []
    t_span = float(w.scan_times[-1])
    F_end = ConstantVelocity.F(t_span)
    alternatives: list[Candidate] = []
    iterations = 0
    P0: FloatArray | None = None
    P1: FloatArray | None = None
    cov_status, cov_msg = "indeterminate", ""

    if settings.method == "lm":
        sols, graph, lm_notes = _refine_lm(w, settings, grid)
        notes += lm_notes
        if settings.half_plane is not None:
            kept = [s for s in sols if settings.half_plane.contains(s.x0)]
            if len(kept) < len(sols):
                notes.append(f"{len(sols) - len(kept)} refined solution(s) outside the half plane discarded")
            sols = kept
        if not sols:
            notes.append("no LM start succeeded: returning the best grid candidate")
            x0, cost = grid.best.copy(), float(grid.costs[0])
            objective = cost
            x1 = settings.motion.propagate(x0, t_span)
        else:
            best = sols[0]
            cost, objective, x0, best_vals, iterations = best.cost, best.objective, best.x0, best.values, best.iterations
            if settings.region_bound:
                spec = settings.grid
                excess, _ = region_excess(x0, spec.x[:2], spec.y[:2], spec.speed_max)
                if np.any(excess != 0.0):
                    notes.append(
                        "the start state is held at the search region's boundary (excess x, y, speed: "
                        + ", ".join(f"{v:.3g}" for v in excess)
                        + "): the data may prefer a start outside it; widen the grid or set region_bound=False"
                    )
            last = X(0) if settings.window == "batch" else X(w.scan_times.size - 1)
            x1 = F_end @ x0 if settings.window == "batch" else best_vals.atVector(last)
            keys = [X(0)] if settings.window == "batch" else [X(0), last]
            marg = marginal_covariances(_without_wall(graph, settings), best_vals, keys)
            cov_status, cov_msg = marg.status, marg.message
            if marg.ok:
                assert marg.covariances is not None
                P0 = marg.covariances[0]
                P1 = F_end @ P0 @ F_end.T if settings.window == "batch" else marg.covariances[1]
            distinct: list[tuple[float, FloatArray]] = [(cost, x0)]
            for sol in sols[1:]:
                if sol.cost <= threshold and not any(_same(sol.x0, d[1], settings) for d in distinct):
                    distinct.append((sol.cost, sol.x0))
                    alternatives.append(Candidate(state=sol.x0, cost=sol.cost, passes_chi2=True))
    else:
        x_grid = grid.best.copy()
        if settings.method == "ils":
            x0, iterations, ils_notes, info = _refine_ils(w, settings, x_grid, threshold)
            notes += ils_notes
        else:
            x0, info = x_grid, None
        cost = objective = w.cost(x0)
        if info is None:
            _, J = batch_doppler_and_jacobian(x0, geometry, w.bt)
            Jw = J / w.sigma[:, None]
            info = Jw.T @ Jw
        x1 = F_end @ x0
        P0, cov_status, cov_msg = _inverse(info)
        P1 = None if P0 is None else F_end @ P0 @ F_end.T
        # other grid optima that pass the test are alternatives as well
        for cand in candidates[1:]:
            if cand.passes_chi2 and not _same(cand.state, x0, settings):
                alternatives.append(cand)

    # Each alternative gets the covariance of the deterministic window fit at its state, so a
    # tracker can follow it as a hypothesis (see :func:`hypotheses`).
    with_cov = []
    for a in alternatives:
        _, J = batch_doppler_and_jacobian(a.state, geometry, w.bt)
        Jw = J / w.sigma[:, None]
        P_alt, _, _ = _inverse(Jw.T @ Jw)
        with_cov.append(Candidate(state=a.state, cost=a.cost, passes_chi2=a.passes_chi2, covariance=P_alt))
    alternatives = with_cov
    passes = bool(cost <= threshold)
    if not passes:
        notes.append(f"final cost {cost:.2f} fails the {settings.confidence:.0%} chi-square test ({threshold:.2f}, {dof} dof)")
    return Initiation(
        method=settings.method,
        t_start=w.t0,
        t_end=w.t0 + t_span,
        x_start=np.asarray(x0, dtype=float),
        x_end=np.asarray(x1, dtype=float),
        P_start=P0,
        P_end=P1,
        covariance_status=cov_status,
        covariance_message=cov_msg,
        cost=float(cost),
        objective=float(objective),
        chi2_threshold=threshold,
        dof=dof,
        passes_chi2=passes,
        iterations=iterations,
        candidates=candidates,
        alternatives=tuple(alternatives),
        ambiguous=bool(alternatives),
        n_measurements=len(measurements),
        notes=tuple(notes),
        wall_time=time.perf_counter() - t_begin,
    )


def _inverse(info: FloatArray) -> tuple[FloatArray | None, str, str]:
    s = np.linalg.svd(info, compute_uv=False)
    if s[-1] <= s[0] * 1e-15:
        return None, "indeterminate", f"information matrix numerically singular (cond {s[0] / max(s[-1], 1e-300):.3g})"
    P = np.linalg.inv(info)
    P = 0.5 * (P + P.T)
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return None, "indeterminate", "covariance not positive definite"
    return P, "ok", ""


def residual_landscape(
    measurements: Measurements,
    geometry: Geometry,
    *,
    x: NDArray[np.float64],
    heading_deg: NDArray[np.float64],
    y0: float,
    speed: float,
) -> NDArray[np.float64]:
    """Weighted residual cost over an initial-x × heading slice at fixed y0 and speed.

    Returns the cost, shape ``(x.size, heading_deg.size)`` — the landscape of
    the paper's Fig. 2 (many local optima; the start decides which is found).
    """
    from fgdoppler.analysis.observability import grid_states
    from fgdoppler.estimators.grid import grid_costs

    w = _Window.build(measurements, geometry)
    states = grid_states(x, y0, speed, heading_deg).reshape(-1, 4)
    return grid_costs(geometry, w.bt, w.z, w.sigma, states).reshape(np.size(x), np.size(heading_deg))


def hypotheses(init: Initiation) -> list[Initiation]:
    """The initiation and one unambiguous copy per alternative (best first).

    Each copy starts from the alternative's state and covariance at the
    window start, propagated to the window end.  Alternatives without a
    determinate covariance are skipped.  A copy's ``objective`` is its data
    cost (the regularisers are not evaluated for alternatives).
    """
    out = [replace(init, alternatives=(), ambiguous=False)]
    F = ConstantVelocity.F(init.t_end - init.t_start)
    for a in init.alternatives:
        if a.covariance is None:
            continue
        out.append(replace(
            init, x_start=a.state, x_end=F @ a.state, P_start=a.covariance, P_end=F @ a.covariance @ F.T,
            cost=a.cost, objective=a.cost, passes_chi2=a.passes_chi2, covariance_status="ok", covariance_message="",
            alternatives=(), ambiguous=False, notes=(*init.notes, "hypothesis from an ambiguous initiation"),
        ))
    return out


def window_grid(measurements: Measurements, geometry: Geometry, settings: InitiationSettings | None = None) -> GridResult:
    """The grid search of :func:`initiate` alone (to share between refinement methods)."""
    settings = settings or InitiationSettings()
    w = _Window.build(measurements, geometry)
    return grid_search(geometry, w.bt, w.z, w.sigma, settings.grid, k_best=settings.k_best,
                       half_plane=settings.half_plane)
