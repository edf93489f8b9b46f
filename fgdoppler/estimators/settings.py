"""Settings of the trackers: a shared base and one class per estimator with only its options.

The model every estimator shares (observation, motion, zone, weak prior) is
a :class:`~fgdoppler.models.tracking.TrackingModel`; the classes here hold
how each estimator works on it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from scipy.stats import chi2

__all__ = ["EKFSettings", "FixedLagSettings", "GaussianSumSettings", "ISAM2Settings", "MapSettings",
           "ParticleSettings", "SampledCovarianceSettings", "SmootherSettings", "StreamingSettings", "TrackerSettings"]


def _positive(value: float, name: str) -> None:
    if isinstance(value, bool) or not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number, got {value!r}")


def _flag(value: bool, name: str) -> None:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be True or False, got {value!r}")


def _per_pair_sigma(value: Any, name: str, unit: str, each: str = "pair") -> float | tuple[float, ...]:
    """``value`` as a float or a tuple of floats, each finite and >= 0 (``unit``); ``name`` and ``each`` (what
    a tuple has one value per) in the refusal."""
    many = isinstance(value, (tuple, list))
    try:
        values = [float(v) for v in (value if many else [value])]
    except (TypeError, ValueError):
        values = []
    if not values or not all(math.isfinite(v) and v >= 0 for v in values):
        raise ValueError(f"{name} must be a number >= 0 ({unit}) or one per {each}, got {value!r}")
    return tuple(values) if many else values[0]


def _bias_sigma(value: Any) -> float | tuple[float, ...]:
    """``bias_sigma`` as a float or a tuple of floats, each finite and >= 0 (m/s)."""
    return _per_pair_sigma(value, "bias_sigma", "m/s")


def _clock_sigma(value: Any) -> float | tuple[float, ...]:
    """``clock_sigma`` as a float or a tuple of floats, each finite and >= 0 (s)."""
    return _per_pair_sigma(value, "clock_sigma", "s")


def _site_sigma(value: Any) -> float | tuple[float, ...]:
    """``site_sigma`` as a float or a tuple of floats, each finite and >= 0 (m)."""
    return _per_pair_sigma(value, "site_sigma", "m", "site")


def _dimension(dim: int) -> None:
    if dim not in (2, 3):
        raise ValueError(f"a model has 2 or 3 spatial dimensions, got {dim!r}")


def _in_space_unless_given(given: bool | None, dim: int) -> bool:
    """A switch whose ``None`` means on in space (``dim`` 3) and off in the plane (``dim`` 2)."""
    _dimension(dim)
    return dim == 3 if given is None else given


def _count(value: int, name: str, minimum: int = 1, meaning: str = "") -> None:
    """Raise unless ``value`` is a whole number (not a bool) of at least ``minimum``; ``meaning`` adds what a
    special value does to the message."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}{meaning}, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class TrackerSettings:
    """Base of every tracker's settings: the measurement gate, the robust loss, the pairs' declared
    calibration and clock uncertainty, the sensor sites' declared position uncertainty, and the seed of the
    estimator's random numbers.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate: a measurement whose normalised innovation against the
        prediction exceeds the χ²₁ quantile at this probability is rejected
        and reported.  ``None`` disables gating.  (The offline smoother gates
        only the EKF pass that starts it.)
    huber_k : float or None, default None
        Huber loss with this threshold (whitened units; 1.345 gives 95 %
        efficiency on Gaussian data) on every Doppler residual: quadratic up
        to ``k``, linear beyond, so a few gross outliers cannot drag the
        estimate.  ``None`` for the Gaussian loss.
    bias_sigma : float or tuple of float, default 0.0
        Each pair's Doppler calibration uncertainty (m/s, one standard
        deviation; one value for every pair or one per pair); what each
        estimator does with it is said in its own settings.
    clock_sigma : float or tuple of float, default 0.0
        Each pair's clock uncertainty (s, one standard deviation; one value
        for every pair or one per pair); what each estimator does with it is
        said in its own settings.
    site_sigma : float or tuple of float, default 0.0
        Each sensor site's position uncertainty (m, one standard deviation
        in every coordinate; one value for every site or one per site, in
        the order the pairs first name them:
        :meth:`~fgdoppler.geometry.Geometry.sites`).  Every estimator's
        reported covariances then include what such site errors would do to
        its answer, a consider covariance
        (:mod:`~fgdoppler.estimators.site_offsets`; four runs of the
        estimator per site coordinate, added with the clock offsets' share,
        last).  The track does not change, nor does the verdict but for a
        filter's whole-track comparison with the reference smoother, which
        reads the grown covariances.  Needs a Doppler model.
    seed : int, default 0
        Seed of every random number the estimator draws: the particle
        estimators' particles, the sampled posterior whose Gaussian sum
        starts the filters where their start is split (``split_ratio``), the
        filters' sampled covariance checks, the smoother's sampled
        covariance and posterior mean, and those of the reference smoother
        that a filter's verdict runs.  The same input and seed give the same
        answer to the bit on one machine; another seed shows the Monte Carlo
        spread of what was sampled (in the paper's well-observed scenarios no
        track of the Gaussian trackers moved; in its curved valleys a
        filter's error moved by a tenth of itself: docs/concepts.md, "Random
        numbers and the seed").  Floating-point arithmetic differs between
        CPUs, which acts as another seed.  The initiation draws no random
        numbers that depend on it.
    """

    gate_probability: float | None = 0.9999
    huber_k: float | None = None
    bias_sigma: float | tuple[float, ...] = 0.0
    clock_sigma: float | tuple[float, ...] = 0.0
    site_sigma: float | tuple[float, ...] = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        p = self.gate_probability
        if p is not None and (isinstance(p, bool) or not 0 < p < 1):
            raise ValueError(f"gate_probability must be in (0, 1) or None, got {p!r}")
        if self.huber_k is not None:
            _positive(self.huber_k, "huber_k")
        object.__setattr__(self, "bias_sigma", _bias_sigma(self.bias_sigma))
        object.__setattr__(self, "clock_sigma", _clock_sigma(self.clock_sigma))
        object.__setattr__(self, "site_sigma", _site_sigma(self.site_sigma))
        _count(self.seed, "seed", 0)

    @property
    def gate(self) -> float:
        """NIS threshold (``inf`` when gating is off)."""
        return float(chi2.ppf(self.gate_probability, 1)) if self.gate_probability is not None else math.inf

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, with the class name under ``"type"``."""
        return {"type": type(self).__name__, **dataclasses.asdict(self)}


@dataclass(frozen=True, kw_only=True)
class GaussianSumSettings(TrackerSettings):
    """Base of the Gaussian trackers that carry a non-Gaussian start as a Gaussian sum (EKF, iSAM2, fixed-lag).

    Parameters
    ----------
    components : int, default 8
        When the initiation's window has no Gaussian posterior — its
        ``nonlinear`` finding or a curvature beyond ``split_ratio``, or
        other solutions (``ambiguous``) — the posterior is sampled
        (:func:`~fgdoppler.estimators.particle.window_posterior`) and split
        into at most this many Gaussian terms; the tracker runs from each
        and reports their mixture, weighted by how well each predicts the
        data (:mod:`fgdoppler.estimators.ambiguity`).  ``1`` keeps one
        Gaussian (the initiation's, and the hypotheses of an ambiguous one).
    split_ratio : float, default 2.5
        Split the start also where the initiation's covariance still passes
        as a description of its likelihood but its curvature probe
        (:attr:`Initiation.curvature <fgdoppler.estimators.initiation.Initiation>`:
        the cost's rise three standard deviations out over the covariance's
        prediction) exceeds this ratio or falls below its inverse.  A
        Kalman filter linearises the measurements over its whole covariance;
        where the valley already bends across it, narrower terms track
        better.  On the paper's windows the ratio is 1.1–2.0 where the data
        observe the track well and 3.2 and more in the 25 km scenarios, which
        the split makes 120–430 m more accurate (docs/concepts.md, "Where a
        Gaussian start is split").  ``inf``: only on the ``nonlinear``
        finding.
    restarts : bool, default True
        At checkpoints, find the best fit of all data so far (Levenberg–Marquardt
        from the tracker's own estimate, unless a fresh multi-start
        initiation finds a mode 1,000 times more likely) and restart the
        tracker from it when each lies outside the other's 99.9 % region
        (decided under the Huber loss where a few measurements pull the
        squared-loss fit away: outliers do not restart it;
        :mod:`fgdoppler.estimators.restart`).
    """

    components: int = 8
    split_ratio: float = 2.5
    restarts: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _count(self.components, "components")
        r = self.split_ratio
        if isinstance(r, bool) or not isinstance(r, (int, float)) or math.isnan(r) or r < 1:
            raise ValueError(f"split_ratio must be a number >= 1 (inf: split only on the nonlinear finding), got {r!r}")
        _flag(self.restarts, "restarts")

    def splits(self, curvature: float | None) -> bool:
        """Whether a start of this curvature probe ratio is split by ``split_ratio`` (:class:`GaussianSumSettings`)."""
        return curvature is not None and not (1.0 / self.split_ratio <= curvature <= self.split_ratio)


@dataclass(frozen=True, kw_only=True)
class StreamingSettings(GaussianSumSettings):
    """Base of the graph trackers fed scan by scan (iSAM2, fixed-lag): their warm-up.

    Parameters
    ----------
    warmup_seconds : float, default 4.5
        A tracker whose first update is a single scan (not a window) holds
        its scans back until they span this long and hold ``warmup_per_pair``
        measurements per pair, then solves them together and adds them as
        one window (:mod:`fgdoppler.estimators.warmup`); it returns no
        estimate until then.  One scan per update from a broad prior
        diverges (measured at 50 scans/s: 45 km off at 0.5 s with a stated
        standard deviation of 58 m).  The default is the initiation window's
        span (:meth:`~fgdoppler.measurements.Measurements.initiation_window`).
        Trackers started with a window (``add_window``, as every registry
        estimator is) never warm up.
    warmup_per_pair : int, default 10
        Measurements per pair on average the warm-up must hold as well.
        ``warmup_seconds=0`` and ``warmup_per_pair=0`` switch the warm-up
        off: every scan is one update from the first (with an informative
        prior only).
    """

    warmup_seconds: float = 4.5
    warmup_per_pair: int = 10

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.warmup_seconds, bool) or not (
                math.isfinite(self.warmup_seconds) and self.warmup_seconds >= 0):
            raise ValueError(f"warmup_seconds must be a finite number >= 0, got {self.warmup_seconds!r}")
        _count(self.warmup_per_pair, "warmup_per_pair", 0)

    @property
    def warms_up(self) -> bool:
        """Whether a tracker fed a single scan first warms up."""
        return self.warmup_seconds > 0 or self.warmup_per_pair > 0


@dataclass(frozen=True, kw_only=True)
class SampledCovarianceSettings(GaussianSumSettings):
    """Base of the trackers whose Gaussian covariance is checked against posterior samples (EKF, iSAM2, fixed-lag).

    Parameters
    ----------
    sampled_covariance : bool, default True
        At checks every ``sampling_interval`` seconds, draw posterior samples
        of the data so far about the filtered estimate and widen the
        filtered covariances wherever the samples spread more than twice as
        far (in variance) as the Gaussian covariance says
        (:func:`~fgdoppler.estimators.spread.filtered_spread`; applied by
        :func:`~fgdoppler.estimators.registry.run_estimator` after the
        verdict, not by the trackers fed by hand,
        ``ExtendedKalmanFilter``, ``ISAM2Tracker`` and
        ``GaussianSumTracker``, ``FixedLagTracker``).  The estimates do not
        change.  On a poorly observed track the filter's covariance is a
        linearisation of a curved, long-tailed posterior and understates
        the error: measured on the paper's six scenarios (100 runs each,
        seed 2026) the run-averaged NEES of iSAM2's filtered estimates in
        case a 5 km drops from 9.17 to 6.39, the EKF's in case b 25 km from
        6.28 to 3.48, at 0.04–0.12 s a run (docs/concepts.md).  The
        fixed-lag smoother's lagged estimates are checked against the data
        up to ``lag`` seconds after their time, which they have read.  Where
        the process noise puts the samples beyond their reach (long
        recordings), the covariances are widened towards the posterior of
        the data they have read linearised about the verdict's reference
        smoother's track instead (not with ``verify=False``;
        :mod:`~fgdoppler.estimators.linearized_posterior`): on 600 s
        recordings of the paper's pairs the EKF's NEES 9.2 → 4.3 and
        9.0 → 3.8, the fixed-lag smoother's 7.4 → 4.7 and 729 → 35
        (``studies/long_filters.py``); by default at every estimate
        (``linearised_everywhere``; then 4.1 and 3.7, 4.7 and 4.4).
    sampling_interval : float, default 5.0
        Seconds between two checks; doubled after each check that widened
        nothing (up to 8 times), and never less than a tenth of the time
        since the first measurement, so a long recording costs a bounded
        number of samples per measurement.
    linearised_everywhere : bool, default True
        With ``sampled_covariance`` and a reference smoother (not with
        ``verify=False``): widen every covariance, not only those beyond
        the samples' reach, towards the posterior of the data it has read
        linearised about the reference smoother's track, after the sampled
        checks (which are spaced, back off, and carry a check's widening to
        the next, where a covariance can change shape).  Measured on the
        accuracy benchmark (100 runs per scenario): the runs of the EKF,
        iSAM2 and the fixed-lag smoother whose NEES averages beyond the χ²₄
        99.9 % point and whose verdict is ``ok`` go from 10 to 6 (seed 2026)
        and from 6 to 1 (seed 7), the run-averaged NEES of case a 5 km from
        5.27 / 6.39 / 4.63 to 3.80 / 4.48 / 4.42 (seed 2026); the cost: in
        the poorly observed scenarios some fall below the 95 % band
        (conservative, 2.87–3.45 with seed 2026, 3.09–3.43 with seed 7;
        docs/concepts.md, "The linearised enclosure at every estimate").
        The estimates do not change, and neither does the verdict: its
        whole-track ``reference`` finding reads the covariances without this
        enclosure, which is built from the reference's own track and could
        not disagree with it.  The covariances then depend on the whole
        recording through that track (its point of linearisation; each
        posterior reads only the data its estimate has read); ``False``
        applies the enclosure only beyond the samples' reach, so that on
        recordings the samples cover no covariance reads data after its own
        time.
    bias_sigma : float or tuple of float, default 0.0
        Each pair's Doppler calibration uncertainty (m/s, one standard
        deviation; one value for every pair or one per pair), as for
        :class:`SmootherSettings`: the reported covariances of every
        estimate then include what constant offsets of that size would do
        to the answer — the tracker run again, from its start moved as the
        initiation window's solution moves, on the data with one pair
        shifted at a time (:func:`~fgdoppler.estimators.calibration.offset_shares`;
        applied by :func:`~fgdoppler.estimators.registry.run_estimator`
        last, after the verdict and the sampled covariances).  Where the
        tracker restarted, each of its runs (the first and every restart's,
        from its own moved start) is made again and the runs are spliced
        at the same checkpoints, so that the share is that of the track
        reported; each restart adds its run to every one of these.  The track
        does not change; the verdict's reference smoother is told of the
        same offsets (:meth:`SmootherSettings.reference_for`) and reads its
        findings with them in the model — its covariances without their
        share, like the tracker's own before its share is added — so that
        offsets pass neither for a manoeuvre nor for a start outside the
        zone.
    clock_sigma : float or tuple of float, default 0.0
        Each pair's clock uncertainty (s, one standard deviation; one value
        for every pair or one per pair): all of a pair's measurement times
        may be late or early by one constant, which the data cannot tell
        from another track (:mod:`~fgdoppler.estimators.clock_offsets`).
        The reported covariances of every estimate then include what such
        offsets would do to the answer — the tracker run again, from its
        start moved as the initiation window's solution moves, on the data
        as they would read with one pair's clock off at a time, made along
        the tracker's own primary track (its runs spliced as for
        ``bias_sigma``)
        (:func:`~fgdoppler.estimators.clock_offsets.clock_shares`; four runs
        per pair, added with the calibration offsets' share, last).  The
        track does not change, nor does the verdict but for its whole-track
        comparison with the reference smoother, which reads the grown
        covariances: a track confidently elsewhere than the smoother's may
        be so no longer.
    site_sigma : float or tuple of float, default 0.0
        Each sensor site's position uncertainty (m; see
        :class:`TrackerSettings`): the covariances of every estimate grow by
        what such site errors would do to the answer, as for the clocks —
        the tracker run again from its moved start on the data as they would
        read with one site coordinate off at a time, made along its own
        primary track (:func:`~fgdoppler.estimators.site_offsets.site_shares`;
        four runs per site coordinate, added after the clock offsets' share).
    """

    sampled_covariance: bool = True
    sampling_interval: float = 5.0
    linearised_everywhere: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive(self.sampling_interval, "sampling_interval")
        _flag(self.sampled_covariance, "sampled_covariance")
        _flag(self.linearised_everywhere, "linearised_everywhere")

    @property
    def look_ahead(self) -> float:
        """Seconds of data after its time that an estimate has read (0: a filter's, data so far)."""
        return 0.0


@dataclass(frozen=True, kw_only=True)
class EKFSettings(SampledCovarianceSettings):
    """Extended Kalman filter.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate probability (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold on the normalised innovation: a measurement beyond it
        updates with its variance inflated by ``|ν|/(k√S)`` (see
        :class:`TrackerSettings`).
    components : int, default 8
        Gaussian-sum terms (see :class:`GaussianSumSettings`).
    sampled_covariance, sampling_interval, linearised_everywhere, bias_sigma, clock_sigma, site_sigma
        See :class:`SampledCovarianceSettings`.
    update : {"sequential", "scan"}, default "sequential"
        ``"sequential"``: one scalar update per measurement, relinearising
        after each; ``"scan"``: one vector update per scan (all pairs measured
        at one time, linearised once at the prediction), the textbook EKF of
        other libraries (Stone Soup's with one Detection per scan).  The gate
        is the same χ²₁ test per measurement against the prediction.
    gaussian_gate_probability : float or None, default 1 - 1e-6
        The gate where the filter's Gaussian fits its position posterior —
        sag ratio of the measured pair below
        :data:`~fgdoppler.estimators.gating.SAG_LIMIT`
        (:func:`~fgdoppler.estimators.gating.sag_ratio`): there the linear
        update of a large genuine innovation is right, and the narrow gate
        only loses data; a gross outlier (beyond 4.9 σ at the default) is
        still rejected.  ``None``: ``gate_probability`` everywhere (before
        2026-11-26).  Measured (100 runs per scenario, seeds 2026 and 7,
        paired, docs/concepts.md): case a 45 km with seed 7 −1.7 m, case a
        25 km with seed 2026 −1.8 m, every other cell −0.2 to +0.23 m.
    """

    update: Literal["sequential", "scan"] = "sequential"
    gaussian_gate_probability: float | None = 1 - 1e-6

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.update not in ("sequential", "scan"):
            raise ValueError(f"update must be 'sequential' or 'scan', got {self.update!r}")
        g, p = self.gaussian_gate_probability, self.gate_probability
        if g is not None and (isinstance(g, bool) or not 0 < g < 1):
            raise ValueError(f"gaussian_gate_probability must be in (0, 1) or None, got {g!r}")
        if g is not None and p is not None and g < p:
            raise ValueError(f"gaussian_gate_probability ({g}) must not be below gate_probability ({p}): "
                             "it is the wider gate, where the filter's Gaussian fits its posterior")

    @classmethod
    def gating_as(cls, settings: TrackerSettings) -> EKFSettings:
        """An EKF that gates and weighs residuals as ``settings`` do — one gate, as every other tracker has —
        for the EKFs inside other estimators (the smoother's start, rankings, Gaussian-sum weights)."""
        return cls(gate_probability=settings.gate_probability, huber_k=settings.huber_k,
                   gaussian_gate_probability=None)


@dataclass(frozen=True, kw_only=True)
class ISAM2Settings(StreamingSettings, SampledCovarianceSettings):
    r"""iSAM2 tracker.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate probability (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold (whitened units, e.g. 1.345) on every Doppler
        residual; ``None`` for the Gaussian loss.
    relinearize_position : float, default 10.0
        A Doppler factor is relinearised when its state has moved more than
        this (m) from the linearisation point.  With the Doppler curvature of
        these geometries (:math:`|\partial^2 h/\partial p^2| \lesssim v/r^2`,
        about 3e-5 s⁻¹ m⁻¹ at 2 km) a 10 m move changes the linearisation by
        ~1e-3 m/s, far below σ.
    relinearize_velocity : float, default 0.1
        The same for velocity (m/s).
    relinearize_window : int, default 10
        How many of the most recent scans are checked for relinearisation at
        every update; the whole graph is solved to convergence at the end.
    relinearize_history : int, default 120
        Every ``relinearize_every`` updates, this many states before the
        ``relinearize_window`` most recent ones are checked as well; 0 switches
        the check off.  On a poorly observed track old states go on moving by
        kilometres long after their scan, and their Doppler factors would stay
        linearised where the states were (on the slow three-pair two-hour
        recording of the long benchmark: iSAM2's filtered RMSE 1,489 m without
        the check, 538 m with it, the EKF's 454 m; 19 % more time).  A bound, not the whole
        history, keeps the cost of a check constant on long tracks: checking
        every state made a 1,200 s track 2.6 times slower.
    relinearize_every : int, default 10
        Updates between two checks of the ``relinearize_history`` older states.
    wildfire_threshold : float, default 0.01
        Back-substitution threshold (m and m/s): changes smaller than this are
        not propagated to older states until the end (GTSAM's default 0.001
        made the per-scan cost grow with the track length).
    keep_states : int, default 1000
        States held in iSAM2 behind the newest; older ones are marginalised
        out, in batches of a quarter of this (at least 100), each rebuilding
        iSAM2 from the kept states (0 keeps every state).  GTSAM's iSAM2 update costs
        O(N) in the states it holds, with a small constant that the
        relinearisation of old states multiplies: the tracker's median
        update grew from 1.2 ms at the start to 3.7 ms after 7,200 scans of
        the scaling benchmark's track.  The marginalised states lie beyond
        the relinearisation's reach (at least ``relinearize_window +
        relinearize_history`` states are kept, whatever this says), their
        factors are linear and fixed, so their Gaussian marginal is exact:
        the filtered estimates do not change beyond rounding.  The final smoothing
        (:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker.finish`) still
        solves every state, starting the marginalised ones from their
        estimate when they left.
    final_passes : int, default 100
        Cap on the Levenberg–Marquardt iterations of the final smoothing
        (:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker.finish`).
    smoothed_covariances : bool, default True
        Compute the marginal covariance of every smoothed state at the end.
    sampled_covariance, sampling_interval, linearised_everywhere, bias_sigma, clock_sigma, site_sigma
        See :class:`SampledCovarianceSettings`.
    """

    relinearize_position: float = 10.0
    relinearize_velocity: float = 0.1
    relinearize_window: int = 10
    relinearize_history: int = 120
    relinearize_every: int = 10
    wildfire_threshold: float = 0.01
    keep_states: int = 1000
    final_passes: int = 100
    smoothed_covariances: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive(self.relinearize_position, "relinearize_position")
        _positive(self.relinearize_velocity, "relinearize_velocity")
        _positive(self.wildfire_threshold, "wildfire_threshold")
        _count(self.relinearize_window, "relinearize_window")
        if self.relinearize_history != 0:
            _count(self.relinearize_history, "relinearize_history")
        _count(self.relinearize_every, "relinearize_every")
        _count(self.final_passes, "final_passes")
        _count(self.keep_states, "keep_states", 0, " (0: keep every state)")


@dataclass(frozen=True, kw_only=True)
class FixedLagSettings(StreamingSettings, SampledCovarianceSettings):
    """Fixed-lag smoother.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate probability (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold on every Doppler residual; ``None`` for Gaussian.
    lag : float, default 5.0
        Lag in seconds: states older than this are marginalised out.
    final_iterations : int, default 100
        Cap on the smoother iterations that bring the last window to its
        optimum at the end.
    warmup_seconds : float, default 0.0
    warmup_per_pair : int, default 0
        The warm-up (:class:`StreamingSettings`) is off by default here:
        GTSAM's smoother relinearises the whole lag window itself and holds
        a stream from the prior, and the warm-up did not improve it
        (docs/concepts.md, "Feeding a tracker yourself").  Switch it on to feed the
        tracker without a guess of the first state.
    sampled_covariance, sampling_interval, linearised_everywhere, bias_sigma, clock_sigma, site_sigma
        See :class:`SampledCovarianceSettings`: the lagged covariances are
        checked against posterior samples of the data up to ``lag``
        seconds after their time (measured on the paper's six scenarios,
        100 runs each, seed 2026: the run-averaged NEES of case a 5 km
        6.04 -> 4.62, case b 25 km 4.91 -> 3.56, case b 45 km 3.77 -> 2.97,
        slightly conservative there; seed 7: 4.60 -> 3.55, 4.66 -> 3.54,
        4.77 -> 3.48; docs/concepts.md).
    """

    lag: float = 5.0
    final_iterations: int = 100
    warmup_seconds: float = 0.0
    warmup_per_pair: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive(self.lag, "lag")
        _count(self.final_iterations, "final_iterations")

    @property
    def look_ahead(self) -> float:
        """The lagged estimates have read the data up to ``lag`` seconds after their time."""
        return self.lag


@dataclass(frozen=True, kw_only=True)
class SmootherSettings(TrackerSettings):
    """Offline smoother (the whole recording by Levenberg–Marquardt).

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate of the EKF pass that gives the smoother its starting
        trajectory (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold on every Doppler residual; ``None`` for Gaussian.
    max_iterations : int, default 100
        Cap on the Levenberg–Marquardt iterations.
    covariances : bool, default True
        Compute the marginal covariance of every state.
    reinitiate : bool, default True
        If the solution cannot explain the data (its cost fails a 99.9 % χ²
        check; with the Huber loss, as in the verdict, its inliers' χ²
        statistic fails it or more than 10 % of the residuals are beyond the
        outlier cut), initiate again from the whole recording and keep the
        better.
    region_bound : bool, default True
        The zone is the support of the track's first state, as in the
        initiation (:class:`~fgdoppler.estimators.initiation.InitiationSettings`):
        a steep wall (``wall_sigma``) keeps it inside.  When the wall holds
        the start and the data prefer one outside, the verdict says so
        (``boundary``; with ``mode_search`` the modes beyond the wall are
        searched, not only the held track's basin).  Without it, a poorly observed recording can settle
        in a second likelihood mode that starts outside the zone, 10-14 km
        from the truth (case a 5 km and case b 45 km: 2-5 runs in 100).
    wall_sigma : tuple of float, default (10.0, 0.1)
        Stiffness of the zone wall: (position m, speed m/s).
    sampled_covariance : bool, default True
        Where the likelihood is far from Gaussian about the estimate (the
        curvature probe of :mod:`fgdoppler.estimators.curvature`), report the
        posterior mean-square error from samples instead of the Laplace
        covariance (:mod:`fgdoppler.estimators.spread`; 0.2-1 s).
    posterior_mean : bool, default True
        With ``sampled_covariance``: where the cost is near-quadratic about
        the most likely track but the posterior is skewed beyond (its mean,
        found by importance sampling, lies more than a fifth of a standard
        deviation away), report the posterior mean and its covariance
        instead (:mod:`fgdoppler.estimators.spread`, "Skewed valleys"; about
        10 ms to check, 0.2 s where it applies).  Measured on the paper's
        25 km scenarios (100 runs, seeds 2026 and 7) the mean is 33-87 m
        closer to the truth; ``False`` reports the most likely track.
    mode_search : bool, default True
        2-D: initiate the whole recording again (multi-start), smooth from
        each of its solutions, keep the lowest cost and report a rival track
        that explains the data about as well (``competing``); and where the
        zone wall holds the track, search beyond it as well (the window's and
        the whole recording's initiation over the zone widened where the
        wall holds) before the ``boundary`` test; and where the wall does
        not hold but the track fits the data poorly (cost, or under the
        Huber loss the inliers' χ² statistic, above the 90 % χ² level),
        search outside the zone on every side (a ``zone`` finding when a
        track starting outside fits better by more than χ²₁ at 99.9 %).  3-D always searches its altitude levels and the
        whole recording.
    mode_candidates : int, default 20
        Grid candidates the whole-recording searches of ``mode_search``
        refine by Levenberg–Marquardt (the initiation's ``k_best``, 5 by
        default there).  Over a whole recording the modes are narrow, and the
        grid's cost at a node near one can rank below nodes of broader,
        worse basins: on two random layouts (docs/concepts.md, "Modes of the
        whole recording") the truth's mode, 12 and 21 lower in cost, was
        first found with 10 and with 20 (the second beyond the zone wall).
        Measured: 0.05-0.13 s more per smoother run on the paper's recordings
        with 20 than with 5 (``python -m benchmarks --only modes``).
    motion_check : bool, default True
        Test whether the target moves as the motion model says: the
        recording split at the middle of its span, each half fitted on its
        own, and a ``manoeuvre`` finding (``doubtful``) where the halves
        explain the data better than one track by more than the 99.9 % χ²
        level (:mod:`fgdoppler.estimators.manoeuvre`).  A manoeuvring target
        can leave a constant-velocity track kilometres off while its
        residuals pass the χ² test.  Three Levenberg–Marquardt fits from the
        smoother's own track.
    bias_sigma : float or tuple of float, default 0.0
        Each pair's Doppler calibration uncertainty (m/s, one standard
        deviation; one value for every pair or one per pair): a constant
        offset on all of a pair's measurements, which the data cannot tell
        from a shift of the track.  The reported covariances then include
        what such offsets would do to the answer (a *consider* covariance,
        :func:`~fgdoppler.estimators.calibration.with_bias_uncertainty`;
        four Levenberg–Marquardt solves per pair); the track itself does not
        change (unless ``estimate_offsets``).  In the paper's well-observed
        case a 45 km an offset of 1 σ of the noise on one pair moves the
        smoother's answer by 6–8 of its own σ while its residuals stay as
        good.  The verdict tests the model with the offsets in it either
        way: the split test of the motion model re-fits them, in 2-D a
        mirror image of the track that free offsets make about as likely is
        a ``competing`` finding where the reported covariance (with the
        offsets' share) does not reach it (one more joint solve of track and
        offsets, :mod:`fgdoppler.estimators.smoother_offsets`), and the zone wall's
        ``boundary`` test compares the held and the released track with the
        offsets free (:func:`~fgdoppler.estimators.smoother_offsets.joint_wall_gain`,
        three more solves where the wall's test without them fails).
    estimate_offsets : bool, default False
        With ``bias_sigma``: estimate each uncertain pair's offset together
        with the track (one variable per pair, prior N(0, σ²) with σ its
        ``bias_sigma``)
        instead of only considering them: the track moves by the joint
        mode's shift, its covariance widens by what the offsets' remaining
        uncertainty does to it (the consider covariance's rule about the
        estimated offsets), and the offsets are reported
        (:attr:`~fgdoppler.estimators.results.TrackResult.offsets`;
        :mod:`fgdoppler.estimators.smoother_offsets`).  One
        Levenberg–Marquardt solve of track and offsets from the chosen
        track, then four solves per pair; the mode searches keep the model
        without offsets, the fit test reads the residuals less the
        estimated offsets, and the split test of the motion model re-fits
        them with each part's track (two more solves).  In 2-D (with
        ``mode_search``, no half plane) one more solve from the track's
        mirror image across the sensors' line: free offsets can make that
        mode as likely, and then the verdict has a ``competing`` finding
        (as with the offsets only considered).
    offset_share : bool, default True
        With ``bias_sigma``: add the offsets' share to the reported
        covariances.  ``False`` reports the covariances of the track alone
        while the verdict still tests the model with the offsets in it (the
        split test, the mirror image, the zone wall): the reference a
        tracker told of offsets is held against (:meth:`reference_for`),
        whose track and covariance it compares like with like, each without
        its share.  Not with ``estimate_offsets``, whose reported track is
        the joint mode's.
    clock_sigma : float or tuple of float, default 0.0
        Each pair's clock uncertainty (s, one standard deviation; one value
        for every pair or one per pair): all of a pair's measurement times
        may be late or early by one constant.  On the paper's closely spaced
        pairs that moves the answer as another track would, with residuals
        as good (:mod:`~fgdoppler.estimators.clock_offsets`).  The reported
        covariances then include what such offsets would do to the answer
        (a consider covariance,
        :func:`~fgdoppler.estimators.clock_offsets.with_clock_uncertainty`;
        four Levenberg–Marquardt solves per pair, from the smoother's own
        solution on the data delayed along it, added after the calibration
        offsets' share).  The track and the verdict do not change.
    site_sigma : float or tuple of float, default 0.0
        Each sensor site's position uncertainty (m, one standard deviation
        in every coordinate; one value or one per site, in the order of
        :meth:`~fgdoppler.geometry.Geometry.sites`).  The reported
        covariances then include what such site errors would do to the
        answer (a consider covariance,
        :func:`~fgdoppler.estimators.site_offsets.with_site_uncertainty`;
        four Levenberg–Marquardt solves per site coordinate, from the
        smoother's own solution on the data displaced along it, added after
        the clock offsets' share).  The track and the verdict do not change.
    """

    max_iterations: int = 100
    covariances: bool = True
    reinitiate: bool = True
    region_bound: bool = True
    wall_sigma: tuple[float, float] = (10.0, 0.1)
    sampled_covariance: bool = True
    posterior_mean: bool = True
    mode_search: bool = True
    mode_candidates: int = 20
    motion_check: bool = True
    estimate_offsets: bool = False
    offset_share: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _flag(self.estimate_offsets, "estimate_offsets")
        _flag(self.offset_share, "offset_share")
        sigmas = self.bias_sigma if isinstance(self.bias_sigma, tuple) else (self.bias_sigma,)
        if self.estimate_offsets and max(sigmas) == 0.0:
            raise ValueError("estimate_offsets needs bias_sigma > 0 for at least one pair (the offsets' prior)")
        if self.estimate_offsets and not self.offset_share:
            raise ValueError("estimate_offsets reports the joint mode with its share; it cannot leave out offset_share")
        _count(self.max_iterations, "max_iterations")
        _count(self.mode_candidates, "mode_candidates")
        _flag(self.sampled_covariance, "sampled_covariance")
        _flag(self.posterior_mean, "posterior_mean")
        _flag(self.mode_search, "mode_search")
        _flag(self.motion_check, "motion_check")
        if not (len(self.wall_sigma) == 2 and all(v > 0 for v in self.wall_sigma)):
            raise ValueError(f"wall_sigma must be two positive numbers, got {self.wall_sigma}")

    def start(self) -> EKFSettings:
        """Settings of the EKF pass that starts the smoother (its gate: this one, everywhere)."""
        return EKFSettings.gating_as(self)

    @classmethod
    def reference_for(cls, settings: TrackerSettings) -> SmootherSettings:
        """The offline smoother a tracker's verdict holds it against: the tracker's gate, loss, seed and calibration
        offsets, every other setting the default (one such smoother serves every tracker that shares those four).

        With offsets declared (``bias_sigma``) its findings test the model with them in it, and its covariances
        leave out their share (``offset_share=False``), as the tracker's own verdict reads its covariances before
        its share is added."""
        sigmas = settings.bias_sigma if isinstance(settings.bias_sigma, tuple) else (settings.bias_sigma,)
        return cls(gate_probability=settings.gate_probability, huber_k=settings.huber_k, seed=settings.seed,
                   bias_sigma=settings.bias_sigma, offset_share=max(sigmas) == 0.0)


@dataclass(frozen=True, kw_only=True)
class ParticleSettings(TrackerSettings):
    """Particle estimator (:mod:`fgdoppler.estimators.particle`).

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate against the particles' predictive distribution (see
        :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber loss in the particles' likelihood.
    n_particles : int or None, default 4096
        Number of particles (at least 64); ``None``: the estimator's default
        for the model's dimension (:meth:`particles`).
    seed : int, default 0
        Seed of the estimator's random numbers (see :class:`TrackerSettings`):
        the same input gives the same track.
    ess_threshold : float, default 0.5
        Resample and move when the effective sample size falls below this
        fraction of ``n_particles``.
    move_steps : int, default 5
        Metropolis steps after each resampling.
    start_move_steps : int, default 20
        Metropolis steps on the initiation window's posterior.
    max_noise_share : float, default 0.1
        Move the anchor on once the process noise the particles' likelihood
        leaves out since the anchor exceeds this share of the posterior's
        variance in the direction it affects most, unless the posterior is
        too far from Gaussian for the summary
        (:mod:`fgdoppler.estimators.particle`, "Re-anchoring");
        ``math.inf``: only after ``max_span``.
    max_span : float, default 300.0
        Seconds of data a move may re-evaluate before the anchor moves on.
    tempered_start : bool, default True
        Carry the start's proposal to the window's posterior by adaptive
        tempering; ``False``: importance sampling in one step, then the
        ``start_move_steps`` moves (faster; its sample stays near the
        proposal's centres, under-dispersed, and can give one of two
        mirror modes all the mass).
    restarts : bool, default True
        At the filters' checkpoints where the measurements since the last
        one surprise the estimator (their NIS sum beyond the χ² 99.9 %
        quantile), where the particles were sampled again about a mode
        they had missed since the last one (``mode_rescue``;
        :func:`~fgdoppler.estimators.particle.rescued`), or where one of the
        initiation's solutions, refined on all the
        data so far, fits them better than the running estimate's basin
        (:mod:`fgdoppler.estimators.basin_screen`), and no later than
        ``max_span`` after the start, find the
        best fit of all data so far and, where it and the running estimate
        each lie outside the other's 99.9 % region (under the Huber loss
        where a few measurements pull the fit away), sample the posterior
        of all the data so far again from the fit's solutions and the
        running estimate (:mod:`fgdoppler.estimators.restart`, "The
        particle estimators").
    mode_rescue : bool or None, default None
        At each report, climb to the posterior's mode and, where the best
        particle falls further below it in log density than a sample of a
        posterior near Gaussian about it would
        (:func:`~fgdoppler.estimators.particle.rescue_shortfall`: 1.68 in
        the plane, 2.67 in space), sample the particles again about it, with
        an event (:class:`MapSettings` has the details).  ``None``: in space
        only (:meth:`rescues`).  In space a few thousand particles can miss the
        posterior's peak for tens of seconds: on 40 random 3-D layouts (60 s)
        the rescue acted in 8 runs and brought the mean closer to the truth in
        7 of them (median NEES over t >= 10 s of those runs 1,768 -> 369)
        and farther in 1, for 1.2 times the CPU time (docs/concepts.md,
        "The mean's particles too").  A rescue also makes the ``restarts``
        test at the next checkpoint: the peak can lie in a wrong basin
        (docs/concepts.md, "A rescue arms the next check").  In the plane
        it costs the climb at every report and never acted on the paper's scenarios, so it is off
        there; ``True`` and ``False`` hold in both.
    check_every : bool or None, default False
        Make the ``restarts`` test at every checkpoint of the first
        ``max_span`` seconds, not only where the data surprise the
        estimator, a rescue armed it or the basin screen fires.  A wrong
        basin the data leave slowly surprises nobody, and the screen only
        knows the initiation's basins; the test's fresh fit of all the data
        so far finds the others.  ``None``: in space only
        (:meth:`checks_every`), :class:`MapSettings`' default.  For the
        posterior mean it does not pay: on 40 random 3-D layouts (60 s) its
        error over the track fell in 13 draws and rose in 15, for 4.5 times
        its CPU time; its mean, off the valley's floor where the posterior
        is curved, lies outside the fit's region more often, and it
        restarted 53 times against ``map``'s 18 (docs/concepts.md, "Every
        checkpoint in space").
    bias_sigma : float or tuple of float, default 0.0
        Each pair's Doppler calibration uncertainty (m/s, one standard
        deviation; one value for every pair or one per pair).  Where the
        Gaussian trackers add the offsets' effect to their covariances
        (:class:`SmootherSettings`, :class:`SampledCovarianceSettings`),
        the particle estimators change the model they sample: each pair's
        constant offset, prior :math:`N(0, \\sigma_b^2)`, is integrated out
        of every particle's likelihood exactly
        (:mod:`~fgdoppler.estimators.offset_posterior`), so the track is the
        posterior's mean (or mode) under offsets of that size, and its
        covariance is that posterior's.  Needs the squared loss
        (``huber_k=None``): with a Huber loss the offsets do not integrate
        out in closed form.
    clock_sigma : float or tuple of float, default 0.0
        Each pair's clock uncertainty (s, one standard deviation; one value
        for every pair or one per pair), as for the filters
        (:class:`SampledCovarianceSettings`): a time offset does not
        integrate out of the likelihood in closed form, so the track does not
        change (nor the verdict, but for its whole-track comparison with the
        reference smoother, as for the filters) and the covariances grow by what such offsets
        would do to the track — the estimator run again, with the same
        random numbers, on the data as a clock late or early by each of the
        four outer points of a five-point Gauss–Hermite rule would give
        them, pair by pair (:func:`~fgdoppler.estimators.clock_offsets.clock_shares`,
        added by :func:`~fgdoppler.estimators.registry.run_estimator`).
        The reruns' Monte Carlo error enters the share too: 0.04–0.5 % of
        the position variance's trace at ``clock_sigma=1e-4`` s (case a
        45 km, 12 recordings, 4,096 particles).
    site_sigma : float or tuple of float, default 0.0
        Each sensor site's position uncertainty (m; see
        :class:`TrackerSettings`), as the clocks: the track does not change
        and the covariances grow by what site errors would do to it, the
        estimator run again with the same random numbers on the data as they
        would read with one site coordinate off at a time
        (:func:`~fgdoppler.estimators.site_offsets.site_shares`, added by
        :func:`~fgdoppler.estimators.registry.run_estimator`).
    """

    #: Particles when ``n_particles`` is ``None``: in the plane (2-D), in space (3-D).
    DEFAULT_PARTICLES: ClassVar[tuple[int, int]] = (4096, 4096)

    n_particles: int | None = 4096
    ess_threshold: float = 0.5
    move_steps: int = 5
    start_move_steps: int = 20
    max_span: float = 300.0
    max_noise_share: float = 0.1
    tempered_start: bool = True
    restarts: bool = True
    mode_rescue: bool | None = None
    check_every: bool | None = False

    def __post_init__(self) -> None:
        super().__post_init__()
        declared = self.bias_sigma if isinstance(self.bias_sigma, tuple) else (self.bias_sigma,)
        if self.huber_k is not None and max(declared) > 0:
            raise ValueError("bias_sigma > 0 needs the squared loss in the particle estimators (huber_k=None): "
                             "with a Huber loss the offsets do not integrate out of the likelihood")
        if self.n_particles is not None:
            _count(self.n_particles, "n_particles")
            if self.n_particles < 64:
                raise ValueError(f"n_particles must be >= 64, got {self.n_particles}")
        if not 0 < self.ess_threshold <= 1:
            raise ValueError(f"ess_threshold must be in (0, 1], got {self.ess_threshold!r}")
        for name in ("move_steps", "start_move_steps"):
            _count(getattr(self, name), name, 0)
        _positive(self.max_span, "max_span")
        if isinstance(self.max_noise_share, bool) or not self.max_noise_share > 0:
            raise ValueError(f"max_noise_share must be a positive number (math.inf: off), got {self.max_noise_share!r}")
        _flag(self.tempered_start, "tempered_start")
        _flag(self.restarts, "restarts")
        for name in ("mode_rescue", "check_every"):
            v = getattr(self, name)
            if v is not None and not isinstance(v, bool):
                raise ValueError(f"{name} must be True, False or None, got {v!r}")
        if self.check_every and not self.restarts:
            raise ValueError("check_every=True asks for the restart test at every checkpoint, but restarts=False "
                             "turns the test off")

    def rescues(self, dim: int) -> bool:
        """Whether the particles are sampled again about a mode they have missed, for ``dim`` (2 or 3) dimensions.

        ``mode_rescue`` where given, else ``dim == 3``.

        Raises
        ------
        ValueError
            If ``dim`` is neither 2 nor 3.
        """
        return _in_space_unless_given(self.mode_rescue, dim)

    def checks_every(self, dim: int) -> bool:
        """Whether the ``restarts`` test is made at every checkpoint, for ``dim`` (2 or 3) dimensions.

        ``check_every`` where given (``True`` or ``False``), else ``dim == 3``.

        Raises
        ------
        ValueError
            If ``dim`` is neither 2 nor 3.
        """
        return _in_space_unless_given(self.check_every, dim)

    def particles(self, dim: int) -> int:
        """The number of particles for a model of ``dim`` (2 or 3) spatial dimensions.

        ``n_particles`` where given, else :attr:`DEFAULT_PARTICLES` for ``dim``.

        Raises
        ------
        ValueError
            If ``dim`` is neither 2 nor 3.
        """
        _dimension(dim)
        return self.DEFAULT_PARTICLES[dim - 2] if self.n_particles is None else self.n_particles


@dataclass(frozen=True, kw_only=True)
class MapSettings(ParticleSettings):
    """The filtered MAP (:func:`fgdoppler.estimators.particle.run_map`): :class:`ParticleSettings` with fewer moves, and its read-out.

    The mode reads the particles only for its covariance (their second
    moment about it) and for where to start a second climb, so it needs
    less of the posterior's detail than the mean does: three Metropolis
    steps after each resampling instead of five leave ``map``'s track within
    2.5 m in every scenario of the accuracy benchmark (100 runs, two seeds;
    one scenario 36 m better) for 0.72-0.79 times the CPU time, and 2,048
    particles instead of 4,096 leave it within 2 m (one scenario 17 m better)
    for 0.65-0.70 times the CPU time again, at a run-averaged NEES higher by
    0.02-0.46 (docs/concepts.md, "The filtered mode", with the numbers) — in the plane; in space it
    holds more (``n_particles``).  Every other parameter means what it
    means in :class:`ParticleSettings`; ``MapSettings(move_steps=5, n_particles=4096)`` runs on the
    same particles and random numbers as the particle estimator's defaults.
    (The mean read from these particles is the particle estimator's to
    within 6 m in the paper's 25 km scenarios; ``map`` is 11-20 m behind
    ``particle`` there because its rule keeps the mode at some reports
    where the mean was the better point.  2026-12-01.)

    Parameters
    ----------
    move_steps : int, default 3
        Metropolis steps after each resampling.
    n_particles : int or None, default None
        Particles (at least 64); ``None``: 2,048 in the plane, 8,192 in
        space (:attr:`DEFAULT_PARTICLES`).  A space state has six unknowns
        to the plane's four, and 2,048 particles there often sit away from
        the posterior's peak: on 40 random 3-D layouts (60 s) 8,192 brought
        ``map`` closer to the truth in 28 draws and farther in 12 (median
        error over t >= 10 s 8.3 -> 6.6 km, median NEES 439 -> 80) for 2.1
        times the CPU time, where 16,384 did no better (docs/concepts.md,
        "Particles in space").
    posterior_mean : bool, default True
        Where the posterior is skewed rather than curved, report its mean
        (the particles' weighted mean and covariance, as the particle
        estimator does) instead of the mode: where the mean lies beyond the
        particles' Monte Carlo scatter about the mode and either within one
        standard deviation of it or in a valley that stays near-quadratic
        three standard deviations out (the offline smoother's limit for a
        near-quadratic valley;
        :func:`~fgdoppler.estimators.particle.mean_is_the_better_point`).
        Measured on the paper's 25 km scenarios, where the zone truncates a
        long valley, the track is 344-385 m closer to the truth than the mode's
        (accuracy benchmark, 100 runs, seeds 2026 and 7) and at most 4 m
        farther elsewhere (docs/concepts.md, "The filtered mode"); ``False``
        reports the mode at every scan, as does ``map`` with calibration
        offsets integrated out (``bias_sigma`` > 0), where the prior pulls the
        mean along the offsets' ridge.
    mode_rescue : bool or None, default True
        On in the plane too, where ``map`` climbs to the mode at every
        report anyway (``None``: in space only).  Where the best particle
        falls further below the mode in log density
        than a sample of a posterior near Gaussian about it would
        (:func:`~fgdoppler.estimators.particle.rescue_shortfall`: 1.68 in the
        plane, 2.67 in space), the particles sit away from the posterior's
        peak — in space a few thousand of them can miss it for tens of
        seconds — and are sampled again from the mode's Laplace Gaussian and
        their own (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.resample_about`),
        with an event.  The covariance reported (their second moment about
        the mode) and the Gaussian summary of a re-anchoring then describe the
        posterior again (docs/concepts.md, "Particles that miss the peak").
        ``False``: never (``fgdoppler track --estimator map --no-rescue``).
    check_every : bool or None, default None
        The ``restarts`` test at every checkpoint in space, only where
        something calls for it in the plane (:meth:`checks_every`).  On 40
        random 3-D layouts (60 s) it brought ``map`` closer to the truth in
        11 draws and farther in 2 (RMS over draws 16,808 -> 16,342 m,
        median final error 2,384 -> 1,338 m) for 2.8 times its CPU time
        (1.76 -> 4.85 s, median), where a wrong basin the data leave slowly
        had kept it kilometres off, unsurprised.  In the plane it moved 2
        of 40 random 2-D layouts' tracks and none of the paper's, and would
        take ``map`` past a tenth of the particle filter's time there
        (docs/concepts.md, "Every checkpoint in space").  ``True``: in both;
        ``False``: in neither (``--no-check-every``).
    """

    DEFAULT_PARTICLES: ClassVar[tuple[int, int]] = (2048, 8192)

    move_steps: int = 3
    n_particles: int | None = None
    posterior_mean: bool = True
    mode_rescue: bool | None = True
    check_every: bool | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        _flag(self.posterior_mean, "posterior_mean")
