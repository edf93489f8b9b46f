"""Settings and helpers shared by the trackers (EKF, iSAM2, fixed-lag, batch).

Every tracker starts from an :class:`~fgdoppler.estimators.initiation.Initiation`
of the same recording.  The *window* is every measurement at or before the
initiation's ``t_end``; the *stream* is everything after it.  The EKF starts
from the initiation's end state and covariance and processes the stream; the
graph-based estimators re-use the window's measurements in their graphs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from fgdoppler.estimators.grid import GridSpec
from fgdoppler.measurements import Measurements
from fgdoppler.models.measurement import MeasurementModel
from fgdoppler.models.motion import ConstantVelocity

__all__ = ["Scans", "StreamingTracker", "TrackerSettings", "feed", "huber_weights", "nis_gate", "region_prior",
           "split_window"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class TrackerSettings:
    """Settings shared by all trackers.

    Parameters
    ----------
    motion
        NCV model (the same in the EKF and every graph; full-rank Q).
    gate_probability
        NIS gate: a measurement whose normalised innovation exceeds the
        χ²₁ quantile at this probability is rejected (and reported).
        ``None`` disables gating.  Used by the EKF, iSAM2 and the fixed-lag
        smoother (against the predicted state); the batch smoother has no
        prediction and relies on ``huber_k``.
    huber_k
        If set, graph estimators use a Huber robust loss with this threshold
        (whitened units) on every Doppler residual.
    weak_prior
        Include the initiation's weak search-region prior on the first
        state in the graph estimators (as the LM initiation does).
    grid
        The search region the weak prior is built from.
    relinearize_position, relinearize_velocity
        iSAM2: a Doppler factor is relinearised when its state has moved
        more than this (m, m/s) from the linearisation point.  With the
        Doppler curvature of these geometries (|∂²h/∂p²| ≲ v/r² ≈ 3e-5 s⁻¹ m⁻¹
        at 2 km) a 10 m move changes the linearisation by ~1e-3 m/s, far
        below σ.
    relinearize_window
        iSAM2: how many of the most recent scans are checked for
        relinearisation at every update (older states barely move).  All
        are relinearised to convergence at the end.
    wildfire_threshold
        iSAM2 back-substitution threshold (m and m/s): changes smaller than
        this are not propagated to older states until the end (GTSAM's
        default 0.001 made the per-scan cost grow with the track length).
    lag
        Fixed-lag smoother lag in seconds.
    max_iterations
        Cap for batch LM iterations and iSAM2's final relinearisation passes.
    smoothed_covariances
        Compute per-time marginal covariances of smoothed trajectories.
    """

    motion: ConstantVelocity = field(default_factory=lambda: ConstantVelocity(q=1e-3))
    gate_probability: float | None = 0.9999
    huber_k: float | None = None
    weak_prior: bool = True
    grid: GridSpec = field(default_factory=GridSpec)
    relinearize_position: float = 10.0
    relinearize_velocity: float = 0.1
    relinearize_window: int = 10
    wildfire_threshold: float = 0.01
    lag: float = 5.0
    max_iterations: int = 100
    smoothed_covariances: bool = True

    def __post_init__(self) -> None:
        if self.gate_probability is not None and not 0 < self.gate_probability < 1:
            raise ValueError(f"gate_probability must be in (0, 1) or None, got {self.gate_probability}")
        if self.huber_k is not None and not self.huber_k > 0:
            raise ValueError(f"huber_k must be > 0, got {self.huber_k}")
        if not (self.relinearize_position > 0 and self.relinearize_velocity > 0):
            raise ValueError("relinearisation thresholds must be > 0")
        if self.relinearize_window < 1 or self.max_iterations < 1:
            raise ValueError("relinearize_window and max_iterations must be >= 1")
        if not self.lag > 0:
            raise ValueError(f"lag must be > 0 s, got {self.lag}")
        if not self.wildfire_threshold > 0:
            raise ValueError(f"wildfire_threshold must be > 0, got {self.wildfire_threshold}")

    @property
    def gate(self) -> float:
        """NIS threshold (``inf`` when gating is off)."""
        return float(chi2.ppf(self.gate_probability, 1)) if self.gate_probability is not None else np.inf

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        d = dataclasses.asdict(self)
        d["motion"] = {"q": self.motion.q, "form": self.motion.form}
        return d


@dataclass(frozen=True, kw_only=True)
class Scans:
    """Measurements grouped by distinct time: ``times (n,)`` and per scan the row slice."""

    times: FloatArray
    bounds: NDArray[np.intp]
    meas: Measurements

    @classmethod
    def of(cls, meas: Measurements) -> Scans:
        times, inv = meas.scan_index()
        return cls(times=times, bounds=np.searchsorted(inv, np.arange(times.size + 1)).astype(np.intp), meas=meas)

    def __len__(self) -> int:
        return int(self.times.size)

    def rows(self, k: int) -> slice:
        """Rows of scan ``k`` in ``meas``."""
        return slice(int(self.bounds[k]), int(self.bounds[k + 1]))

    @property
    def scan_of(self) -> NDArray[np.intp]:
        """Scan index of every measurement row."""
        return np.repeat(np.arange(len(self)), np.diff(self.bounds))


def split_window(meas: Measurements, t_end: float) -> tuple[Measurements, Measurements]:
    """(window, stream): measurements at or before ``t_end`` and after it."""
    return meas.subset(meas.time <= t_end), meas.subset(meas.time > t_end)


def region_prior(grid: GridSpec) -> tuple[FloatArray, FloatArray]:
    """Mean and covariance of the weak prior spanning the search region.

    Centre of the position box and zero velocity; standard deviations equal
    to the box half-widths (at least 1 m) and ``speed_max`` per velocity axis.
    """
    centre = np.array([(grid.x[0] + grid.x[1]) / 2, (grid.y[0] + grid.y[1]) / 2, 0.0, 0.0])
    half = np.array([(grid.x[1] - grid.x[0]) / 2, (grid.y[1] - grid.y[0]) / 2, grid.speed_max, grid.speed_max])
    return centre, np.diag(np.maximum(half, 1.0) ** 2)


def huber_weights(whitened: FloatArray, k: float | None) -> FloatArray:
    r"""IRLS weights of the Huber loss: :math:`w = \min(1, k/|r|)` for whitened residuals ``r``."""
    r = np.abs(np.asarray(whitened, dtype=float))
    if k is None:
        return np.ones_like(r)
    return np.minimum(1.0, k / np.maximum(r, 1e-300))


def check_model(model: MeasurementModel, meas: Measurements) -> None:
    """Raise if a measurement's channel is outside the model."""
    if len(meas) and int(meas.pair.max()) >= model.n_channels:
        raise ValueError(f"pair index {int(meas.pair.max())} outside a model of {model.n_channels} channel(s)")


