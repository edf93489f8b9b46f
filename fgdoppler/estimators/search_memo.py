r"""What the offline smoother's whole-recording searches found, kept for the other hypotheses of one call.

With an ambiguous initiation the smoother runs once per hypothesis and
keeps the lowest cost (:mod:`fgdoppler.estimators.ambiguity`, resolution
``"cost"``).  Each run searches the whole recording — the re-initiation
after a failed χ² check, the 2-D mode search, the search beyond a zone wall
(:mod:`fgdoppler.estimators.smoother`) — and smooths from what it found.
Those searches depend on the recording, the model, the zone searched, the
smoother's settings and the half plane, never on the hypothesis: every
hypothesis's run would repeat the same grid, the same refinements and the
same Levenberg–Marquardt runs from the same starts, to the same numbers.
A :class:`SearchMemo` makes each happen once per call; the runs' results
are the same to the bit as without it.  :class:`RecordingMemo` is what it
shares with the restart checks' memo
(:class:`~fgdoppler.estimators.restart.FreshFits`): one recording, results
by key, each computed once.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, TypeVar

import numpy as np
from numpy.typing import NDArray

from fgdoppler.measurements import Measurements

if TYPE_CHECKING:
    from fgdoppler.estimators.smoother_solve import SmootherSolution

__all__ = ["RecordingMemo", "SearchMemo"]

FloatArray = NDArray[np.float64]
_T = TypeVar("_T")


class RecordingMemo:
    """Results computed once for the runs of one recording, each under a key naming what it depends on.

    Parameters
    ----------
    measurements
        The recording the runs share; a look-up for another is refused.
    """

    def __init__(self, measurements: Measurements) -> None:
        self._measurements = measurements

    def _once(self, store: dict[Hashable, _T], measurements: Measurements, key: Hashable,
              compute: Callable[[], _T]) -> _T:
        """``store[key]``, from ``compute()`` the first time.

        Raises
        ------
        ValueError
            If ``measurements`` is not the recording the memo was made for.
        """
        if measurements is not self._measurements:
            raise ValueError(f"a {type(self).__name__} serves the runs of one recording: it was made for another")
        if key not in store:
            store[key] = compute()
        return store[key]


class SearchMemo(RecordingMemo):
    """Start trajectories of the whole-recording searches and the smoother's solutions from them, for one call.

    One memo serves the smoother runs of one recording and one model (the
    hypotheses of one ``run_estimator`` call, which creates it): the keys
    name what may differ between those runs — which search (measurements
    per pair, candidates, half plane, zone searched) and, for a solution,
    its start trajectory and settings — and nothing else.

    Parameters
    ----------
    measurements
        The recording the runs share; a run on another is refused.
    """

    def __init__(self, measurements: Measurements) -> None:
        super().__init__(measurements)
        self._starts: dict[Hashable, list[FloatArray]] = {}
        self._solutions: dict[Hashable, SmootherSolution | None] = {}

    def starts(self, measurements: Measurements, key: Hashable,
               search: Callable[[], list[FloatArray]]) -> list[FloatArray]:
        """The start trajectories of the search named ``key``: ``search()`` the first time, then the same list.

        Raises
        ------
        ValueError
            If ``measurements`` is not the recording the memo was made for.
        """
        return self._once(self._starts, measurements, key, search)

    def solution(self, measurements: Measurements, key: Hashable,
                 solve: Callable[[], SmootherSolution | None]) -> SmootherSolution | None:
        """The smoother's solution from the start named ``key`` (``None``: it cannot start from there)."""
        return self._once(self._solutions, measurements, key, solve)
