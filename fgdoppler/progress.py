"""Progress reporting for long runs: a two-method protocol and a tqdm implementation.

Every estimator (and :func:`~fgdoppler.estimators.registry.run_estimator`)
takes an optional ``progress`` object.  It is told when a task starts — its
name and, where known, how many steps it has (scans of an online tracker;
``None`` for Levenberg–Marquardt iterations, whose number is not known in
advance) — and advanced as steps complete.  Estimators never print;
:class:`TqdmProgress` draws the bars (the command line uses it on a
terminal), and any object with the two methods will do::

    with TqdmProgress() as bar:
        result = run_estimator("isam2", meas, geometry, init, progress=bar)
"""

from __future__ import annotations

import sys
from types import TracebackType
from typing import IO, Any, Protocol

__all__ = ["Prefixed", "Progress", "TqdmProgress", "advance", "prefixed", "start_task"]


class Progress(Protocol):
    """What an estimator reports progress to."""

    def task(self, name: str, total: int | None) -> None:
        """A new task begins (``total`` steps, or ``None`` when not known)."""

    def advance(self, n: int = 1) -> None:
        """``n`` more steps of the current task are done."""


def start_task(progress: Progress | None, name: str, total: int | None) -> None:
    """``progress.task(name, total)`` unless ``progress`` is ``None``."""
    if progress is not None:
        progress.task(name, total)


def advance(progress: Progress | None, n: int = 1) -> None:
    """``progress.advance(n)`` unless ``progress`` is ``None``."""
    if progress is not None:
        progress.advance(n)


class Prefixed:
    """A :class:`Progress` that names its tasks ``"<prefix>: <name>"`` (a hypothesis, a reference run)."""

    def __init__(self, inner: Progress, prefix: str) -> None:
        self.inner = inner
        self.prefix = prefix

    def task(self, name: str, total: int | None) -> None:
        self.inner.task(f"{self.prefix}: {name}", total)

    def advance(self, n: int = 1) -> None:
        self.inner.advance(n)


def prefixed(progress: Progress | None, prefix: str) -> Progress | None:
    """``progress`` with ``prefix`` on its task names (``None`` stays ``None``)."""
    return None if progress is None else Prefixed(progress, prefix)


class TqdmProgress:
    """One tqdm bar per task, on stderr, drawn only on a terminal.

    Parameters
    ----------
    file
        Where to draw (default: ``sys.stderr``).
    disable
        ``True`` hides the bars; ``None`` (default) hides them when ``file``
        is not a terminal, so logs and pipes get no control characters.
    """

    def __init__(self, file: IO[str] | None = None, disable: bool | None = None) -> None:
        self.file = file if file is not None else sys.stderr
        isatty = getattr(self.file, "isatty", None)
        self.disable = disable if disable is not None else not (callable(isatty) and isatty())
        self._bar: Any = None

    def task(self, name: str, total: int | None) -> None:
        from tqdm import tqdm

        self.close()
        unit = "step" if total is not None else "it"
        self._bar = tqdm(total=total, desc=name, unit=unit, file=self.file, disable=self.disable, leave=False,
                         mininterval=0.2)

    def advance(self, n: int = 1) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def close(self) -> None:
        """Remove the current bar."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> TqdmProgress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
