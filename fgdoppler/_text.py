"""Short texts for messages and reports: exceptions, times, distances, pairs."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import SupportsFloat

import numpy as np

__all__ = ["distance_text", "first_line", "pairs_text", "plain_number", "time_text"]


def first_line(exc: BaseException) -> str:
    """The first non-empty line of an exception's message, or its type name if the message is empty.

    GTSAM's errors carry multi-line explanations; reports keep one line.
    """
    for line in str(exc).splitlines():
        if line.strip():
            return line.strip()
    return type(exc).__name__


def plain_number(v: float, decimals: int) -> str:
    """``v`` positional, never in exponent notation, with the shortest decimals that give it back (at most
    ``decimals``; rounded there) and no trailing zeros: ``plain_number(4512345.25, 3)`` is ``"4512345.25"``.

    ``f"{v:g}"`` keeps six significant digits, so a time in Unix seconds
    (``1700000012.25``) reads ``1.7e+09`` and a UTM northing ``4.51235e+06``.
    """
    return np.format_float_positional(float(v), precision=decimals, unique=True, trim="-")


def time_text(t: float) -> str:
    """A time in seconds as a message shows it: :func:`plain_number` to the microsecond.

    Examples
    --------
    >>> time_text(30.0), time_text(12.25), time_text(1700000012.25)
    ('30', '12.25', '1700000012.25')
    """
    return plain_number(t, 6)


def distance_text(metres: SupportsFloat, km_decimals: int = 1) -> str:
    """A distance or coordinate in metres as a message shows it: in kilometres (``km_decimals`` decimals) from
    1 km, in whole metres from 10 m, else to two significant digits.

    Messages once divided every distance by 1000 and printed ``0.0 km`` for
    the tens of metres of a small layout (or of sensor positions given in
    kilometres where metres are read).

    Examples
    --------
    >>> distance_text(23012.0), distance_text(-5000.0), distance_text(437.4), distance_text(4.24), distance_text(0.0)
    ('23.0 km', '-5.0 km', '437 m', '4.2 m', '0 m')
    >>> distance_text(10630.0, km_decimals=2)
    '10.63 km'
    """
    v = float(metres)
    if abs(v) >= 1e3:
        return f"{v / 1e3:.{km_decimals}f} km"
    if abs(v) >= 10.0 or v == 0.0:
        return f"{v:.0f} m"
    return f"{v:.2g} m"


def pairs_text(which: Sequence[int], label: Callable[[int], str] = str, *, every: bool = False) -> str:
    """``"every pair"`` (``every``: ``which`` is every pair that reported), ``"pair 1"`` or ``"pairs 0, 2 and 3"``,
    each pair as ``label`` gives it (:meth:`~fgdoppler.geometry.Geometry.pair_label`: ``"pair 1 (south)"`` where
    the geometry names its pairs, as the measurement file may).

    Examples
    --------
    >>> pairs_text([1]), pairs_text([0, 2, 3]), pairs_text([0, 1], every=True)
    ('pair 1', 'pairs 0, 2 and 3', 'every pair')
    """
    if every:
        return "every pair"
    if len(which) == 1:
        return f"pair {label(which[0])}"
    return f"pairs {', '.join(map(label, which[:-1]))} and {label(which[-1])}"
