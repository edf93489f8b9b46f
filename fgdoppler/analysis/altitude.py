r"""The altitude study: the paper's six scenarios flown at altitude over the same ground sensors.

Each scenario (case a or b, start 5, 25 or 45 km, velocity (10, -100) m/s, 30 s) is flown level at
heights :math:`z_0` of 0, 1, 3 and 10 km over the paper's sensors, which stay on the ground.  The
problem is then 3-D (states :math:`[x, y, z, \dot x, \dot y, \dot z]`, the default zone's height
band 0–12.5 km) and for each scenario and height the study reports

* the observability measure :math:`O` of the initiation window (10 measurements per pair) in 3-D:
  :math:`\log_{10}\det(\mathbf J'\mathbf J)` of the 6×6 information, floored at −40;
* the smoothing Cramér–Rao bound of the 3-D position at the end of the track from the data alone
  (deterministic constant velocity, all measurements) and with the zone's weak prior on the start
  (the information every fgdoppler estimator uses), as the RMS of the position bound;
* Monte Carlo position RMSE (3-D, time-averaged after the window) of the offline smoother and of
  the best online estimator (the lower RMSE of the EKF and the particle estimator by default),
  and the horizontal RMSE of the 2-D model (the paper's,
  which assumes :math:`z = 0`) run on the same 3-D recordings;
* the smoother's run-averaged NEES at the end of the track (6 degrees of freedom: about 6 when
  its covariance is honest) and the share of its runs with the verdict ``ok``.

:math:`z_0 = 0` is the limit: there the Doppler's derivatives with respect to height vanish (a target
on the sensors' plane and its mirror image give the same Doppler), the information is singular and
:math:`O = -40`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgdoppler.analysis.workers import one_blas_thread

__all__ = ["ALTITUDES", "AltitudeStudy", "altitude_study"]

FloatArray = NDArray[np.float64]

#: The study's heights (m) above the ground sensors.
ALTITUDES: tuple[float, ...] = (0.0, 1e3, 3e3, 10e3)
#: The initiation window: measurements per pair (as in the paper's scenarios).
WINDOW_PER_PAIR = 10


@dataclass(frozen=True, kw_only=True)
class AltitudeStudy:
    """Observability, bounds and Monte Carlo accuracy of the paper's scenarios versus altitude.

    Every array is ``(n_scenarios, n_altitudes)``; positions in metres.

    Attributes
    ----------
    scenarios
        The paper scenarios' names (``"case a, start 5 km"``, ...).
    altitudes
        Heights (m).
    observability
        :math:`O` of the initiation window in 3-D (−40: unobservable).
    crlb
        RMS of the smoothing CRLB of the end position from the data alone (``inf`` when the
        information is singular).
    crlb_prior
        The same bound with the zone's weak prior on the first state.
    rmse_smoother, rmse_online
        Time-averaged 3-D position RMSE after the window of the offline smoother and of the
        best of the online estimators ``online`` (per cell; which one is ``best_online``).
    rmse_2d
        Time-averaged horizontal RMSE of the 2-D model's smoother on the same recordings.
    nees_smoother
        The smoother's NEES of the last state, averaged over runs.
    ok_smoother
        Fraction of the smoother's runs whose verdict is ``ok``.
    best_online
        Name of the online estimator with the lower RMSE, per cell.
    runs, seed, online, wall_time
        The protocol.
    """

    scenarios: tuple[str, ...]
    altitudes: tuple[float, ...]
    observability: FloatArray
    crlb: FloatArray
    crlb_prior: FloatArray
    rmse_smoother: FloatArray
    rmse_online: FloatArray
    best_online: NDArray[np.str_]
    rmse_2d: FloatArray
    nees_smoother: FloatArray
    ok_smoother: FloatArray
    runs: int
    seed: int
    online: tuple[str, ...]
    wall_time: float

    def table_markdown(self) -> str:
        """One row per scenario and altitude: O, both bounds and the three RMSEs."""
        rows = ["| scenario | altitude (km) | O (3-D window) | CRLB data only (m) | CRLB with zone prior (m) | "
                "smoother RMSE (m) | smoother NEES | smoother ok | best online RMSE (m) | "
                "2-D model RMSE, horizontal (m) |",
                "|---|---|---|---|---|---|---|---|---|---|"]
        for i, name in enumerate(self.scenarios):
            for j, alt in enumerate(self.altitudes):
                rows.append(f"| {name} | {alt / 1e3:g} | {self.observability[i, j]:.1f} | {_m(self.crlb[i, j])} | "
                            f"{_m(self.crlb_prior[i, j])} | {_m(self.rmse_smoother[i, j])} | "
                            f"{self.nees_smoother[i, j]:.3g} | {self.ok_smoother[i, j]:.0%} | "
                            f"{_m(self.rmse_online[i, j])} ({self.best_online[i, j]}) | {_m(self.rmse_2d[i, j])} |")
        return "\n".join(rows)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (non-finite values as ``None``)."""
        def clean(a: FloatArray) -> list[list[float | None]]:
            return [[float(v) if np.isfinite(v) else None for v in row] for row in a]
        return {"scenarios": list(self.scenarios), "altitudes": list(self.altitudes), "runs": self.runs,
                "seed": self.seed, "online": list(self.online), "wall_time": self.wall_time,
                "best_online": self.best_online.tolist(),
                "observability": clean(self.observability), "crlb": clean(self.crlb),
                "crlb_prior": clean(self.crlb_prior), "rmse_smoother": clean(self.rmse_smoother),
                "rmse_online": clean(self.rmse_online), "rmse_2d": clean(self.rmse_2d),
                "nees_smoother": clean(self.nees_smoother), "ok_smoother": clean(self.ok_smoother)}

    def figure(self, path: str | Path) -> Path:
        """Three panels, one column: the 3-D estimators' error and bound, the 2-D model's error, and O."""
        import matplotlib.pyplot as plt

        from fgdoppler import plotting

        fig, (top, middle, bottom) = plt.subplots(3, 1, figsize=(7.2, 11.0), layout="constrained", sharex=True)
        km = np.asarray(self.altitudes) / 1e3
        colours = [plt.get_cmap("tab10")(k) for k in range(10)]
        for i, name in enumerate(self.scenarios):
            c = colours[i % len(colours)]
            top.semilogy(km, self.rmse_smoother[i], "o-", color=c, lw=1.5, label=f"{name}")
            top.semilogy(km, self.rmse_online[i], "s--", color=c, lw=1.0, ms=4)
            top.semilogy(km, self.crlb_prior[i], ":", color=c, lw=1.2)
            middle.semilogy(km, self.rmse_2d[i], "o-", color=c, lw=1.3)
            bottom.plot(km, self.observability[i], "o-", color=c, lw=1.3)
        top.plot([], [], "ko-", label="smoother RMSE")
        top.plot([], [], "ks--", ms=4, label=f"best online ({' or '.join(self.online)}) RMSE")
        top.plot([], [], "k:", label="CRLB with zone prior")
        top.set_ylabel("3-D position error (m)")
        top.set_title(f"3-D model: paper scenarios over ground sensors, {self.runs} run(s) each", fontsize="medium")
        middle.set_ylabel("horizontal error (m)")
        middle.set_title("the paper's 2-D model on the same recordings (smoother)", fontsize="medium")
        bottom.set_xlabel("altitude (km)")
        bottom.set_ylabel("O of the window (3-D; -40: unobservable)")
        for ax in (top, middle, bottom):
            ax.grid(True, which="both", alpha=0.3)
        handles, labels = top.get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize="small", frameon=False)
        return plotting.save(top, path)


