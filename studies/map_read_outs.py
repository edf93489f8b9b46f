r"""Where along a curved valley should ``map`` report?  The mode against points on the valley's floor.

In the curved valleys of case a 5 km and case b 45 km ``map`` reports the
posterior mode, which on the accuracy benchmark's recordings is 213-288 m
closer to the truth than the particle estimator's posterior mean
(docs/concepts.md, "The filtered mode").  The mean lies inside the
curve, off the valley's floor; is that what costs it, or is it where the
mean lies *along* the valley?  This study reads one run of the particle
posterior (:func:`fgdoppler.estimators.particle.run_map`, its defaults, no
ambiguity resolution or restarts, so every read-out comes from the same
particles) at every report in five ways:

* ``map``: what ``map`` reports (the mode, or the mean where the posterior is skewed);
* ``mode``: the mode throughout;
* ``mean``: the particles' weighted mean throughout;
* ``floor-mean``: the point of highest posterior density on the hyperplane
  :math:`\mathbf n^\top(\mathbf x - \bar{\mathbf x}) = 0` through the mean
  :math:`\bar{\mathbf x}`, where :math:`\mathbf n` is the valley's
  direction — the major axis of the Laplace covariance
  :math:`\mathbf P` at the mode, taken on its correlation matrix
  (:math:`\mathbf n = \mathbf D^{-1}\mathbf v`, :math:`\mathbf D = \mathrm{diag}(\mathbf P)^{1/2}`,
  :math:`\mathbf v` the top eigenvector of :math:`\mathbf D^{-1}\mathbf P\mathbf D^{-1}`,
  normalised): the valley's floor at the mean's place along it;
* ``floor-median``: the same at the particles' weighted median of
  :math:`\mathbf n^\top\mathbf x`.

The floor points are found by nonlinear least squares on the hyperplane's
coordinates (:func:`floor_point`; the recordings' Gaussian loss, the
estimators' default), from the mode moved onto it.  Per
scenario: the position RMSE over t >= 5 s of each read-out (the accuracy
benchmark's :func:`~fgdoppler.analysis.metrics.time_averaged_rmse`) and
each one's paired difference against ``mode`` with its 95 % bootstrap
interval.  The study reads private parts of the particle posterior
(``_ModeReadOut.report`` is wrapped in each worker) because the read-outs
it compares are not ``map``'s.

The numbers quoted here and in the docs were measured with 4,096
particles, ``map``'s default until 2026-12-04 (``--particles 4096``).

Run: python studies/map_read_outs.py [--runs 100] [--seed 2026] [--particles N] [--workers 2] [--out DIR]
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from _common import each_run, paper_run, save_table
from scipy.optimize import least_squares

import fgdoppler as fd
import fgdoppler.estimators.particle as particle
from benchmarks.bench_accuracy import T_RMSE, _on_grid
from fgdoppler.analysis.metrics import compare_rmse, time_averaged_rmse
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.particle_posterior import _along_jacobian, _Posterior

FloatArray = np.ndarray
READ_OUTS = ("map", "mode", "mean", "floor-mean", "floor-median")


def valley_normal(post: _Posterior, x_mode: FloatArray) -> FloatArray | None:
    """The valley's direction :math:`\\mathbf n` at the mode (module docstring); ``None`` where singular."""
    laplace = post._state_laplace(x_mode)
    if laplace is None:
        return None
    P = laplace[0]
    s = np.sqrt(np.diag(P))
    v = np.linalg.eigh(P / np.outer(s, s))[1][:, -1]
    n = v / s
    return np.asarray(n / np.linalg.norm(n), dtype=float)


def floor_point(post: _Posterior, x_mode: FloatArray, n: FloatArray, level: float) -> FloatArray:
    """The highest point of the posterior on the hyperplane ``n·x = level`` (module docstring).

    Nonlinear least squares (:func:`scipy.optimize.least_squares`, Levenberg–Marquardt) on the plane's
    coordinates, of the whitened residuals of the data since the anchor and the prior's Gaussian factor, from
    the mode moved onto the plane.  The prior's support (the zone) is not imposed; where the track meets a
    sensor the starting point is returned.
    """
    basis = np.linalg.qr(np.column_stack([n, np.eye(n.size)]))[0][:, 1:n.size]
    x0 = x_mode + n * (level - n @ x_mode)
    d, quad = post.data, post._prior_quadratic()
    prior_rows = np.zeros((0, n.size)) if quad is None else quad[1]

    last: dict[bytes, tuple[FloatArray, FloatArray]] = {}

    def rows(y: FloatArray) -> tuple[FloatArray, FloatArray]:
        # least_squares asks for the residuals and then the Jacobian at the same point: one linearisation serves both
        key = y.tobytes()
        if key not in last:
            x = x0 + basis @ y
            h, J = _along_jacobian(post.model, x, d.t, d.pair)
            prior = np.zeros(0) if quad is None else quad[1] @ (x - quad[0])
            last.clear()
            last[key] = (np.concatenate([(h - d.z) / d.sigma, prior]),
                         np.vstack([J / d.sigma[:, None], prior_rows]) @ basis)
        return last[key]

    try:
        y = least_squares(lambda y: rows(y)[0], np.zeros(n.size - 1), jac=lambda y: rows(y)[1], method="lm").x
    except ValueError:  # the track passes through a sensor
        return x0
    return np.asarray(x0 + basis @ y, dtype=float)


