r"""Why does ``map``'s climb to the mode take six linearisations where the valley curves?  Two variants counted.

``map`` (:func:`fgdoppler.estimators.particle.run_map`) climbs to the
posterior mode at every report by Levenberg–Marquardt
(:meth:`~fgdoppler.estimators.particle_posterior._Posterior._climb`, its
damping starting at :math:`\lambda_0 = 10^{-3}` times the diagonal of the
Gauss–Newton information and divided by 3 after each accepted step).  In
the curved valleys of case a 5 km and case b 45 km its gains shrink only
geometrically.  This study runs ``map`` on the accuracy benchmark's
recordings and, at every climb, first climbs the same way from the same
start with a variant, counting the model linearisations of each; the run
itself is ``map``'s (the variant's peak is thrown away).  Variants:

* ``--lambda0 L``: the same Levenberg–Marquardt with the damping starting
  at ``L`` (does the damping hold back the steps along the weakly observed
  direction, whose information is far below the diagonal's entries?);
* ``--sr1``: besides, the Gauss–Newton matrix plus a symmetric-rank-one
  secant estimate of the residuals' second-order term
  :math:`\sum_j r_j\nabla^2 r_j` (Dennis, Gay and Welsch's structured
  update, secant condition :math:`\mathbf S\mathbf s = (\mathbf J_+ - \mathbf J)^\top\mathbf r_+`;
  the plain Gauss–Newton matrix where the sum is not positive definite):
  is it a large-residual problem?

Printed: climbs, mean and median linearisations per climb of each, and the
variant's peak against ``map``'s (log density and position).  Gaussian
loss only (the estimators' default).

The counts quoted in the docs were measured with 4,096 particles,
``map``'s default until 2026-12-04 (``--particles 4096``).

Run: python studies/mode_climb.py [--scenario 5] [--runs 4] [--seed 2026] [--particles N] [--lambda0 1e-6] [--sr1]
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from _common import paper_run

import fgdoppler as fd
import fgdoppler.estimators.particle_posterior as pp
from fgdoppler.estimators.particle import run_map

FloatArray = np.ndarray


def variant_climb(post: pp._Posterior, x: FloatArray, lambda0: float, sr1: bool) -> tuple[FloatArray, float]:
    """The variant's climb from ``x``: its peak and log density (module docstring)."""
    quad = post._prior_quadratic()
    value, r, Jw = post._linearised(x, quad)
    if not np.isfinite(value):
        return x, value
    n = x.size
    S = np.zeros((n, n))
    lam = lambda0
    for _ in range(pp.MODE_ITERATIONS):
        A = Jw.T @ Jw
        g = Jw.T @ r
        if quad is not None:
            A += quad[1].T @ quad[1]
            g += quad[1].T @ (quad[1] @ (x - quad[0]))
        D = np.diag(np.maximum(np.diag(A), 1e-12 * max(float(np.max(np.diag(A))), 1e-300)))
        B = A + S
        if sr1:
            try:
                np.linalg.cholesky(B)
            except np.linalg.LinAlgError:
                B = A
        gain = 0.0
        for _ in range(pp.MODE_DAMPING_TRIES):
            try:
                trial = x - np.linalg.solve(B + lam * D, g)
            except np.linalg.LinAlgError:
                lam *= 4.0
                continue
            v, r_t, J_t = post._linearised(trial, quad)
            if v > value:
                gain, s = v - value, trial - x
                u = (J_t - Jw).T @ r_t - S @ s
                if sr1 and abs(float(u @ s)) > 1e-8 * np.linalg.norm(u) * np.linalg.norm(s):
                    S = S + np.outer(u, u) / float(u @ s)
                x, value, r, Jw = trial, v, r_t, J_t
                lam = max(lam / 3.0, 1e-9)
                break
            lam *= 4.0
        if gain < pp.MODE_TOLERANCE:
            break
    return x, value


def main() -> None:
    p = argparse.ArgumentParser(prog="python studies/mode_climb.py")
    p.add_argument("--scenario", type=int, default=5, help="index of fd.paper_scenarios() (5: case b 45 km)")
    p.add_argument("--runs", type=int, default=4)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--particles", type=int, default=fd.MapSettings().n_particles)
    p.add_argument("--lambda0", type=float, default=1e-6)
    p.add_argument("--sr1", action="store_true")
    args = p.parse_args()
    calls = {"n": 0}
    linearised, climb = pp._Posterior._linearised, pp._Posterior._climb
    records: list[tuple[int, int, float, float]] = []

    def counted(self: pp._Posterior, x: FloatArray, quad: Any) -> Any:
        calls["n"] += 1
        return linearised(self, x, quad)

    def both(self: pp._Posterior, x: FloatArray) -> tuple[FloatArray, float]:
        peaks = list(self._peaks)
        calls["n"] = 0
        xv, vv = variant_climb(self, np.array(x, dtype=float), args.lambda0, args.sr1)
        n_variant = calls["n"]
        self._peaks = peaks
        calls["n"] = 0
        xm, vm = climb(self, x)
        d = self.model.dim
        records.append((calls["n"], n_variant, vm - vv, float(np.linalg.norm((xm - xv)[:d]))))
        return xm, vm

    pp._Posterior._linearised = counted  # type: ignore[method-assign]
    pp._Posterior._climb = both  # type: ignore[method-assign]
    for r in range(args.runs):
        sim, model, init = paper_run(args.scenario, r, args.seed)
        run_map(sim.measurements, model, init, fd.MapSettings(n_particles=args.particles))
    own, var = np.array([q[0] for q in records]), np.array([q[1] for q in records])
    dv, dx = np.array([q[2] for q in records]), np.array([q[3] for q in records])
    print(f"{len(records)} climbs; linearisations per climb, map's: mean {own.mean():.2f}, median {np.median(own):g}; "
          f"variant's (lambda0 {args.lambda0:g}{', SR1' if args.sr1 else ''}): mean {var.mean():.2f}, "
          f"median {np.median(var):g}")
    print(f"log density, map's peak less the variant's: median {np.median(dv):.2e}, min {dv.min():.2e}, "
          f"max {dv.max():.2e}; position apart (m): median {np.median(dx):.3g}, 99th percentile "
          f"{np.percentile(dx, 99):.3g}, max {dx.max():.3g}")


if __name__ == "__main__":
    main()
