r"""iSAM2 tracker: the initiation window's graph continued incrementally, one update per scan.

Each scan adds a state, its constant-velocity motion factor and its
measurement factor, in one ``gtsam.ISAM2.update``.  At every scan the
filtered estimate of the newest state and its marginal covariance are
recorded; :meth:`ISAM2Tracker.finish` solves the tracker's whole graph
(the kept measurements) to convergence by batch Levenberg–Marquardt from
iSAM2's estimate and returns the smoothed trajectory.

The filtered estimate and covariance of the newest state come from its
marginal factor (:meth:`ISAM2Tracker._marginal`), exact and O(1): iSAM2's
``calculateEstimate`` back-substitutes into every old state whose solution
moved more than the wildfire threshold, which on a poorly observed track is
all of them after every scan.

Design (why not ``CustomFactor``): GTSAM copies the whole ``Values`` into
Python for every ``CustomFactor`` callback, so an iSAM2 update would cost
O(N) in the track length.  Here the measurement factors are linearised in
numpy (:mod:`fgdoppler.estimators.linearized`) and enter as native linear
factors; the tracker relinearises them itself, iSAM2-style: at every update
the factors of the ``relinearize_window`` most recent states (and every
``relinearize_every`` updates also of the ``relinearize_history`` states
before them, which on a poorly observed track go on moving long after their
scan) are checked and those whose state moved more than
``relinearize_position`` / ``relinearize_velocity`` from their linearisation
point are replaced (removed and re-added in the same update).  The recent
states' values for the check come from their joint marginal
(:meth:`ISAM2Tracker._means`), which does not stop where iSAM2's own
estimate stops back-substituting (the wildfire threshold); eliminated by QR
it agrees with iSAM2's full back-substitution to 5e-11 standard deviations
(7e-11 m on the first 300 s of the long benchmark's slow recording:
``python studies/isam2_check_values.py``; by Cholesky the per-state
marginals were up to 13 m, 0.5 % of a standard deviation, off there, and
kilometres off where pairs report milliseconds apart,
:meth:`ISAM2Tracker._means`).  The history check, which reaches 130
states back, reads that full back-substitution itself
(:meth:`ISAM2Tracker._solved`): O(N) in the states held, and cheaper there
than the joint marginal of so many states.  iSAM2's own relinearisation is
switched off (all factors are linear), and the factorisation is QR, which
survives the ill-conditioning of Doppler-only graphs.

Verdict reasons: ``covariance`` (some filtered covariances indeterminate),
``not-converged`` (the final smoothing hit its iteration cap), both
``"doubtful"``.

Through :func:`~fgdoppler.estimators.registry.run_estimator` the filtered
covariances are then checked against posterior samples of the data so far
and widened where those spread further
(``ISAM2Settings.sampled_covariance``,
:func:`~fgdoppler.estimators.spread.filtered_spread`); :func:`run_isam2`
and the tracker report the Gaussian marginals themselves.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._text import first_line
from fgdoppler.estimators.gating import NISGate
from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.linearized import MotionBlocks, linearize_rows
from fgdoppler.estimators.local import LocalFrame, in_computation_frame
from fgdoppler.estimators.marginals import upper_inverse
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.settings import ISAM2Settings, SmootherSettings
from fgdoppler.estimators.smoother import solve_smoother
from fgdoppler.estimators.verdict import NOT_CONVERGED, Event
from fgdoppler.estimators.warmup import WarmUp
from fgdoppler.estimators.window import feed_from_window_start, start_prior
from fgdoppler.factors import X, absolute_linear_factor
from fgdoppler.geometry import pair_labels
from fgdoppler.measurements import Measurements, scan_time
from fgdoppler.models.observation import check_channels
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, prefixed

__all__ = ["ISAM2Tracker", "run_isam2"]

FloatArray = NDArray[np.float64]

#: States marginalised out of iSAM2 at a time (``ISAM2Settings.keep_states``), at least: each batch rebuilds
#: iSAM2 from the kept states, so it comes once every max(this, keep / 4) scans.
_MARGINALISE_BATCH = 100


@dataclass
class _ScanData:
    channels: NDArray[np.intp]
    z: FloatArray
    sigma: FloatArray
    lin: FloatArray | None = None  # linearisation point of its factor (None: no factor)
    factor: int = -1  # index of its factor in iSAM2
    theta: FloatArray | None = None  # the state's value when inserted: iSAM2's linearisation point of it
    # its factors as added to iSAM2 (the Doppler one, the motion one from the state before), for a rebuild
    doppler: gtsam.LinearContainerFactor | None = None
    motion: gtsam.LinearContainerFactor | None = None


class ISAM2Tracker:
    """Incremental smoother over a growing constant-velocity trajectory.

    Start it with a window (:meth:`add_window`, as :func:`run_isam2` does
    with the initiation window), or feed it scans from the first: it then
    warms up (:mod:`fgdoppler.estimators.warmup`, ``ISAM2Settings.warmup_seconds``),
    holding them back until they can be solved together.  Guesses, the prior
    and every estimate are in the model's coordinates; the tracker computes
    in its computation frame (:mod:`fgdoppler.estimators.local`), so its
    answers move with a rigidly moved problem.

    Parameters
    ----------
    model
        Observation and motion model.
    settings
        Gate, Huber threshold, relinearisation thresholds.
    prior
        Optional ``(mean, covariance)`` on the first state.
    """

    def __init__(self, model: TrackingModel, settings: ISAM2Settings | None = None,
                 prior: tuple[ArrayLike, ArrayLike] | None = None) -> None:
        # computed in the model's computation frame; states cross at the public methods
        self.local, self.tracking_model = LocalFrame.of(model)
        self.model = self.tracking_model.observation
        self.motion_model = self.tracking_model.motion
        self.settings = settings or ISAM2Settings()
        params = gtsam.ISAM2Params()
        params.setFactorization("QR")
        params.enableRelinearization = False
        # Relinearising replaces factors all the time: reuse the freed slots (no measurable
        # speed effect here, but the factor list no longer grows with every replacement).
        params.findUnusedFactorSlots = True
        # Wildfire: after an update iSAM2 back-substitutes into every state whose solution
        # changed by more than this.  GTSAM's default (0.001) let each new measurement ripple
        # through hundreds of old states, so the per-scan cost grew with the track (0.30 ms at
        # 60 scans, 0.53 ms at 7,200); at 0.01 it is flat.  The newest state (the filtered
        # output) is always exact, and finish() back-substitutes fully.
        gn = gtsam.ISAM2GaussNewtonParams()
        gn.setWildfireThreshold(self.settings.wildfire_threshold)
        params.setOptimizationParams(gn)
        self._params = params
        self.isam = gtsam.ISAM2(params)
        self.motion = MotionBlocks(self.motion_model)
        self.prior = self.local.prior_in(prior)  # in the computation frame
        self.times: list[float] = []
        self.scans: list[_ScanData] = []
        self.relinearized: list[int] = []
        self.events: list[Event] = []
        self.gate = NISGate(self.settings.gate_probability, self.events, label=pair_labels(self.model))
        self.final_passes = 0
        self.converged = True
        self._last: tuple[FloatArray, FloatArray | None] | None = None  # newest (x, P) after an update
        self._pending: tuple[gtsam.NonlinearFactorGraph, gtsam.Values, list[int], list[int]] | None = None
        self._n_updates = 0
        self._warmup = WarmUp.of(self.settings, self.model.n_channels)
        # states [0, _oldest) are marginalised out of iSAM2 (their estimates when they left start finish());
        # _first is the factor on state _oldest that holds them (the prior, if any, before anything left)
        self._oldest = 0
        self._left: list[FloatArray] = []
        self._first: gtsam.LinearContainerFactor | None = None

    # -- helpers ----------------------------------------------------------------
    def _meas_factor(self, k: int, x_lin: FloatArray) -> gtsam.LinearContainerFactor | None:
        sd = self.scans[k]
        if sd.channels.size == 0:
            return None
        try:
            rows = linearize_rows(self.model, np.broadcast_to(x_lin, (sd.channels.size, x_lin.size)), sd.channels, sd.z,
                                  sd.sigma, self.settings.huber_k)
        except ValueError as exc:  # the predicted state sits on a sensor: drop this scan's factor
            self.events.append(Event(time=self.times[k], message=f"measurements skipped: {exc}"))
            sd.channels = sd.channels[:0]
            return None
        sd.doppler = absolute_linear_factor([X(k)], [rows.A], rows.b + rows.A @ x_lin)
        return sd.doppler

    def _marginal(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Estimate and covariance of state ``k`` from its marginal, exact and O(1) near the newest state.

        iSAM2's own estimate (``calculateEstimate``, ``getDelta``) back-substitutes
        into every state whose solution changed by more than the wildfire
        threshold — in a poorly observed track every state, after every scan,
        which made a long track O(N²).  Online the tracker needs only recent
        states, and a Gaussian marginal's mean is the MAP: with every factor
        linear, state ``k`` is its linearisation point (the value it was
        inserted with) plus :math:`\\mathbf R^{-1}\\mathbf d` of its marginal
        conditional :math:`\\mathbf R\\,\\delta\\mathbf x_k = \\mathbf d`, and its
        covariance :math:`\\mathbf R^{-1}\\mathbf R^{-\\top}`.  The marginal is
        eliminated by QR: the default (Cholesky) squares the condition number
        and lost six digits here.

        Raises
        ------
        numpy.linalg.LinAlgError, RuntimeError
            If the marginal is singular (indeterminate).
        """
        c = self.isam.marginalFactor(X(k), gtsam.EliminateQR)
        R = np.asarray(c.R())
        Ri = upper_inverse(R)
        theta = self.scans[k].theta
        assert theta is not None
        return theta + Ri @ np.asarray(c.d()), Ri @ Ri.T

    def _means(self, ks: list[int]) -> FloatArray:
        r"""Estimates of states ``ks``: the mean of their joint marginal, solved in one call.

        With every factor linear, the joint marginal of the states
        :math:`\mathbf x_{k_1},\dots,\mathbf x_{k_m}` is a Gaussian Bayes
        net :math:`\mathbf R\,\delta\mathbf x = \mathbf d` about their
        linearisation points (iSAM2's ``jointBayesNet``, which assembles it
        from the Bayes tree's cliques on the way to the root), and its mean,
        the MAP of the linear system, is the back-substitution
        :math:`\boldsymbol\theta + \mathbf R^{-1}\mathbf d`.  One joint
        marginal costs less than half of a ``marginalFactor`` per state (the
        tracker's check of its 10 recent states: median 0.13 against 0.31 ms
        on the long benchmark's slow recording, ``python -m benchmarks
        --only check``) and is more exact: 5e-11 standard deviations from the
        full back-substitution against 1.2e-9 (``python
        studies/isam2_check_values.py``).  The history check, which reaches
        130 states back, reads the full back-substitution instead
        (:meth:`_solved`): the joint marginal of so many states costs more.

        The marginal is eliminated by QR, as :meth:`_marginal`'s is.
        GTSAM's default (Cholesky; with it :func:`run_isam2` took 0.85-0.89
        times the CPU time on the paper's scenarios, four runs each) squares
        the condition number, and where two states lie milliseconds
        apart — pairs that report a few ms apart, or timestamps with a little
        jitter — their motion factor pins their difference to micrometres
        while the track is known to hundreds of metres: the Cholesky
        marginals of the older states were then wrong, the measurements were
        relinearised there and the track diverged (case a 45 km with pair 2's
        times 10 ms after pair 1's, two recordings: filtered position RMSE 35
        and 146 km, NEES 9e8 and 2e5, against 138 and 111 m, NEES 1.2, by QR,
        whose joint means agree with iSAM2's full back-substitution to 5e-12
        standard deviations, the per-state marginals' to 2e-8;
        ``tests/estimators/test_trackers.py``, ``python
        studies/async_pairs.py``).  Where QR calls the system indeterminate,
        iSAM2's own estimate is used (its back-substitution, which stops where
        the solution moved less than the wildfire threshold).
        """
        try:
            delta = self.isam.jointBayesNet([X(k) for k in ks], gtsam.EliminateQR).optimize()
        except RuntimeError:
            est = self.isam.calculateEstimate([X(k) for k in ks])
            return np.array([est.atVector(X(k)) for k in ks])
        theta = np.array([self.scans[k].theta for k in ks])
        return theta + np.array([delta.at(X(k)) for k in ks])

    def _solved(self, ks: list[int]) -> FloatArray:
        r"""Estimates of states ``ks`` from iSAM2's full back-substitution, for a check that reaches far back.

        ``calculateBestEstimate`` solves every state iSAM2 holds,
        :math:`\boldsymbol\theta + \delta` with :math:`\delta` back-substituted
        through the whole Bayes tree (no wildfire threshold): the MAP of the
        linear system, as :meth:`_means` gives it, to 1e-9 m on the long
        benchmark's slow recording.  It costs O(N) in the states held (at
        most ``keep_states`` and a quarter), where the joint marginal of
        the 130 states the history check reads costs more: 2.3-3.3 against
        0.3-1.2 ms, the reading of the values included (slow recording, first
        2,400 s, one hypothesis; docs/concepts.md, "The history check reads
        the full solution").  For the 10 recent states alone the joint
        marginal is the cheaper (0.14-0.26 against 0.24-1.06 ms).  If the
        back-substitution is not finite (a singular factor) or GTSAM refuses
        it as indeterminate, the joint marginal is read instead.
        """
        try:
            best = self.isam.calculateBestEstimate()
        except RuntimeError:  # GTSAM's indeterminate system: the joint marginal eliminates again by QR
            return self._means(ks)
        xs = np.array([best.atVector(X(k)) for k in ks])
        return xs if np.all(np.isfinite(xs)) else self._means(ks)

    def _update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, remove: list[int],
                owners: list[int], order: gtsam.KeyGroupMap | None = None) -> None:
        result = self.isam.update(graph, values, remove, order)
        for k, idx in zip(owners, result.getNewFactorsIndices(), strict=False):
            if k >= 0:
                self.scans[k].factor = int(idx)

    def _relinearize(self, candidates: range, graph: gtsam.NonlinearFactorGraph, owners: list[int],
                     remove: list[int], *, history: bool = False) -> int:
        """Replace the factors of the states in ``candidates`` that moved; vectorised over all of them.

        ``history``: the check reaches the older states too; their values come
        from the full back-substitution (:meth:`_solved`), else from the joint
        marginal (:meth:`_means`).
        """
        js = [j for j in candidates if self.scans[j].lin is not None and self.scans[j].channels.size]
        if not js:
            return 0
        xs = self._solved(js) if history else self._means(js)
        lin = np.array([self.scans[j].lin for j in js])
        d = np.abs(xs - lin)
        st = self.settings
        half = self.motion_model.dim
        moved = np.any(d[:, :half] > st.relinearize_position, axis=1) | np.any(
            d[:, half:] > st.relinearize_velocity, axis=1)
        sel = [j for j, mv in zip(js, moved, strict=True) if mv]
        if not sel:
            return 0
        xsel = xs[moved]
        ch = np.concatenate([self.scans[j].channels for j in sel])
        z = np.concatenate([self.scans[j].z for j in sel])
        sg = np.concatenate([self.scans[j].sigma for j in sel])
        counts = [self.scans[j].channels.size for j in sel]
        owner = np.repeat(np.arange(len(sel)), counts)
        rows = linearize_rows(self.model, xsel[owner], ch, z, sg, st.huber_k)
        start = 0
        for i, j in enumerate(sel):
            sl = slice(start, start + counts[i])
            start += counts[i]
            A, b = rows.A[sl], rows.b[sl]
            remove.append(self.scans[j].factor)
            sd = self.scans[j]
            sd.doppler = absolute_linear_factor([X(j)], [A], b + A @ xsel[i])
            graph.add(sd.doppler)
            owners.append(j)
            self.scans[j].lin = xsel[i].copy()
        return len(sel)

    # -- public -------------------------------------------------------------------
    def add_window(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                   guesses: ArrayLike) -> tuple[FloatArray, FloatArray | None]:
        """Add several scans (e.g. the initiation window) in one iSAM2 update, ungated.

        One update makes the window's system determined as a whole even when
        a single scan is not (two Doppler values, four unknowns).  Returns the
        filtered ``(x, P)`` of the last state.
        """
        g = self.local.state_in(np.asarray(guesses, dtype=float).reshape(-1, self.motion_model.n))
        return self.local.out(*self._add_window(times, channels, z, sigma, g))

    def _add_window(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                    g: FloatArray) -> tuple[FloatArray, FloatArray | None]:
        """:meth:`add_window` in the computation frame."""
        ts = np.asarray(times, dtype=float).reshape(-1)
        if ts.size == 0:
            raise ValueError("add_window needs at least one scan")
        if self._warmup is not None:
            self._warmup.refuse_window()
        self._warmup = None  # a window is the start the warm-up would build
        self._pending = (gtsam.NonlinearFactorGraph(), gtsam.Values(), [], [])
        for k in range(ts.size - 1):
            self._add_scan(ts[k], channels[k], z[k], sigma[k], g[k], gate=False, defer=True)
        return self._add_scan(ts[-1], channels[-1], z[-1], sigma[-1], g[-1], gate=False)

    def add_scan(self, t: float, channels: ArrayLike, z: ArrayLike, sigma: ArrayLike,
                 x_guess: ArrayLike | None = None, *, gate: bool = True) -> tuple[FloatArray, FloatArray | None]:
        """Add the measurements of one time; returns the filtered ``(x, P)`` of the new state.

        Parameters
        ----------
        t
            Scan time; must be later than the previous scan's.
        channels, z, sigma
            The measurements of this time.
        x_guess
            Initial value of the new state (default: prediction from the
            previous estimate).  At the very first scan: the start of the
            warm-up's solution (without one, a multi-start initiation of the
            warm-up's scans finds it), or, with the warm-up off, required.
        gate
            Apply the NIS gate against the prediction (needs a previous
            covariance; the warm-up's scans are not gated).

        Returns
        -------
        x, P
            The new state's filtered estimate and covariance (``None`` when
            indeterminate).  During the warm-up (a tracker whose first update
            is a scan, :attr:`warming_up`): a state of NaN and ``None``, and
            at the scan that completes it, the estimate from all its scans.

        Raises
        ------
        ValueError
            If ``t`` is not after the previous scan (out of order).
        """
        guess = None if x_guess is None else self.local.state_in(x_guess)
        if self._warmup is not None:
            if not self._warmup.hold(self.model, t, channels, z, sigma, guess):
                return np.full(self.motion_model.n, np.nan), None
            return self.local.out(*self._start_warmed_up())
        return self.local.out(*self._add_scan(t, channels, z, sigma, guess, gate=gate))

    def _add_scan(self, t: float, channels: ArrayLike, z: ArrayLike, sigma: ArrayLike,
                  x_guess: FloatArray | None, *, gate: bool, defer: bool = False) -> tuple[FloatArray, FloatArray | None]:
        """:meth:`add_scan` in the computation frame, after the warm-up; ``defer`` keeps the update for later."""
        t = scan_time(t, self.times[-1] if self.times else None)
        c = np.asarray(channels, dtype=np.intp).reshape(-1)
        zz = np.asarray(z, dtype=float).reshape(-1)
        ss = np.broadcast_to(np.asarray(sigma, dtype=float), zz.shape).copy()
        k = len(self.times)
        x_pred, P_pred = self._predict(t, x_guess)
        keep = np.ones(c.size, dtype=bool)
        if gate and P_pred is not None and c.size:
            keep = self.gate.scan(self.model, x_pred, P_pred, t, c, zz, ss)
        self.times.append(t)
        self.scans.append(_ScanData(channels=c[keep], z=zz[keep], sigma=ss[keep]))
        graph, values, owners, remove = self._pending or (gtsam.NonlinearFactorGraph(), gtsam.Values(), [], [])
        self._add_factors(k, x_pred, graph, values, owners)
        if defer:
            self._pending = (graph, values, owners, remove)
            return x_pred, None
        self._pending = None
        st = self.settings
        start = max(0, k - st.relinearize_window)
        history = bool(st.relinearize_history) and self._n_updates % st.relinearize_every == 0
        if history:
            start = max(0, start - st.relinearize_history)
        n_relin = self._relinearize(range(start, k), graph, owners, remove, history=history) if self._n_updates else 0
        self._n_updates += 1
        try:
            self._update(graph, values, remove, owners)
        except RuntimeError as exc:
            raise RuntimeError(
                f"iSAM2 update at t = {t} failed: {first_line(exc)} "
                "(an underdetermined start: add the initiation window in one update, or use a prior)"
            ) from exc
        self.relinearized.append(n_relin)
        self._last = self._filtered(k, t)
        self._marginalise_old(k)
        return self._last

    def _marginalise_old(self, k: int) -> None:
        r"""Marginalise the states more than ``keep_states`` behind the newest ``k`` out of iSAM2, in batches.

        GTSAM's iSAM2 update costs O(N) in the states it holds.  States beyond
        the relinearisation's reach keep their linear factors for good, so
        their Gaussian marginal is exact: the leaving states
        :math:`\mathbf x_{o},\dots,\mathbf x_{o'-1}` are eliminated by QR
        from their own factors (the factor on :math:`\mathbf x_o` that holds
        the states before it, or the prior; the motion factors up to
        :math:`\mathbf x_{o'}`; their Doppler factors), which leaves rows
        :math:`\mathbf A\mathbf x_{o'} = \mathbf b` on the first kept state,
        and iSAM2 is rebuilt in one update from those rows and the kept
        states' factors.  (GTSAM's
        own ``marginalizeLeaves`` needs the old states to be leaves of the
        Bayes tree, which the incremental ordering does not ensure: it raised
        or crashed the process on the long benchmark's recordings.)  The
        leaving states' current estimates start :meth:`finish`.
        """
        st = self.settings
        if not st.keep_states:
            return
        keep = max(st.keep_states, st.relinearize_window + st.relinearize_history + 1)
        if k - self._oldest < keep + max(_MARGINALISE_BATCH, keep // 4):
            return
        if not any(sd.doppler is not None for sd in self.scans[self._oldest:]):
            return  # no Doppler factor yet: the graph is linear and finish() reads every state from iSAM2
        o, new = self._oldest, k - keep
        best = self.isam.calculateBestEstimate()
        # the leaving states' own factors (every one linear, in absolute coordinates: linearised at zero)
        old = gtsam.NonlinearFactorGraph()
        zero = gtsam.Values()
        if self._first is not None:
            old.add(self._first)
        for j in range(o, new + 1):
            zero.insert(X(j), np.zeros(self.motion_model.n))
            sd = self.scans[j]
            if j > o and sd.motion is not None:
                old.add(sd.motion)
            if j < new and sd.doppler is not None and sd.channels.size:
                old.add(sd.doppler)
        leaving = gtsam.Ordering()
        for j in range(o, new):
            leaving.push_back(X(j))
        _, rest = old.linearize(zero).eliminatePartialSequential(leaving, gtsam.EliminateQR)
        A, b = rest.jacobian()
        self._first = absolute_linear_factor([X(new)], [A], b)
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        owners: list[int] = []
        graph.add(self._first)
        owners.append(-1)
        for j in range(new, k + 1):
            theta, motion = self.scans[j].theta, self.scans[j].motion
            assert theta is not None
            values.insert(X(j), theta)
            if j > new:
                assert motion is not None
                graph.add(motion)
                owners.append(-1)
        for j in range(new, k + 1):
            sd = self.scans[j]
            if sd.doppler is not None and sd.channels.size:
                graph.add(sd.doppler)
                owners.append(j)
        self._left.extend(np.asarray(best.atVector(X(j)), dtype=float) for j in range(o, new))
        for j in range(o, new):  # their information now lives in _first
            self.scans[j].doppler = self.scans[j].motion = None
        self.scans[new].motion = None
        self._oldest = new
        # eliminated oldest first, as the incremental updates leave it: the newest state at the root, where
        # the next scans attach (a fresh iSAM2 orders all-new keys freely by COLAMD)
        groups = gtsam.KeyGroupMap()
        for j in range(new, k + 1):
            groups.insert2(X(j), j - new)
        self.isam = gtsam.ISAM2(self._params)
        self._update(graph, values, [], owners, groups)

    def _motion_factor(self, j: int) -> gtsam.LinearContainerFactor:
        """The constant-velocity factor between states ``j - 1`` and ``j``."""
        Ap, An = self.motion(self.times[j] - self.times[j - 1])
        return absolute_linear_factor([X(j - 1), X(j)], [Ap, An], np.zeros(An.shape[0]))

    def _filtered(self, k: int, t: float) -> tuple[FloatArray, FloatArray | None]:
        """The newest state's estimate and covariance (``None`` and an event when indeterminate)."""
        try:
            x, P = self._marginal(k)
            if not (np.all(np.isfinite(P)) and np.all(np.isfinite(x))):
                raise RuntimeError("non-finite marginal")
        except (RuntimeError, np.linalg.LinAlgError) as exc:
            self.events.append(Event(time=t, message=f"marginal covariance indeterminate: {first_line(exc)}"))
            return np.asarray(self.isam.calculateEstimate([X(k)]).atVector(X(k)), dtype=float), None
        return x, P

    @property
    def warming_up(self) -> bool:
        """Whether the tracker still holds its first scans back (:mod:`fgdoppler.estimators.warmup`)."""
        return self._warmup is not None

    def _start_warmed_up(self) -> tuple[FloatArray, FloatArray | None]:
        w, self._warmup = self._warmup, None
        assert w is not None
        states = w.start(self.tracking_model, self.prior, huber_k=self.settings.huber_k, events=self.events)
        return self._add_window(w.times, list(w.channels), list(w.z), list(w.sigma), states)

    def _predict(self, t: float, x_guess: ArrayLike | None) -> tuple[FloatArray, FloatArray | None]:
        """Initial value of the state at ``t`` and its predicted covariance (``None`` when unknown)."""
        k = len(self.times)
        if k == 0:
            if x_guess is None:
                raise ValueError("the first scan needs an initial guess x_guess "
                                 "(or the warm-up on, warmup_seconds > 0, to start without one)")
            return np.asarray(x_guess, dtype=float), None
        dt = t - self.times[-1]
        m = self.motion_model
        if self._pending is not None or self._last is None:
            # Inside a deferred window the previous state is not solved yet: no covariance.
            last_x, last_P = self.scans[k - 1].theta, None
        else:
            last_x, last_P = self._last
        assert last_x is not None
        x_pred = m.propagate(last_x, dt) if x_guess is None else np.asarray(x_guess, dtype=float)
        return x_pred, None if last_P is None else m.predict_covariance(last_P, dt)

    def _add_factors(self, k: int, x_pred: FloatArray, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                     owners: list[int]) -> None:
        """State ``k``'s value, its prior (first state), motion factor and measurement factor."""
        values.insert(X(k), x_pred)
        self.scans[k].theta = x_pred.copy()
        if k == 0 and self.prior is not None:
            mean, cov = self.prior
            Ri = np.linalg.inv(np.linalg.cholesky(cov))
            self._first = absolute_linear_factor([X(0)], [Ri], Ri @ mean)
            graph.add(self._first)
            owners.append(-1)
        if k:
            motion = self._motion_factor(k)
            self.scans[k].motion = motion
            graph.add(motion)
            owners.append(-1)
        f = self._meas_factor(k, x_pred)
        if f is not None:
            graph.add(f)
            owners.append(k)
            self.scans[k].lin = x_pred.copy()

    def kept_measurements(self) -> Measurements:
        """The measurements in the tracker's graph: every scan's, less what the gate rejected."""
        counts = [sd.channels.size for sd in self.scans]
        if sum(counts) == 0:
            raise ValueError("the tracker holds no measurements")
        return Measurements.from_scans(self.times, [sd.channels for sd in self.scans], [sd.z for sd in self.scans],
                                       [sd.sigma for sd in self.scans])

    def finish(self, *, covariances: bool = True,
               progress: Progress | None = None) -> tuple[FloatArray, FloatArray | None]:
        """Solve the tracker's whole graph to convergence; returns smoothed states ``(n, 4)`` and covariances.

        The graph (prior, motion factors, the kept measurements, the same
        Huber loss) is solved by the offline smoother's Levenberg–Marquardt
        (:func:`~fgdoppler.estimators.smoother.solve_smoother`), started from
        iSAM2's estimate.  Undamped Gauss–Newton passes inside iSAM2 did not
        converge on poorly observed long tracks (100 passes relinearising all
        3,600 factors of a slow target, 13 s); LM with Marquardt scaling
        converges there and costs O(N) per iteration.  ``final_passes`` caps
        its iterations; ``converged`` is cleared and an event added when it
        does not converge.  A tracker still warming up starts from the
        scans it holds first.
        """
        if self._warmup is not None and self._warmup.times:
            self._start_warmed_up()
        n = len(self.times)
        best = self.isam.calculateBestEstimate()
        start = np.array(self._left + [best.atVector(X(j)) for j in range(self._oldest, n)])
        if not self._oldest and not any(sd.channels.size for sd in self.scans):
            # a prior and motion only: linear, solved already
            covs = np.array([self.isam.marginalCovariance(X(j)) for j in range(n)]) if covariances else None
            return self.local.out(start, covs)
        lm = SmootherSettings(huber_k=self.settings.huber_k, max_iterations=self.settings.final_passes,
                              covariances=covariances, reinitiate=False, region_bound=False)
        sol = solve_smoother(self.kept_measurements(), self.tracking_model, start, lm, prior=self.prior,
                             times=np.asarray(self.times), progress=prefixed(progress, "isam2 final smoothing"))
        self.final_passes = sol.iterations
        for r in sol.reasons:
            if r.code == "not-converged":
                self.converged = False
            self.events.append(Event(time=self.times[-1], message=f"final smoothing: {r.message}"))
        return self.local.out(sol.states, sol.covariances)


@in_computation_frame
def run_isam2(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: ISAM2Settings | None = None,
    *,
    progress: Progress | None = None,
) -> TrackResult:
    """Initiation window in iSAM2, then one update per later scan; filtered and smoothed results.

    The window's states start at the optimum of this tracker's window graph
    (:func:`~fgdoppler.estimators.window.window_start`); its scans are added
    ungated (they produced the initiation).  ``filtered`` holds the estimate
    of the newest state after each update from the window's end on;
    ``smoothed`` the whole trajectory after :meth:`ISAM2Tracker.finish`.
    """
    settings = settings or ISAM2Settings()
    check_channels(model.observation, measurements)
    t_begin = time.perf_counter()
    tracker = ISAM2Tracker(model, settings, start_prior(model, init))
    times, states, covs = feed_from_window_start(tracker, model, measurements, init, tracker.events,
                                                 huber_k=settings.huber_k, progress=progress, name="isam2")
    n_online = len(tracker.relinearized)
    smoothed, scov = tracker.finish(covariances=settings.smoothed_covariances, progress=progress)
    filtered = Estimates.from_lists("filtered", times, states, covs)
    smoothed_est = Estimates.from_lists("smoothed", list(tracker.times), list(smoothed),
                                        list(scov) if scov is not None else [None] * len(tracker.times))
    reasons = [r for r in (filtered.covariance_reason(),) if r is not None]
    if not tracker.converged:
        reasons.append(NOT_CONVERGED)
    return TrackResult(
        estimator="isam2",
        settings=settings,
        estimates=(filtered, smoothed_est),
        reasons=tuple(reasons),
        events=tuple(tracker.events),
        nis=tracker.gate.as_array(),
        relinearizations=np.array(tracker.relinearized[:n_online], dtype=np.int64),
        iterations=tracker.final_passes,
        wall_time=time.perf_counter() - t_begin,
    )
