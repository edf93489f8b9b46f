"""Short texts from exceptions for messages and reports."""

from __future__ import annotations

__all__ = ["first_line"]


def first_line(exc: BaseException) -> str:
    """The first non-empty line of an exception's message, or its type name if the message is empty.

    GTSAM's errors carry multi-line explanations; reports keep one line.
    """
    for line in str(exc).splitlines():
        if line.strip():
            return line.strip()
    return type(exc).__name__