def _weighted_median(c: FloatArray, w: FloatArray) -> float:
    order = np.argsort(c)
    return float(c[order][min(int(np.searchsorted(np.cumsum(w[order]), 0.5)), c.size - 1)])


@one_blas_thread
def one_run(args: tuple[int, int, int], *, particles: int) -> dict[str, Any]:
    """Squared position errors of every read-out on one run (module docstring), with ``particles`` particles."""
    s, r, seed = args
    sim, model, init = paper_run(s, r, seed)
    records: list[tuple[float, dict[str, FloatArray]]] = []
    plain = particle._ModeReadOut.report

    def report(self: particle._ModeReadOut, t: float) -> tuple[FloatArray, FloatArray]:
        point, cov = plain(self, t)
        post = self.post
        assert self.last_mode is not None
        xa = self.last_mode[1]
        mean = post.weights() @ post.x
        n = valley_normal(post, xa)
        if n is None:
            floors = {"floor-mean": mean, "floor-median": mean}
        else:
            floors = {"floor-mean": floor_point(post, xa, n, float(n @ mean)),
                      "floor-median": floor_point(post, xa, n, _weighted_median(post.x @ n, post.weights()))}
        dt = t - post.t_anchor
        at_t = {k: post.model.motion.propagate(v, dt) for k, v in {"mode": xa, "mean": mean, **floors}.items()}
        records.append((t, {"map": point, **at_t}))
        return point, cov

    particle._ModeReadOut.report = report  # type: ignore[method-assign]
    try:
        particle.run_map(sim.measurements, model, init, fd.MapSettings(n_particles=particles))
    finally:
        particle._ModeReadOut.report = plain  # type: ignore[method-assign]
    t = np.array([q[0] for q in records])
    eye = np.broadcast_to(np.eye(model.n), (t.size, model.n, model.n))
    out: dict[str, Any] = {"s": s, "r": r, "t": sim.truth.times.tolist()}
    for name in READ_OUTS:
        x = np.array([q[1][name] for q in records])
        out[name] = _on_grid(sim.truth.times, t, x, eye, sim.truth.states)[0].tolist()
    return out


def summary(rows: list[dict[str, Any]]) -> str:
    """One Markdown table line per scenario."""
    others = [n for n in READ_OUTS if n != "mode"]
    lines = ["| scenario | RMSE (m), " + " / ".join(READ_OUTS) + " | "
             + " | ".join(f"{n} − mode (m, 95 %)" for n in others) + " |",
             "|---|---|" + "---|" * len(others)]
    for s, scen in enumerate(fd.paper_scenarios()):
        rs = [row for row in rows if row["s"] == s]
        if not rs:
            continue
        t = np.array(rs[0]["t"])
        se = {k: np.array([row[k] for row in rs]) for k in READ_OUTS}
        with warnings.catch_warnings():  # all-NaN columns: no state before the window ends
            warnings.simplefilter("ignore", RuntimeWarning)
            lines.append(f"| {scen.name} | " + " / ".join(f"{time_averaged_rmse(se[k], t, t0=T_RMSE):,.0f}"
                                                          for k in READ_OUTS) + " | "
                         + " | ".join(str(compare_rmse(se[k], se["mode"], t, t0=T_RMSE)) for k in others) + " |")
    return "\n".join(lines)


def main() -> None:
    args, rows = each_run(one_run, "map_read_outs.py", "map_read_outs", chunksize=1, options={
        "--particles": {"type": int, "default": fd.MapSettings().n_particles,
                        "help": "map's particles (the docs' numbers: 4096, the default until 2026-12-04)"}})
    text = f"{args.runs} runs per scenario, seed {args.seed}; `map`'s particle posterior read out five ways\n\n"
    save_table(args.out, f"map_read_outs_seed{args.seed}", text + summary(rows) + "\n", rows)


if __name__ == "__main__":
    main()
