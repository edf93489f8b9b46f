"""One result type for every tracker, with CSV and JSON output.

A :class:`TrackResult` holds one or more sets of :class:`Estimates` (times,
states, covariances), each of a *kind*:

``"filtered"``
    The newest state given the data up to its time (EKF, iSAM2, the
    fixed-lag smoother's newest state).
``"lagged"``
    Each state as estimated ``lag`` seconds after its time (fixed-lag).
``"smoothed"``
    Each state given all the data (offline smoother, iSAM2 at the end).

The first set is the result's :attr:`TrackResult.primary` estimate — the one
an estimator is "about", which CSV and the CLI's ``--json`` report.  The
verdict (``status``, ``message``, ``reasons``) and the event log follow
:mod:`fgdoppler.estimators.verdict`.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from fgdoppler._io import atomic_write_text
from fgdoppler.estimators.settings import TrackerSettings
from fgdoppler.estimators.verdict import Event, Judged, Reason
from fgdoppler.frames import Frame

__all__ = ["KINDS", "Estimates", "OffsetEstimate", "TrackResult", "json_dumps", "states_csv"]

FloatArray = NDArray[np.float64]
Kind = Literal["filtered", "lagged", "smoothed"]
#: The kinds of estimate.
KINDS: tuple[Kind, ...] = ("filtered", "lagged", "smoothed")

#: State column names of the track CSV, per state length.
STATE_NAMES = {4: ("x", "y", "vx", "vy"), 6: ("x", "y", "z", "vx", "vy", "vz")}


def _upper(n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    return np.triu_indices(n)


def _track_columns(n: int) -> tuple[str, ...]:
    """A track file's first columns for ``n`` state entries, as :func:`~fgdoppler.csvfile.read_table` names them
    (lower case): the time, the state and the covariance's upper triangle."""
    return ("time", *STATE_NAMES[n], *(c.lower() for c in _cov_names(n)))


def _cov_names(n: int) -> list[str]:
    return [f"P{i}{j}" for i, j in zip(*_upper(n), strict=True)]


def states_csv(times: FloatArray, states: FloatArray, covariances: FloatArray, cov_ok: NDArray[np.bool_],
               comments: Sequence[str] = (), columns: Mapping[str, FloatArray] | None = None) -> str:
    """The track CSV: ``#`` comment lines, the header, a row per time with the covariance's upper triangle.

    Columns ``time, x, y, vx, vy, P00, P01, ..., P33`` in 2-D and
    ``time, x, y, z, vx, vy, vz, P00, ..., P55`` in 3-D (``Pij`` the
    covariance of state entries ``i`` and ``j``, row-major upper triangle),
    then any of ``columns`` (one value a row; e.g. each state's latitude and
    longitude where the sensors were given so: :meth:`fgdoppler.geodetic.GeodeticOrigin.columns`).
    """
    n = int(np.shape(states)[1]) if np.ndim(states) == 2 else 4
    iu, names = _upper(n), _cov_names(n)
    more = dict(columns or {})
    buf = io.StringIO()
    for line in comments:
        buf.write(f"# {line}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["time", *STATE_NAMES[n], *names, *more])
    for k, (t, x, P, ok) in enumerate(zip(times, states, covariances, cov_ok, strict=True)):
        cov = [repr(float(v)) for v in P[iu]] if ok else [""] * len(names)
        w.writerow([repr(float(t)), *(repr(float(v)) for v in x), *cov, *(repr(float(c[k])) for c in more.values())])
    return buf.getvalue()


def json_dumps(obj: Any) -> str:
    """JSON with non-finite numbers as ``null`` (strict JSON has no NaN or infinity)."""
    def clean(o: Any) -> Any:
        if isinstance(o, float | np.floating):
            return float(o) if np.isfinite(o) else None
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, list | tuple):
            return [clean(v) for v in o]
        return o

    return json.dumps(clean(obj), indent=1, allow_nan=False)


