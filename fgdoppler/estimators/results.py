"""One result type for every estimator, with CSV and JSON output.

A :class:`TrackResult` holds one or more sets of :class:`Estimates` (times,
states, covariances): ``"filtered"`` (EKF, iSAM2, the newest state of the
fixed-lag smoother), ``"lagged"`` (the fixed-lag smoother's estimate of the
state ``lag`` seconds back) and ``"smoothed"`` (batch, iSAM2 at the end).
``primary`` names the one an estimator is "about"; CSV and the CLI's
``--json`` report it.  Per-step diagnostics: normalised innovations (NIS)
with gating decisions, relinearisation counts and warnings.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgdoppler._io import atomic_open, atomic_write_text

__all__ = ["Estimates", "TrackResult"]

FloatArray = NDArray[np.float64]

_IU = np.triu_indices(4)
_COV_NAMES = [f"P{i}{j}" for i, j in zip(*_IU, strict=True)]


@dataclass(frozen=True, kw_only=True)
class Estimates:
    """States ``(n, 4)`` and covariances ``(n, 4, 4)`` at times ``(n,)``.

    ``cov_ok[k]`` is False where the covariance could not be computed
    (indeterminate system); the matrix there is filled with zeros and must
    not be used.
    """

    times: FloatArray
    states: FloatArray
    covariances: FloatArray
    cov_ok: NDArray[np.bool_]

    def __post_init__(self) -> None:
        n = np.asarray(self.times).size
        if np.shape(self.states) != (n, 4) or np.shape(self.covariances) != (n, 4, 4) or np.size(self.cov_ok) != n:
            raise ValueError("Estimates: inconsistent shapes")

    @classmethod
    def empty(cls) -> Estimates:
        """No estimates."""
        return cls(times=np.zeros(0), states=np.zeros((0, 4)), covariances=np.zeros((0, 4, 4)),
                   cov_ok=np.zeros(0, dtype=bool))

    @classmethod
    def from_lists(cls, times: Sequence[float], states: Sequence[FloatArray],
                   covs: Sequence[FloatArray | None]) -> Estimates:
        """Build from per-step lists; a ``None`` covariance marks an indeterminate step."""
        if not times:
            return cls.empty()
        ok = np.array([c is not None for c in covs], dtype=bool)
        P = np.array([np.zeros((4, 4)) if c is None else c for c in covs], dtype=float)
        P = 0.5 * (P + np.swapaxes(P, -1, -2))  # symmetric to the last bit (CSV keeps one triangle)
        return cls(times=np.asarray(times, dtype=float), states=np.asarray(states, dtype=float).reshape(-1, 4),
                   covariances=P, cov_ok=ok)

    def __len__(self) -> int:
        return int(np.size(self.times))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: covariances as nested lists, ``null`` where indeterminate."""
        return {
            "times": self.times.tolist(),
            "states": self.states.tolist(),
            "covariances": [c.tolist() if ok else None for c, ok in zip(self.covariances, self.cov_ok, strict=True)],
        }


@dataclass(frozen=True, kw_only=True)
class TrackResult:
    """Output of any estimator.

    Attributes
    ----------
    estimator
        ``"ekf"``, ``"isam2"``, ``"fixed-lag"`` or ``"batch"``.
    settings
        The settings used (JSON-ready).
    estimates
        Name -> :class:`Estimates`.
    primary
        The key of ``estimates`` that CSV/JSON report.
    nis
        ``(m, 4)`` rows of ``time, pair, NIS, accepted`` for every
        measurement the estimator gated (EKF, iSAM2, fixed-lag).
    relinearizations
        Per-step count of relinearised factors (iSAM2), or LM iterations (batch).
    warnings
        ``(time, message)`` of every problem handled.
    wall_time
        Seconds.
    log_likelihood
        EKF: cumulative predictive log-likelihood at each filtered time.
    cost
        Batch: final sum of squared whitened residuals.
    hypothesis
        Index of the initiation hypothesis reported at each primary time
        (all zero unless the initiation was ambiguous).
    """

    estimator: str
    settings: dict[str, Any]
    estimates: dict[str, Estimates]
    primary: str
    nis: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    relinearizations: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    warnings: tuple[tuple[float, str], ...] = ()
    wall_time: float = 0.0
    log_likelihood: FloatArray = field(default_factory=lambda: np.zeros(0))
    cost: float | None = None
    hypothesis: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:
        if self.primary not in self.estimates:
            raise ValueError(f"primary {self.primary!r} not among {list(self.estimates)}")

    @property
    def main(self) -> Estimates:
        """The primary estimates."""
        return self.estimates[self.primary]

    def to_dict(self, *, all_estimates: bool = True) -> dict[str, Any]:
        """JSON-ready: ``estimator``, ``times``, ``states``, ``covariances`` (primary) and more."""
        d: dict[str, Any] = {"estimator": self.estimator, "primary": self.primary, **self.main.to_dict()}
        d["settings"] = self.settings
        if all_estimates:
            d["estimates"] = {k: v.to_dict() for k, v in self.estimates.items() if k != self.primary}
        d["nis"] = [{"time": float(t), "pair": int(p), "nis": float(v), "accepted": bool(a)} for t, p, v, a in self.nis]
        d["relinearizations"] = self.relinearizations.tolist()
        d["warnings"] = [{"time": t, "message": m} for t, m in self.warnings]
        d["hypothesis"] = self.hypothesis.tolist()
        if self.cost is not None:
            d["cost"] = self.cost
        d["wall_time"] = self.wall_time
        return d

    def to_csv(self, path: str | Path) -> None:
        """One row per time: ``time, x, y, vx, vy`` and the covariance upper triangle (empty if indeterminate)."""
        e = self.main
        with atomic_open(Path(path)) as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(["time", "x", "y", "vx", "vy", *_COV_NAMES])
            for t, x, P, ok in zip(e.times, e.states, e.covariances, e.cov_ok, strict=True):
                cov = [repr(float(v)) for v in P[_IU]] if ok else [""] * len(_COV_NAMES)
                w.writerow([repr(float(t)), *(repr(float(v)) for v in x), *cov])

    def to_json(self, path: str | Path) -> None:
        """Write :meth:`to_dict` atomically."""
        atomic_write_text(Path(path), json.dumps(self.to_dict(), indent=1, allow_nan=False))

    @staticmethod
    def read_csv(path: str | Path) -> Estimates:
        """Read a CSV written by :meth:`to_csv` back into :class:`Estimates`."""
        rows = list(csv.reader(Path(path).read_text(encoding="utf-8").splitlines()))
        body = rows[1:]
        t = np.array([float(r[0]) for r in body])
        x = np.array([[float(v) for v in r[1:5]] for r in body]).reshape(-1, 4)
        P = np.zeros((len(body), 4, 4))
        ok = np.zeros(len(body), dtype=bool)
        for k, r in enumerate(body):
            if r[5]:
                P[k][_IU] = [float(v) for v in r[5:]]
                P[k] = P[k] + np.triu(P[k], 1).T
                ok[k] = True
        return Estimates(times=t, states=x, covariances=P, cov_ok=ok)
