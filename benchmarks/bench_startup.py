"""Start-up: ``fgdoppler --help`` against loading the estimators, each in a fresh interpreter.

The package's public names are imported on first use (:mod:`fgdoppler._lazy`), so the command line's help
and argument errors need no estimator, GTSAM or SciPy.  Timed alternately in one run, ``python -m fgdoppler
--help`` against ``python -c "import fgdoppler.estimators.registry"`` (what every ``track`` loads before its
first measurement), both beside a bare ``python -c pass``; the ratio of the two above the bare interpreter's
time holds on a shared machine.  Run alone: ``python -m benchmarks --only startup``.
"""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np

from benchmarks._common import Row

#: ``--help``'s time above a bare interpreter's, at most this share of the estimators' load above it.
LIMIT = 0.5
COMMANDS = {
    "help": [sys.executable, "-m", "fgdoppler", "--help"],
    "estimators": [sys.executable, "-c", "import fgdoppler.estimators.registry"],
    "bare": [sys.executable, "-c", "pass"],
}


def _alternate(repeat: int = 7) -> dict[str, float]:
    """Median wall time of each command, the commands run in turn ``repeat`` times."""
    times: dict[str, list[float]] = {k: [] for k in COMMANDS}
    for _ in range(repeat):
        for name, command in COMMANDS.items():
            t = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
            times[name].append(time.perf_counter() - t)
    return {k: float(np.median(v)) for k, v in times.items()}


def run() -> list[Row]:
    subprocess.run(COMMANDS["estimators"], check=True)  # a first load compiles and caches the bytecode
    t = _alternate()
    ratio = (t["help"] - t["bare"]) / (t["estimators"] - t["bare"])
    return [Row(name="fgdoppler --help (fresh interpreter)",
                value=f"{t['help']:.2f} s (loading the estimators: {t['estimators']:.2f} s; bare Python: "
                      f"{t['bare']:.2f} s)",
                ratio=ratio, target=f"<= {LIMIT:g}x the estimators' load, each above bare Python",
                met=ratio <= LIMIT)]


if __name__ == "__main__":
    for r in run():
        print(r)
