"""The particle estimator's hot path: the Doppler of every particle's track at every measurement.

Each Metropolis move of :mod:`fgdoppler.estimators.particle` evaluates the
likelihood of all its tracks against all the data so far (4,096 tracks ×
up to 120 measurements on the paper's recordings).  Two variants, each timed
in a fresh process (the C allocator's state depends on what ran before in a
process: timed one after the other in one process, the second variant
inherited a heap the first had grown and looked twice as fast as it is):

* now: :func:`fgdoppler.models.doppler._along`, the compiled loop of
  :func:`fgdoppler.models.doppler_kernels.along` (one pass per entry);
* before: the per-state model's ``(n, m, d)`` layout in one block
  (:func:`fgdoppler.models.doppler._terms`), and the likelihood in blocks of
  2^20 entries.

Both must give the same numbers to the bit: the kernel on 4,096 tracks × 120
measurements, and a whole particle run (case a 25 km, CPU time), each
measured in a process of its own.

A third pair times the weights' normalisation: the particle and map
estimators with :func:`fgdoppler.estimators.log_sum_exp.log_sum_exp`
(now) against :func:`scipy.special.logsumexp` (before; the same arithmetic
behind SciPy's array-API dispatch), a run of each on case b 45 km, where
``map`` is slowest; the same tracks to the bit.

A fourth times ``map``'s read-out on the same recording: the information
at each report's mode taken from the climb that ended there (now) against
a linearisation made afresh (before: ``_Posterior._remember`` off); the
same track to the bit.  The saving, about one model linearisation of the
whole window per report, is a few per cent of the run's CPU time, below
this machine's run-to-run scatter, so that row's ratio is of the
linearisations made (counted, exact), beside the CPU times.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from benchmarks._common import Row

_SCRIPT = r"""
import hashlib, json, sys, time
import numpy as np
import fgdoppler as fd
import fgdoppler.estimators.particle_posterior as particle_posterior
import fgdoppler.models.observation as observation
from fgdoppler.models.doppler import _along, _terms

def strided(x, t, tx, rx, *, singular="raise"):
    d = x.shape[-1] // 2
    vel = x[:, None, d:]
    h, _, _, mask = _terms(x[:, None, :d] + t[None, :, None] * vel, vel, tx[None], rx[None], jacobian=False,
                           singular=singular)
    return h, mask

before = sys.argv[1] == "before"
fn = strided if before else _along
if before:
    particle_posterior.CHUNK_ROWS, observation._along = 1 << 20, strided
if sys.argv[1] == "fresh":
    particle_posterior._Posterior._remember = lambda self, *args: None
if sys.argv[1] == "scipy":
    import fgdoppler.estimators.particle as particle
    from scipy.special import logsumexp
    particle_posterior.log_sum_exp = particle.log_sum_exp = logsumexp

def cpu(f, repeat):
    out = []
    for _ in range(repeat):
        c = time.process_time()
        f()
        out.append(time.process_time() - c)
    return float(np.median(out))

if sys.argv[2] == "kernel":
    g = fd.paper_geometry("a")
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4096, 4)) * [5e3, 3e3, 100.0, 100.0] + [25e3, 0.0, 0.0, 0.0]
    t = np.sort(rng.uniform(0.0, 30.0, 120))
    c = rng.integers(0, 2, 120)
    h = fn(x, t, g.tx[c], g.rx[c], singular="mask")[0]
    seconds = cpu(lambda: fn(x, t, g.tx[c], g.rx[c], singular="mask"), 15)
    print(json.dumps({"seconds": seconds, "hash": hashlib.sha256(h.tobytes()).hexdigest()}))
    sys.exit()

case_b = sys.argv[2] in ("weights", "mode")
scen = fd.paper_scenario("b", 45e3) if case_b else fd.paper_scenario("a", 25e3)
sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([7, 1, 3])))
model = fd.TrackingModel.of(scen.geometry)
m = sim.measurements
init = fd.initiate(m.first_per_pair(10), model)
names = {"weights": ("particle", "map"), "mode": ("map",)}.get(sys.argv[2], ("particle",))
calls = [0]
if sys.argv[2] == "mode":  # count the mode's linearisations (only there: the other rows time the plain code)
    linearised = particle_posterior._Posterior._linearised

    def counted(self, x, quad):
        calls[0] += 1
        return linearised(self, x, quad)

    particle_posterior._Posterior._linearised = counted
states = np.concatenate([fd.run_estimator(n, m, model, init, verify=False).primary.states for n in names])
n_calls = calls[0]
seconds = cpu(lambda: [fd.run_estimator(n, m, model, init, verify=False) for n in names], 3)
print(json.dumps({"seconds": seconds, "hash": hashlib.sha256(states.tobytes()).hexdigest(), "calls": n_calls}))
"""


def _variant(name: str, what: str) -> tuple[float, str, int]:
    """CPU seconds (median), a hash of the numbers and the mode's linearisations of ``what`` in a fresh process.

    ``what`` is kernel, run, weights or mode; the linearisations are those of one run (0 for the kernel).
    """
    out = subprocess.run([sys.executable, "-c", _SCRIPT, name, what], check=True, capture_output=True, text=True,
                         env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    d = json.loads(out.stdout.strip().splitlines()[-1])
    return float(d["seconds"]), str(d["hash"]), int(d.get("calls", 0))


def run() -> list[Row]:
    rows = []
    for what, before, name, unit, target in (
            ("kernel", "before",
             "Doppler of 4,096 tracks x 120 measurements: compiled loop vs (n, m, d) layout", 1e3, 0.5),
            ("run", "before", "particle run, case a 25 km: compiled likelihood vs the earlier evaluation", 1.0, 0.7),
            ("weights", "scipy", "particle + map runs, case b 45 km: log_sum_exp vs scipy.special.logsumexp",
             1.0, 0.95),
            ("mode", "fresh", "map run, case b 45 km: the information at each mode from its climb vs afresh "
             "(model linearisations)", 1.0, 0.95)):
        (t_now, h_now, c_now), (t_before, h_before, c_before) = _variant("now", what), _variant(before, what)
        if h_now != h_before:
            raise AssertionError(f"the faster variant changed the numbers ({what})")
        ratio = c_now / c_before if what == "mode" else t_now / t_before
        value = (f"{t_now * unit:.1f} ms vs {t_before * unit:.1f} ms CPU" if unit > 1
                 else f"{t_now:.2f} s vs {t_before:.2f} s CPU") + ", identical"
        if what == "mode":
            value = f"{c_now:,} vs {c_before:,} linearisations, " + value
        rows.append(Row(name=name, value=value, ratio=ratio, target=f"<= {target:g}x", met=ratio <= target))
    return rows


if __name__ == "__main__":
    for row in run():
        print(f"{row.name}: {row.value} (ratio {np.round(row.ratio or 0, 2)}) -> {'met' if row.met else 'NOT MET'}")
