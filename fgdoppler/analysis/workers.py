"""What every worker task of a parallel study shares: one BLAS thread.

numpy's OpenBLAS starts a thread per core in every process.  Every matrix
here is tiny (4×4 to a few dozen rows), so those threads never help, and
with one worker process per core they contend: two Monte Carlo workers ran
*slower* than one (19.6 s vs 14.0 s for 36 scenario-runs), and the accuracy
benchmark took 27 min on two cores instead of 11.  The limit is set per
task, so that any executor (process pool, Dask) gets it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

__all__ = ["one_blas_thread"]

P = ParamSpec("P")
R = TypeVar("R")


def one_blas_thread(task: Callable[P, R]) -> Callable[P, R]:
    """``task`` run with BLAS limited to one thread (``threadpoolctl``), restored afterwards.

    The wrapper keeps ``task``'s name, so a module-level task stays picklable
    for a process pool.
    """

    @functools.wraps(task)
    def limited(*args: P.args, **kwargs: P.kwargs) -> R:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):
            return task(*args, **kwargs)

    return limited
