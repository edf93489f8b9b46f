"""Monte Carlo studies: scenarios × estimators × runs, on any ``concurrent.futures.Executor``.

Each (scenario, run) pair gets its own random stream from
``numpy.random.SeedSequence(seed).spawn``, indexed by position, so results do
not depend on the number of workers or the order in which runs finish.
Workers receive only picklable descriptions (scenarios, settings) and build
every GTSAM graph themselves (``CustomFactor`` callbacks cannot be pickled).
GTSAM holds the GIL, so processes, not threads, give the speed-up; a Dask
``distributed`` cluster works too (``fgdoppler[distributed]``).

Estimators
    ``"grid"``, ``"ils"``, ``"lm"`` (:data:`~fgdoppler.estimators.names.METHODS`):
    initiation only; the estimate at time *t* is the constant-velocity
    extrapolation of the initiation's initial state (the paper's "batch
    initial estimate").
    Every name of the registry (:data:`~fgdoppler.estimators.registry.ESTIMATORS`):
    that tracker's primary estimate — ``"ekf"``, ``"isam2"`` (filtered),
    ``"fixed-lag"`` (each state when it is ``lag`` seconds old),
    ``"smoother"`` (smoothed).
    ``"lag:<seconds>"``: the fixed-lag smoother with that lag (for lag sweeps).

Per run and estimator the squared position and velocity errors and the NEES
are stored on the scenario's truth time grid (NaN where there is no estimate).
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Mapping
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from fgdoppler._io import atomic_write_text
from fgdoppler.analysis.metrics import errors, nees, nees_band, rmse
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.error_draws import ErrorDraws
from fgdoppler.estimators.initiation import InitiationSettings
from fgdoppler.estimators.names import DEFAULT_ESTIMATORS, METHODS, Method
from fgdoppler.estimators.registry import ALIASES, ESTIMATORS
from fgdoppler.estimators.settings import FixedLagSettings, SmootherSettings, TrackerSettings
from fgdoppler.estimators.verdict import STATUSES
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.tracking import TrackingModel, default_motion
from fgdoppler.simulation import Scenario, simulate

#: The summary's NEES leaves out the times before this (s): the initiation window and the first seconds after
#: it, where the estimators still settle (the reproduction report's convention).
NEES_FROM = 10.0

__all__ = ["DEFAULT_ESTIMATORS", "NEES_FROM", "MonteCarloResult", "MonteCarloSpec", "run_monte_carlo"]

FloatArray = NDArray[np.float64]


def _lag(name: str) -> float | None:
    """The lag of a ``"lag:<seconds>"`` name, or ``None`` for other names."""
    if not name.startswith("lag:"):
        return None
    try:
        lag = float(name[4:])
    except ValueError:
        raise ValueError(f"bad lag in estimator {name!r}: expected lag:<seconds>") from None
    if not (np.isfinite(lag) and lag > 0):
        raise ValueError(f"bad lag in estimator {name!r}: must be > 0 s")
    return lag


@dataclass(frozen=True, kw_only=True)
class MonteCarloSpec:
    """What to run.

    Parameters
    ----------
    scenarios
        The scenarios (each simulated ``runs`` times).
    estimators
        Names (see module docstring).
    runs
        Monte Carlo runs per scenario.
    seed
        Root of the ``SeedSequence``.
    init_per_pair
        Initiation window: the first measurements of each pair (paper: 10).
    initiation
        Settings of the initiation.
    settings
        Settings per tracker name (registry defaults for the others).
    motion
        Motion model of every estimator (the tracking model's).
    weak_prior
        Whether the estimators use the zone's weak prior.
    verify
        Give the filters' verdicts their check against the offline smoother
        (one smoother run per simulated run, shared by the filters).
    error_draws
        Sensor errors drawn afresh for every run and added to the scenario's
        own (:class:`~fgdoppler.error_draws.ErrorDraws`): calibration offsets
        and site displacements, from the run's own stream
        (:meth:`scenario_of_run`); ``None`` (default): every run has the
        scenario's errors.
    """

    scenarios: tuple[Scenario, ...]
    estimators: tuple[str, ...] = DEFAULT_ESTIMATORS
    runs: int = 100
    seed: int = 2026
    init_per_pair: int = 10
    initiation: InitiationSettings = field(default_factory=InitiationSettings)
    settings: Mapping[str, TrackerSettings] = field(default_factory=dict)
    motion: ConstantVelocity = field(default_factory=default_motion)
    weak_prior: bool = True
    verify: bool = True
    error_draws: ErrorDraws | None = None

    def __post_init__(self) -> None:
        if self.runs < 1:
            raise ValueError(f"runs must be >= 1, got {self.runs}")
        if not self.scenarios:
            raise ValueError("need at least one scenario")
        if len({sc.geometry.dim for sc in self.scenarios}) > 1:
            raise ValueError("scenarios of one Monte Carlo study must all be 2-D or all 3-D")
        for e in self.estimators:
            if e not in METHODS and e not in ESTIMATORS and e not in ALIASES and _lag(e) is None:
                raise ValueError(f"unknown estimator {e!r}: expected one of {', '.join(DEFAULT_ESTIMATORS)} "
                                 "or lag:<seconds>")
        for name, st in self.settings.items():
            if name not in ESTIMATORS or type(st) is not ESTIMATORS[name].settings:
                raise ValueError(f"settings for {name!r} must be a {ESTIMATORS[name].settings.__name__}"
                                 if name in ESTIMATORS else f"settings given for unknown estimator {name!r}")
        if self.error_draws is not None:
            for sc in self.scenarios:  # every scenario's geometry must take the counts given
                try:
                    self.error_draws.sigmas(sc)
                except ValueError as exc:
                    raise ValueError(f"error_draws in {sc.name or 'a scenario'}: {exc}") from None

    def scenario_of_run(self, s_idx: int, r_idx: int) -> Scenario:
        """Scenario ``s_idx`` as run ``r_idx`` simulates it: with that run's draw of :attr:`error_draws`.

        The draws come from the first child of the run's stream (:func:`run_monte_carlo`), apart from the
        stream that simulates its noise: a study with draws has the same noise as one without.
        """
        if not (0 <= s_idx < len(self.scenarios) and 0 <= r_idx < self.runs):
            raise IndexError(f"no run {r_idx} of scenario {s_idx} in a study of {len(self.scenarios)} scenario(s) "
                             f"x {self.runs} run(s)")
        return self._drawn(s_idx, _run_stream(self.seed, s_idx * self.runs + r_idx))

    def _drawn(self, s_idx: int, seq: np.random.SeedSequence) -> Scenario:
        scen = self.scenarios[s_idx]
        if self.error_draws is None:
            return scen
        child = np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, 0))
        return self.error_draws.applied(scen, np.random.default_rng(child))

    def model(self, scenario: Scenario) -> TrackingModel:
        """The tracking model of a scenario (its geometry with this spec's motion and prior)."""
        return TrackingModel.of(scenario.geometry, motion=self.motion, weak_prior=self.weak_prior)

    def tracker(self, name: str) -> tuple[str, TrackerSettings]:
        """Registry name and settings of a (non-initiation) estimator name, ``lag:<s>`` included."""
        lag = _lag(name)
        if lag is not None:
            base = self.settings.get("fixed-lag", FixedLagSettings())
            assert isinstance(base, FixedLagSettings)
            return "fixed-lag", replace(base, lag=lag)
        name = ALIASES.get(name, name)
        return name, self.settings.get(name, ESTIMATORS[name].settings())


def _run_stream(seed: int, index: int) -> np.random.SeedSequence:
    """Run ``index``'s stream: the ``index``-th child of ``SeedSequence(seed)``, as ``spawn`` makes it."""
    return np.random.SeedSequence(seed, spawn_key=(index,))


@one_blas_thread
def _run_one(spec: MonteCarloSpec, s_idx: int, r_idx: int, seq: np.random.SeedSequence) -> dict[str, Any]:
    """One simulated run of one scenario through every estimator (executed in a worker, one BLAS thread)."""
    from fgdoppler.estimators.initiation import initiate, window_grid
    from fgdoppler.estimators.registry import run_estimator

    scen = spec._drawn(s_idx, seq)
    sim = simulate(scen, np.random.default_rng(seq))
    meas = sim.measurements
    truth_t = sim.truth.times
    truth_x = sim.truth.states
    window = meas.first_per_pair(spec.init_per_pair)
    model = spec.model(scen)
    grid = window_grid(window, model, spec.initiation)
    inits: dict[str, Any] = {}

    def init_of(method: Method) -> Any:
        if method not in inits:
            inits[method] = initiate(window, model, replace(spec.initiation, method=method), grid_result=grid)
        return inits[method]

    n_t = truth_t.size
    out: dict[str, Any] = {}
    verdicts: dict[str, str] = {}
    timing: dict[str, float] = {}
    references: dict[SmootherSettings, Any] = {}

    def reference(estimator: str, settings: Any) -> Any:
        """The smoother's result with the gate, loss and seed of ``settings``, shared by the filters (verify only)."""
        if not spec.verify or estimator == "smoother":
            return None
        key = SmootherSettings.reference_for(settings)
        if key not in references:
            references[key] = run_estimator("smoother", meas, model, init_of("lm"), key)
        return references[key]

    for name in spec.estimators:
        t_begin = time.perf_counter()
        n_x = model.n
        est = np.full((n_t, n_x), np.nan)
        cov = np.full((n_t, n_x, n_x), np.nan)
        if name in METHODS:
            ini = init_of(cast(Method, name))
            F = model.motion.F(truth_t - ini.t_start)
            est = F @ ini.x_start
            if ini.P_start is not None:
                cov = F @ ini.P_start @ np.swapaxes(F, -1, -2)
            verdicts[name] = ini.status
        else:
            estimator, settings = spec.tracker(name)
            result = run_estimator(estimator, meas, model, init_of("lm"), settings, verify=spec.verify,
                                   reference=reference(estimator, settings))
            res = result.primary
            idx = np.searchsorted(truth_t, res.times)
            est[idx] = res.states
            cov[idx] = np.where(res.cov_ok[:, None, None], res.covariances, np.nan)
            verdicts[name] = result.status
        pe, ve = errors(est, truth_x)
        with np.errstate(invalid="ignore"):
            ne = np.full(n_t, np.nan)
            ok = np.all(np.isfinite(cov), axis=(1, 2)) & np.all(np.isfinite(est), axis=1)
            if np.any(ok):
                ne[ok] = nees(est[ok], cov[ok], truth_x[ok])
        out[name] = (pe, ve, ne)
        timing[name] = time.perf_counter() - t_begin
    return {"s": s_idx, "r": r_idx, "data": out, "verdicts": verdicts, "timing": timing,
            "ambiguous": bool(inits["lm"].ambiguous) if "lm" in inits else False}


@dataclass(frozen=True, kw_only=True)
class MonteCarloResult:
    """Errors of every estimator in every run, and summaries.

    ``pos_se[s][name]``, ``vel_se[s][name]`` and ``nees[s][name]`` are
    ``(runs, n_times)`` arrays for scenario index ``s``; ``times[s]`` the
    scenario's truth times; ``verdicts[s][name]`` the status of every run
    (``"ok"``, ``"doubtful"``, ``"failed"``); ``error_draws`` the sensor
    errors drawn for each run (:attr:`MonteCarloSpec.error_draws`).
    """

    scenario_names: tuple[str, ...]
    estimators: tuple[str, ...]
    runs: int
    seed: int
    times: tuple[FloatArray, ...]
    pos_se: tuple[dict[str, FloatArray], ...]
    vel_se: tuple[dict[str, FloatArray], ...]
    nees: tuple[dict[str, FloatArray], ...]
    ambiguous: FloatArray
    verdicts: tuple[dict[str, NDArray[np.str_]], ...]
    wall_time: float
    workers: int
    timing: dict[str, float]
    state_dim: int = 4
    error_draws: ErrorDraws | None = None

    def pos_rmse(self, s: int, name: str) -> FloatArray:
        """Position RMSE over runs at each time of scenario ``s``."""
        return rmse(self.pos_se[s][name])

    def vel_rmse(self, s: int, name: str) -> FloatArray:
        """Velocity RMSE over runs at each time of scenario ``s``."""
        return rmse(self.vel_se[s][name])

    def mean_nees(self, s: int, name: str) -> FloatArray:
        """Run-averaged NEES at each time (NaN where no run has one)."""
        x = self.nees[s][name]
        ok = np.isfinite(x)
        n = ok.sum(axis=0)
        total = np.where(ok, x, 0.0).sum(axis=0)
        return np.where(n > 0, total / np.maximum(n, 1), np.nan)

    def run_nees(self, s: int, name: str, t_min: float = 0.0) -> FloatArray:
        """Each run's NEES averaged over its times ``>= t_min`` (NaN for a run with none)."""
        x = self.nees[s][name][:, np.asarray(self.times[s]) >= t_min]
        ok = np.isfinite(x)
        n = ok.sum(axis=1)
        return np.where(n > 0, np.where(ok, x, 0.0).sum(axis=1) / np.maximum(n, 1), np.nan)

    def nees_band(self) -> tuple[float, float]:
        """95 % band of the run-averaged NEES (``state_dim`` degrees of freedom per run)."""
        return nees_band(self.runs, self.state_dim)

    def nees_after(self, s: int, name: str, t0: float = NEES_FROM) -> float | None:
        """The run-averaged NEES (:meth:`mean_nees`) averaged over the times ``>= t0`` (``None`` where there is
        none): the number to hold against :meth:`nees_band`."""
        x = self.mean_nees(s, name)
        sel = (np.asarray(self.times[s]) >= t0) & np.isfinite(x)
        return float(np.mean(x[sel])) if np.any(sel) else None

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: per scenario and estimator the time-averaged RMSE, the NEES (:meth:`nees_after`,
        with its band ``nees_band`` for ``nees_from``) and the verdict counts; and the settings."""
        rows = []
        for s, name in enumerate(self.scenario_names):
            for e in self.estimators:
                r = self.pos_rmse(s, e)
                v = self.verdicts[s][e]
                rows.append({"scenario": name, "estimator": e,
                             "pos_rmse_mean": _nanmean(r), "pos_rmse_final": float(r[-1]) if np.isfinite(r[-1]) else None,
                             "vel_rmse_mean": _nanmean(self.vel_rmse(s, e)), "nees_mean": self.nees_after(s, e),
                             "verdicts": {k: int(np.sum(v == k)) for k in STATUSES}})
        return {"runs": self.runs, "seed": self.seed, "workers": self.workers, "wall_time": self.wall_time,
                "nees_from": NEES_FROM, "nees_band": list(self.nees_band()),
                "scenarios": list(self.scenario_names), "estimators": list(self.estimators),
                "ambiguous_fraction": self.ambiguous.tolist(), "timing_per_run": self.timing, "rows": rows,
                **({} if self.error_draws is None else {"error_draws": _draws_json(self.error_draws)})}

    def save(self, path: str | Path) -> tuple[Path, Path]:
        """Write ``path.npz`` (all arrays) and ``path.json`` (summary); returns both paths."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, Any] = {}
        for s in range(len(self.scenario_names)):
            arrays[f"times_{s}"] = self.times[s]
            for e in self.estimators:
                arrays[f"pos_{s}_{e}"] = self.pos_se[s][e]
                arrays[f"vel_{s}_{e}"] = self.vel_se[s][e]
                arrays[f"nees_{s}_{e}"] = self.nees[s][e]
                arrays[f"verdict_{s}_{e}"] = self.verdicts[s][e]
        arrays["ambiguous"] = self.ambiguous
        npz = path.with_suffix(".npz")
        tmp = npz.with_name(f".{npz.name}.tmp.npz")
        np.savez_compressed(tmp, **arrays)
        os.replace(tmp, npz)
        meta = {"scenario_names": list(self.scenario_names), "estimators": list(self.estimators), "runs": self.runs,
                "seed": self.seed, "wall_time": self.wall_time, "workers": self.workers, "timing": self.timing,
                "state_dim": self.state_dim,
                "error_draws": None if self.error_draws is None else _draws_json(self.error_draws),
                "summary": self.summary()}
        js = path.with_suffix(".json")
        atomic_write_text(js, json.dumps(meta, indent=1, allow_nan=False, default=_json_default))
        return npz, js

    @classmethod
    def load(cls, path: str | Path) -> MonteCarloResult:
        """Reload a result written by :meth:`save` (no re-running)."""
        path = Path(path)
        meta = json.loads(path.with_suffix(".json").read_text())
        data = np.load(path.with_suffix(".npz"))
        n = len(meta["scenario_names"])
        ests = tuple(meta["estimators"])
        return cls(
            scenario_names=tuple(meta["scenario_names"]), estimators=ests, runs=int(meta["runs"]),
            seed=int(meta["seed"]), times=tuple(data[f"times_{s}"] for s in range(n)),
            pos_se=tuple({e: data[f"pos_{s}_{e}"] for e in ests} for s in range(n)),
            vel_se=tuple({e: data[f"vel_{s}_{e}"] for e in ests} for s in range(n)),
            nees=tuple({e: data[f"nees_{s}_{e}"] for e in ests} for s in range(n)),
            verdicts=tuple({e: data[f"verdict_{s}_{e}"] for e in ests} for s in range(n)),
            ambiguous=data["ambiguous"], wall_time=float(meta["wall_time"]), workers=int(meta["workers"]),
            timing=dict(meta["timing"]), state_dim=int(meta.get("state_dim", 4)),
            error_draws=None if meta.get("error_draws") is None else ErrorDraws(
                **{k: v if isinstance(v, float | int) else tuple(v) for k, v in meta["error_draws"].items()}),
        )


def _draws_json(draws: ErrorDraws) -> dict[str, float | list[float]]:
    """The standard deviations of ``draws`` as JSON values (a list where given per pair or per site)."""
    return {k: v if isinstance(v, float) else list(v)
            for k, v in (("bias_sigma", draws.bias_sigma), ("site_sigma", draws.site_sigma))}


def _nanmean(x: FloatArray) -> float | None:
    f = x[np.isfinite(x)]
    return float(f.mean()) if f.size else None


def _json_default(o: object) -> object:
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(type(o).__name__)


def run_monte_carlo(
    spec: MonteCarloSpec,
    *,
    executor: Executor | None = None,
    workers: int = 1,
    progress: bool | None = None,
) -> MonteCarloResult:
    """Run a Monte Carlo study.

    Parameters
    ----------
    spec
        What to run.
    executor
        Any ``concurrent.futures.Executor`` (e.g. a Dask ``distributed``
        client's ``get_executor()``).  Default: a process pool of ``workers``
        processes, or in-process when ``workers == 1``.
    workers
        Process count of the default pool.
    progress
        Show a tqdm bar (default: only on a terminal).
    """
    from tqdm import tqdm

    t_begin = time.perf_counter()
    n_s = len(spec.scenarios)
    tasks = [(s, r, _run_stream(spec.seed, s * spec.runs + r)) for s in range(n_s) for r in range(spec.runs)]
    show = sys.stderr.isatty() if progress is None else progress
    own = None
    if executor is None and workers > 1:
        own = ProcessPoolExecutor(max_workers=workers)
        executor = own
    records: list[dict[str, Any]] = []
    try:
        with tqdm(total=len(tasks), desc="Monte Carlo", unit="run", disable=not show, leave=False) as bar:
            if executor is None:
                for s, r, q in tasks:
                    records.append(_run_one(spec, s, r, q))
                    bar.update(1)
            else:
                futures = [executor.submit(_run_one, spec, s, r, q) for s, r, q in tasks]
                for f in futures:
                    records.append(f.result())
                    bar.update(1)
    finally:
        if own is not None:
            own.shutdown()
    times = []
    pos, vel, nes, ver = [], [], [], []
    amb = np.zeros(n_s)
    timing: dict[str, float] = {e: 0.0 for e in spec.estimators}
    for s in range(n_s):
        recs = sorted((x for x in records if x["s"] == s), key=lambda x: x["r"])
        times.append(spec.scenarios[s].truth_times())
        pos.append({e: np.array([x["data"][e][0] for x in recs]) for e in spec.estimators})
        vel.append({e: np.array([x["data"][e][1] for x in recs]) for e in spec.estimators})
        nes.append({e: np.array([x["data"][e][2] for x in recs]) for e in spec.estimators})
        ver.append({e: np.array([x["verdicts"][e] for x in recs], dtype=np.str_) for e in spec.estimators})
        amb[s] = np.mean([x["ambiguous"] for x in recs])
        for x in recs:
            for e, v in x["timing"].items():
                timing[e] += v / len(records)
    return MonteCarloResult(
        scenario_names=tuple(sc.name for sc in spec.scenarios), estimators=spec.estimators, runs=spec.runs,
        seed=spec.seed, times=tuple(times), pos_se=tuple(pos), vel_se=tuple(vel), nees=tuple(nes), ambiguous=amb,
        verdicts=tuple(ver),
        wall_time=time.perf_counter() - t_begin, workers=workers if executor is None or own is not None else -1,
        timing=timing, state_dim=spec.scenarios[0].geometry.state_dim if spec.scenarios else 4,
        error_draws=spec.error_draws,
    )