def _m(v: float) -> str:
    if not np.isfinite(v):
        return "∞"
    return f"{v:,.0f}" if v >= 10 else f"{v:.1f}"


def _bound_rms(P: FloatArray) -> float:
    if not np.all(np.isfinite(P)):
        return float("inf")
    return float(np.sqrt(max(np.trace(P[:3, :3]), 0.0)))


@one_blas_thread
def _one_run(case: str, start_x: float, altitude: float, online: tuple[str, ...], seed: Any) -> tuple[float, ...]:
    """One recording at ``altitude``: time-averaged squared position errors of the smoother and the 2-D
    model, the smoother's final NEES, 1.0 if its verdict is ``ok``, then the online estimators' errors
    (in a worker, one BLAS thread)."""
    import fgdoppler as fd

    scen = fd.paper_scenario(case, start_x, altitude=altitude)
    sim = fd.simulate(scen, np.random.default_rng(seed))
    window = sim.measurements.first_per_pair(WINDOW_PER_PAIR)
    t_window = float(window.time.max())
    out = []
    init = fd.initiate(window, scen.geometry)
    nees, ok = float("nan"), 0.0
    for name in ("smoother", *online):
        result = fd.run_estimator(name, sim.measurements, scen.geometry, init, verify=False)
        track = result.primary
        keep = track.times > t_window
        err = track.states[keep, :3] - sim.truth.at(track.times[keep])[:, :3]
        out.append(float(np.mean(np.sum(err**2, axis=1))))
        if name == "smoother":
            ok = float(result.status == "ok")
            if track.cov_ok[-1]:
                e = track.states[-1] - sim.truth.at(track.times[-1:])[0]
                nees = float(e @ np.linalg.solve(track.covariances[-1], e))
    flat = fd.paper_geometry(case)  # the paper's 2-D model on the same (3-D) data
    track = fd.run_estimator("smoother", sim.measurements, flat, fd.initiate(window, flat)).primary
    keep = track.times > t_window
    err = track.states[keep, :2] - sim.truth.at(track.times[keep])[:, :2]
    return (out[0], float(np.mean(np.sum(err**2, axis=1))), nees, ok, *out[1:])


