"""Short texts for messages and reports: exceptions, times."""

from __future__ import annotations

import numpy as np

__all__ = ["first_line", "plain_number", "time_text"]


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
