"""Shared helpers: timing, scenarios, result rows."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import fgdoppler as fd


@dataclass(frozen=True, kw_only=True)
class Row:
    """One benchmark line: what, the measurement, the ratio and the target it is judged by."""

    name: str
    value: str
    ratio: float | None = None
    target: str = ""
    met: bool | None = None


def median_time(fn: Callable[[], object], repeat: int = 7, number: int = 1) -> float:
    """Median over ``repeat`` of the mean time of ``number`` calls (seconds)."""
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        out.append((time.perf_counter() - t) / number)
    return float(np.median(out))


def long_scenario(n_scans: int) -> fd.Scenario:
    """A well-observed recording of ``n_scans`` scans (dt = 0.05 s, target crossing the baseline)."""
    return fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0),
                       duration=(n_scans - 1) * 0.05, dt=0.05)