def altitude_study(*, altitudes: Sequence[float] = ALTITUDES, runs: int = 10, seed: int = 2026, workers: int = 1,
                   online: Sequence[str] = ("ekf", "particle"), scenarios: Sequence[tuple[str, float]] | None = None
                   ) -> AltitudeStudy:
    """Run the study (module docstring): bounds at the truth, then ``runs`` seeded recordings per cell.

    Parameters
    ----------
    altitudes
        Heights above the ground sensors (m), each ``>= 0``.
    runs
        Monte Carlo recordings per scenario and height (independent streams from
        ``numpy.random.SeedSequence(seed)``).
    workers
        Processes for the Monte Carlo part (1: in this process).
    online
        The online estimators compared with the smoother (registry names); the better per cell is reported.
    scenarios
        ``(case, start_x)`` pairs of paper scenarios (default: all six).

    Raises
    ------
    ValueError
        If ``runs < 1``, an altitude is negative or not finite, or an ``online`` name is unknown.
    """
    import fgdoppler as fd
    from fgdoppler.analysis.bounds import crlb_deterministic
    from fgdoppler.estimators.registry import ESTIMATORS
    from fgdoppler.simulation import PAPER_START_X

    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")
    alts = tuple(float(a) for a in altitudes)
    if not alts or not all(np.isfinite(a) and a >= 0 for a in alts):
        raise ValueError(f"altitudes must be finite and >= 0, got {altitudes}")
    online = tuple(online)
    if not online or any(o not in ESTIMATORS or o == "smoother" for o in online):
        raise ValueError(f"online must name online estimators of the registry, got {online!r}")
    t_begin = time.perf_counter()
    cells = [(case, float(x)) for case, x in scenarios] if scenarios is not None else \
        [(case, x) for case in ("a", "b") for x in PAPER_START_X]
    if not cells:
        raise ValueError("no scenarios")
    shape = (len(cells), len(alts))
    O, crlb, crlb_prior = np.empty(shape), np.empty(shape), np.empty(shape)
    for i, (case, x) in enumerate(cells):
        for j, alt in enumerate(alts):
            scen = fd.paper_scenario(case, x, altitude=alt)
            meas = fd.simulate(scen, np.random.default_rng(0)).measurements  # times, pairs and sigmas only
            window = meas.first_per_pair(WINDOW_PER_PAIR)
            times = [window.time[window.pair == k] for k in range(scen.geometry.n_pairs)]
            O[i, j] = fd.observability_measure(np.asarray(scen.x0), scen.geometry, times)
            t_end = [float(meas.time.max())]
            crlb[i, j] = _bound_rms(crlb_deterministic(scen.geometry, scen.x0, meas, t_end, smoothing=True)[0])
            prior_info = np.linalg.inv(scen.geometry.zone.prior()[1])
            crlb_prior[i, j] = _bound_rms(crlb_deterministic(scen.geometry, scen.x0, meas, t_end, smoothing=True,
                                                             prior_information=prior_info)[0])
    seeds = np.random.SeedSequence(seed).spawn(len(cells) * len(alts) * runs)
    jobs = [(case, x, alt, online, seeds[(i * len(alts) + j) * runs + r])
            for i, (case, x) in enumerate(cells) for j, alt in enumerate(alts) for r in range(runs)]
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            results = list(pool.map(_one_run, *zip(*jobs, strict=True)))
    else:
        results = [_one_run(*job) for job in jobs]
    res = np.array(results).reshape(len(cells), len(alts), runs, 4 + len(online))
    rmse = np.sqrt(res[..., [0, 1]].mean(axis=2))
    rmse_on = np.sqrt(res[..., 4:].mean(axis=2))
    best = np.argmin(rmse_on, axis=-1)
    return AltitudeStudy(scenarios=tuple(f"case {c}, start {x / 1e3:g} km" for c, x in cells), altitudes=alts,
                         observability=O, crlb=crlb, crlb_prior=crlb_prior, rmse_smoother=rmse[..., 0],
                         rmse_online=np.take_along_axis(rmse_on, best[..., None], axis=-1)[..., 0],
                         best_online=np.array(online)[best], rmse_2d=rmse[..., 1],
                         nees_smoother=np.nanmean(res[..., 2], axis=2), ok_smoother=res[..., 3].mean(axis=2),
                         runs=runs, seed=seed, online=online,
                         wall_time=time.perf_counter() - t_begin)
