"""The compiled Doppler loops (:mod:`fgdoppler.models.doppler_kernels`) against numpy's layout of the same
arithmetic (:func:`fgdoppler.models.doppler._terms` on the propagated states, then the chain rule), at the
sizes the library calls them with, through the same entry points (the numpy variant stands in for the
compiled module), alternately in one process:

* the initiation window's factor: one start state, its 20 measurements, Doppler and Jacobian
  (:func:`fgdoppler.models.doppler._cv`, at every Levenberg-Marquardt linearisation);
* a restart check's prediction: one track, 40 measurements, Doppler alone
  (:func:`fgdoppler.models.doppler._along`);
* a particle move's likelihood: 4,096 tracks x 120 measurements, Doppler alone.

Both must give the same numbers to the bit.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

import fgdoppler as fd
import fgdoppler.models.doppler as doppler
from benchmarks._common import Row

FloatArray = NDArray[np.float64]


class _NumpyKernels:
    """:mod:`fgdoppler.models.doppler_kernels`'s two entry points in numpy's layout."""

    @staticmethod
    def along_and_jacobian(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray
                           ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        d = x.shape[-1] // 2
        vel = x[..., None, d:]
        h, dp, dv, mask = doppler._terms(x[..., None, :d] + t[:, None] * vel, vel, tx, rx, jacobian=True,
                                         singular="mask")
        assert dp is not None and dv is not None
        bad = np.zeros(h.shape, dtype=bool) if mask is None else mask
        return h, np.concatenate([dp, t[:, None] * dp + dv], axis=-1), bad

    @staticmethod
    def along(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray
              ) -> tuple[FloatArray, NDArray[np.bool_]]:
        d = x.shape[-1] // 2
        vel = x[..., None, d:]
        h, _, _, mask = doppler._terms(x[..., None, :d] + t[:, None] * vel, vel, tx, rx, jacobian=False,
                                       singular="mask")
        return h, np.zeros(h.shape, dtype=bool) if mask is None else mask


def _timed(fn: Callable[[], tuple[FloatArray, FloatArray | None]], numpy: bool, calls: int
           ) -> tuple[float, tuple[FloatArray, FloatArray | None]]:
    """CPU seconds per call of ``fn`` with the compiled loops or their numpy stand-in, and its last result."""
    compiled = doppler._kernels
    if numpy:
        doppler._kernels = lambda: _NumpyKernels  # type: ignore[assignment,return-value]
    try:
        start = time.process_time()
        for _ in range(calls):
            out = fn()
        return (time.process_time() - start) / calls, out
    finally:
        doppler._kernels = compiled


def run(repeat: int = 15) -> list[Row]:
    g = fd.paper_geometry("a")
    rng = np.random.default_rng(0)
    rows = []
    for name, n, m, jacobian, target in (
            ("initiation window factor: 1 state x 20 measurements, Doppler and Jacobian", 1, 20, True, 0.5),
            ("restart check prediction: 1 track x 40 measurements, Doppler", 1, 40, False, 0.5),
            ("particle move: 4,096 tracks x 120 measurements, Doppler", 4096, 120, False, 0.3)):
        x = rng.normal(size=(n, 4)) * [5e3, 3e3, 100.0, 100.0] + [25e3, 2e3, 0.0, 0.0]
        t = np.sort(rng.uniform(0.0, 30.0, m))
        c = rng.integers(0, 2, m)
        times = fd.StackedTimes(pair=c, t=t)
        tx, rx = g.tx[c], g.rx[c]

        def call(x: FloatArray = x, t: FloatArray = t, tx: FloatArray = tx, rx: FloatArray = rx,
                 times: fd.StackedTimes = times, jacobian: bool = jacobian) -> tuple[FloatArray, FloatArray | None]:
            if jacobian:
                h, jac, _ = doppler._cv(x, g, times, jacobian=True)
                return h, jac
            return doppler._along(x, t, tx, rx, singular="mask")[0], None

        calls = max(1, 20_000 // (n * m))
        seconds: list[list[float]] = [[], []]
        outs: list[tuple[FloatArray, FloatArray | None]] = []
        for _ in range(repeat):
            outs = []
            for i in range(2):
                s, out = _timed(call, i == 1, calls)
                seconds[i].append(s)
                outs.append(out)
        same = all((a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))
                   for a, b in zip(outs[0], outs[1], strict=True))
        now, before = (float(np.median(s)) for s in seconds)
        ratio = now / before
        rows.append(Row(name=f"{name}: compiled vs numpy", value=f"{now * 1e6:,.1f} us vs {before * 1e6:,.1f} us CPU; "
                        + ("identical" if same else "RESULTS DIFFER"),
                        ratio=ratio, target=f"<= {target:g}x, identical", met=same and ratio <= target))
    return rows


if __name__ == "__main__":
    for r in run():
        print(r)