@dataclass(frozen=True, kw_only=True)
class Estimates:
    """States ``(n, 2d)`` and covariances ``(n, 2d, 2d)`` at times ``(n,)``, of one kind (``d`` = 2 or 3).

    ``cov_ok[k]`` is False where the covariance could not be computed
    (indeterminate system); the matrix there is filled with zeros and must
    not be used.
    """

    kind: Kind
    times: FloatArray
    states: FloatArray
    covariances: FloatArray
    cov_ok: NDArray[np.bool_]

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")
        n = np.asarray(self.times).size
        m = np.shape(self.states)[-1] if np.ndim(self.states) == 2 else -1
        if m not in (4, 6) or np.shape(self.states) != (n, m) or np.shape(self.covariances) != (n, m, m) \
                or np.size(self.cov_ok) != n:
            raise ValueError("Estimates: inconsistent shapes")

    @property
    def dim(self) -> int:
        """Spatial dimension of the states (2 or 3)."""
        return int(np.shape(self.states)[1]) // 2

    @classmethod
    def empty(cls, kind: Kind, n: int = 4) -> Estimates:
        """No estimates (states of ``n`` numbers)."""
        return cls(kind=kind, times=np.zeros(0), states=np.zeros((0, n)), covariances=np.zeros((0, n, n)),
                   cov_ok=np.zeros(0, dtype=bool))

    @classmethod
    def from_lists(cls, kind: Kind, times: Sequence[float], states: Sequence[FloatArray],
                   covs: Sequence[FloatArray | None]) -> Estimates:
        """Build from per-step lists; a ``None`` covariance marks an indeterminate step."""
        if not times:
            return cls.empty(kind)
        ok = np.array([c is not None for c in covs], dtype=bool)
        x = np.asarray(states, dtype=float)
        n = x.shape[-1]
        P = np.array([np.zeros((n, n)) if c is None else c for c in covs], dtype=float)
        P = 0.5 * (P + np.swapaxes(P, -1, -2))  # symmetric to the last bit (CSV keeps one triangle)
        return cls(kind=kind, times=np.asarray(times, dtype=float), states=x.reshape(-1, n), covariances=P,
                   cov_ok=ok)

    def __len__(self) -> int:
        return int(np.size(self.times))

    def covariance_reason(self) -> Reason | None:
        """A ``"doubtful"`` ``covariance`` finding if some covariances are indeterminate, else ``None``."""
        if bool(np.all(self.cov_ok)):
            return None
        return Reason(code="covariance", status="doubtful", message=(
            f"{int(np.sum(~self.cov_ok))} of {len(self)} {self.kind} covariances are indeterminate"))

    def transformed(self, frame: Frame, *, to_world: bool) -> Estimates:
        """The estimates moved out of (``to_world``) or into ``frame``'s local coordinates."""
        if frame.is_identity or len(self) == 0:
            return self
        x = frame.states_to_world if to_world else frame.states_to_local
        P = frame.covariances_to_world if to_world else frame.covariances_to_local
        return replace(self, states=x(self.states), covariances=np.where(self.cov_ok[:, None, None],
                                                                          P(self.covariances), 0.0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: covariances as nested lists, ``null`` where indeterminate."""
        return {
            "kind": self.kind,
            "times": self.times.tolist(),
            "states": self.states.tolist(),
            "covariances": [c.tolist() if ok else None for c, ok in zip(self.covariances, self.cov_ok, strict=True)],
        }


@dataclass(frozen=True, kw_only=True)
class OffsetEstimate:
    """What the data say of each uncertain pair's calibration offset at the end of the recording (m/s).

    Given by the particle estimators when ``bias_sigma`` is declared
    (:mod:`~fgdoppler.estimators.offset_posterior`): ``particle`` the
    offsets' posterior mean and covariance, ``map`` their most probable
    values given the reported state and the second moment about them; and
    by the smoother with ``estimate_offsets``: their values at the joint mode
    of track and offsets and the Laplace covariance there
    (:mod:`~fgdoppler.estimators.smoother_offsets`).
    Offsets are scalars per pair, the same in every frame.

    Attributes
    ----------
    pairs
        The pairs (channels) declared uncertain, ``(P,)``.
    values
        Their offsets ``(P,)``.
    covariance
        ``(P, P)``.
    """

    pairs: NDArray[np.int64]
    values: FloatArray
    covariance: FloatArray

    def full(self, n_pairs: int) -> FloatArray:
        """The offsets as one value per pair of ``n_pairs``, 0 for the pairs not declared uncertain."""
        out = np.zeros(n_pairs)
        out[self.pairs] = self.values
        return out

    def square_root(self, n_pairs: int) -> FloatArray:
        r"""Rows :math:`\sqrt{\lambda_j}\mathbf v_j` over ``n_pairs`` pairs, one per eigenpair of :attr:`covariance`:
        the offsets' uncertainty as :math:`\sum_j \xi_j\mathbf d_j` with :math:`\xi_j \sim N(0, 1)` independent."""
        lam, vec = np.linalg.eigh(self.covariance)
        out = np.zeros((self.pairs.size, n_pairs))
        out[:, self.pairs] = (vec * np.sqrt(np.maximum(lam, 0.0))).T
        return out

    def describe(self, label: Callable[[int], str] = str) -> str:
        """One line: each pair's offset and standard deviation, the pair named by ``label`` (its index by default;
        :func:`~fgdoppler.geometry.pair_labels` names it as the measurement file may, ``"pair 1 (south)"``)."""
        return ", ".join(f"pair {label(int(p))} {v:+.2f} +- {sd:.2f} m/s" for p, v, sd in
                         zip(self.pairs, self.values, np.sqrt(np.diag(self.covariance)), strict=True))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``pairs``, ``values``, ``sigmas`` and ``covariance``."""
        return {"pairs": self.pairs.tolist(), "values": self.values.tolist(),
                "sigmas": np.sqrt(np.diag(self.covariance)).tolist(), "covariance": self.covariance.tolist()}


@dataclass(frozen=True, kw_only=True)
class TrackResult(Judged):
    """Output of any tracker.

    Attributes
    ----------
    estimator
        Registry name: ``"ekf"``, ``"isam2"``, ``"fixed-lag"`` or ``"smoother"``.
    settings
        The estimator's settings.
    estimates
        The estimate sets, the primary first (see the module docstring).
    reasons
        The findings behind the verdict (:mod:`fgdoppler.estimators.verdict`).
    events
        What happened along the way (rejections, fallbacks, restarts).
    nis
        ``(m, 4)`` rows of ``time, pair, NIS, accepted`` for every
        measurement the estimator gated (EKF, iSAM2, fixed-lag).
    relinearizations
        iSAM2: factors relinearised at each online update (empty otherwise).
    iterations
        Solver iterations: Levenberg–Marquardt iterations (smoother), final
        relinearisation passes (iSAM2), final smoothing iterations
        (fixed-lag); 0 for the EKF.
    log_likelihood
        EKF: cumulative predictive log-likelihood at each filtered time.
    cost
        Smoother: final sum of squared whitened residuals.
    hypothesis
        Index of the initiation hypothesis reported at each primary time
        (all zero unless the initiation was ambiguous).
    wall_time
        Seconds.
    offsets
        The calibration offsets the data imply (:class:`OffsetEstimate`),
        where the estimator estimates them (the particle estimators with
        ``bias_sigma``, the smoother with ``estimate_offsets``); ``None``
        otherwise.
    """

    estimator: str
    settings: TrackerSettings
    estimates: tuple[Estimates, ...]
    reasons: tuple[Reason, ...] = ()
    events: tuple[Event, ...] = ()
    nis: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    relinearizations: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    iterations: int = 0
    log_likelihood: FloatArray = field(default_factory=lambda: np.zeros(0))
    cost: float | None = None
    hypothesis: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    wall_time: float = 0.0
    offsets: OffsetEstimate | None = None

    def __post_init__(self) -> None:
        if not self.estimates:
            raise ValueError("a TrackResult needs at least one set of estimates")
        kinds = [e.kind for e in self.estimates]
        if len(set(kinds)) != len(kinds):
            raise ValueError(f"duplicate estimate kinds {kinds}")
        hyp = np.asarray(self.hypothesis, dtype=np.int64).reshape(-1)
        if hyp.size == 0:
            hyp = np.zeros(len(self.primary), dtype=np.int64)
        elif hyp.size != len(self.primary):
            raise ValueError(f"{hyp.size} hypothesis indices for {len(self.primary)} primary estimates")
        object.__setattr__(self, "hypothesis", hyp)

    @property
    def primary(self) -> Estimates:
        """The estimate the estimator is about (CSV and ``--json`` report it)."""
        return self.estimates[0]

    def transformed(self, frame: Frame, *, to_world: bool) -> TrackResult:
        """The result with every estimate moved out of (``to_world``) or into ``frame``'s local coordinates."""
        if frame.is_identity:
            return self
        return replace(self, estimates=tuple(e.transformed(frame, to_world=to_world) for e in self.estimates))

    @property
    def main(self) -> Estimates:
        """Deprecated name of :attr:`primary` (the documentation used it)."""
        import warnings

        warnings.warn("TrackResult.main is now TrackResult.primary", DeprecationWarning, stacklevel=2)
        return self.primary

    def estimate(self, kind: Kind) -> Estimates:
        """The estimates of one kind.

        Raises
        ------
        KeyError
            If this result has none of that kind.
        """
        for e in self.estimates:
            if e.kind == kind:
                return e
        raise KeyError(f"{self.estimator} has no {kind!r} estimates (it has {[e.kind for e in self.estimates]})")

    def to_dict(self, *, all_estimates: bool = True) -> dict[str, Any]:
        """JSON-ready: ``estimator``, the verdict, the primary ``times``/``states``/``covariances`` and more."""
        d: dict[str, Any] = {"estimator": self.estimator, "status": self.status, "message": self.message,
                             "reasons": [r.to_dict() for r in self.reasons], **self.primary.to_dict()}
        d["settings"] = self.settings.to_dict()
        if all_estimates:
            d["estimates"] = {e.kind: e.to_dict() for e in self.estimates[1:]}
        d["nis"] = [{"time": float(t), "pair": int(p), "nis": float(v), "accepted": bool(a)} for t, p, v, a in self.nis]
        d["relinearizations"] = self.relinearizations.tolist()
        d["iterations"] = self.iterations
        d["events"] = [e.to_dict() for e in self.events]
        d["hypothesis"] = self.hypothesis.tolist()
        if self.cost is not None:
            d["cost"] = self.cost
        d["wall_time"] = self.wall_time
        if self.offsets is not None:
            d["offsets"] = self.offsets.to_dict()
        return d

    def csv_text(self, *, header: Sequence[str] = (), columns: Mapping[str, FloatArray] | None = None) -> str:
        """The track CSV (see :meth:`to_csv`) as text."""
        e = self.primary
        return states_csv(e.times, e.states, e.covariances, e.cov_ok,
                          [f"fgdoppler {self.estimator}: {e.kind} estimates, status {self.status}", *header], columns)

    def to_csv(self, path: str | Path, *, header: Sequence[str] = (),
               columns: Mapping[str, FloatArray] | None = None) -> None:
        """One row per time: ``time``, the state (``x, y, vx, vy`` or ``x, y, z, vx, vy, vz``) and the
        covariance's upper triangle (empty if indeterminate); see :func:`states_csv`.

        The file starts with ``#`` comment lines: the estimator, the estimate's
        kind and the verdict, then each line of ``header`` (the command line
        records the geometry and the zone there).  ``columns`` follow the
        covariance (:func:`states_csv`).  Written atomically.
        """
        atomic_write_text(Path(path), self.csv_text(header=header, columns=columns))

    def json_text(self, *, extra: dict[str, Any] | None = None) -> str:
        """:meth:`to_dict` (with ``extra`` keys, e.g. the geometry) as JSON; non-finite numbers become ``null``."""
        return json_dumps({**self.to_dict(), **(extra or {})})

    def to_json(self, path: str | Path, *, extra: dict[str, Any] | None = None) -> None:
        """Write :meth:`json_text` atomically."""
        atomic_write_text(Path(path), self.json_text(extra=extra))

    @staticmethod
    def read_csv(path: str | Path, kind: Kind = "smoothed") -> Estimates:
        """Read a CSV written by :meth:`to_csv` back into :class:`Estimates` (of the given kind).

        Indeterminate covariances (empty cells) come back with ``cov_ok``
        False.  Columns after the covariance (``latitude``, ``longitude``,
        ...) must hold numbers and are not returned.  The file is read once
        (a pipe reads as the file).

        Raises
        ------
        fgdoppler.csvfile.CSVError
            Naming the file and the line: not a track file (no ``time``,
            state and covariance columns), a row with the wrong number of
            fields, a field that is not a number, an empty state cell, or a
            covariance given in part.
        """
        from fgdoppler.csvfile import CSVError, read_table

        def layout(names: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
            known = _track_columns(6 if "z" in names else 4)
            # the columns after the covariance, once it is there (otherwise the header's problem is said alone)
            return known, tuple(n for n in names if n not in known) if set(known) <= set(names) else ()

        table = read_table(path, header=(), what="track file", comments=True, layout=layout,
                           blank=tuple(c.lower() for c in _cov_names(6)))  # every covariance cell, 2-D or 3-D
        m = 6 if "z" in table.header else 4
        k = len(_cov_names(m))
        values = table.values
        empty = np.isnan(values[:, 1 + m:1 + m + k])
        partial = np.flatnonzero(np.any(empty, axis=1) & ~np.all(empty, axis=1))
        if partial.size:
            raise CSVError(f"{table.where(int(partial[0]))}: the covariance is given in part: its cells are all "
                           "numbers, or all empty where it is indeterminate")
        ok = ~np.all(empty, axis=1)
        iu = _upper(m)
        P = np.zeros((len(values), m, m))
        P[:, iu[0], iu[1]] = np.where(ok[:, None], values[:, 1 + m:1 + m + k], 0.0)
        P = P + np.triu(P, 1).transpose(0, 2, 1)
        return Estimates(kind=kind, times=values[:, 0], states=values[:, 1:1 + m], covariances=P, cov_ok=ok)