class StreamingTracker(Protocol):
    """What :func:`feed` needs from a tracker (iSAM2 and fixed-lag implement it)."""

    def add_window(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                   guesses: ArrayLike) -> tuple[FloatArray, FloatArray | None]: ...

    def add_scan(self, t: float, channels: ArrayLike, z: ArrayLike,
                 sigma: ArrayLike) -> tuple[FloatArray, FloatArray | None]: ...


def feed(tracker: StreamingTracker, measurements: Measurements, init: Any,
         settings: TrackerSettings, *, guesses: ArrayLike | None = None,
         ) -> tuple[list[float], list[FloatArray], list[FloatArray | None]]:
    """Feed the initiation window (one call), then every later scan.

    The window's states start at ``guesses`` (one per window scan; default:
    the initiation's constant-velocity track, see
    :func:`fgdoppler.estimators.window.window_start` for why the trackers
    pass better ones).  Returns the filtered ``(times, states, covariances)``
    from the window's end on.
    """
    window, stream = split_window(measurements, init.t_end)
    times: list[float] = []
    states: list[FloatArray] = []
    covs: list[FloatArray | None] = []
    ws = Scans.of(window)
    if len(ws):
        rows = [ws.rows(k) for k in range(len(ws))]
        x, P = tracker.add_window(
            ws.times, [window.pair[r] for r in rows], [window.doppler[r] for r in rows],
            [window.sigma[r] for r in rows],
            settings.motion.propagate(init.x_start, ws.times - init.t_start) if guesses is None else guesses,
        )
        times.append(float(ws.times[-1]))
        states.append(x)
        covs.append(P)
    ss = Scans.of(stream)
    for k in range(len(ss)):
        sl = ss.rows(k)
        x, P = tracker.add_scan(ss.times[k], stream.pair[sl], stream.doppler[sl], stream.sigma[sl])
        times.append(float(ss.times[k]))
        states.append(x)
        covs.append(P)
    return times, states, covs


def nis_gate(
    model: MeasurementModel,
    x_pred: FloatArray,
    P_pred: FloatArray,
    t: float,
    channels: NDArray[np.intp],
    z: FloatArray,
    sigma: FloatArray,
    gate: float,
    nis_log: list[tuple[float, int, float, bool]],
    warnings: list[tuple[float, str]],
) -> NDArray[np.bool_]:
    r"""Gate the measurements of one scan against the prediction; returns the mask of those kept.

    :math:`\mathrm{NIS}_j = (z_j - h_j(\mathbf x^-))^2 / (\mathbf H_j\mathbf P^-\mathbf H_j' + \sigma_j^2)`;
    every value is appended to ``nis_log`` and every rejection to ``warnings``.
    """
    h, H = model.predict_and_jacobian(np.broadcast_to(x_pred, (channels.size, 4)), channels)
    nis = (z - h) ** 2 / (np.einsum("ij,jk,ik->i", H, P_pred, H) + sigma**2)
    keep = nis <= gate
    for ch, v, ok in zip(channels, nis, keep, strict=True):
        nis_log.append((t, int(ch), float(v), bool(ok)))
        if not ok:
            warnings.append((t, f"pair {ch}: NIS {v:.1f} > gate {gate:.1f}, measurement rejected"))
    return keep
