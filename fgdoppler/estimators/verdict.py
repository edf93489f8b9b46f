"""How far to trust a result: one status vocabulary for every estimator.

Every result (:class:`~fgdoppler.estimators.initiation.Initiation`,
:class:`~fgdoppler.estimators.results.TrackResult`,
:class:`~fgdoppler.estimators.smoother.SmootherSolution`) carries

``reasons``
    The findings behind its verdict, each a :class:`Reason` with a stable
    ``code``, the status it alone would give and a message.
``status``
    The worst status among the reasons, from :data:`STATUSES`:

    ``"ok"``
        Nothing found that casts doubt on the estimate.
    ``"doubtful"``
        The estimate may be wrong: use it with care and read the reasons.
    ``"failed"``
        The estimate is not usable.
``message``
    The reasons that set the status, in one line (empty when ``ok``).
``events``
    What happened along the way (a rejected measurement, a fallback, a
    restart), each an :class:`Event` with its time.  Events are the log;
    reasons are the judgement.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from fgdoppler.zone import ZoneBox

__all__ = ["MIRRORS", "NOT_CONVERGED", "STATUSES", "Event", "Judged", "Mirror", "Reason", "Status", "message_of",
           "status_of"]

Status = Literal["ok", "doubtful", "failed"]
#: Which line a mirror image is taken across: the one the sensors of the pairs that reported lie on exactly, the
#: one the sensors of the finding's ``pairs`` lie on exactly, or that of every sensor (least squares) — in the
#: order the command line's half-plane hint prefers them.
Mirror = Literal["reporting", "pairs", "sensors"]
MIRRORS: tuple[Mirror, ...] = ("reporting", "pairs", "sensors")
#: The status vocabulary, from best to worst.
STATUSES: tuple[Status, ...] = ("ok", "doubtful", "failed")


@dataclass(frozen=True, kw_only=True)
class Reason:
    """One finding behind a verdict.

    Parameters
    ----------
    code
        Stable short identifier (documented with the estimator that emits it).
    status
        The status this finding alone gives (``"ok"`` for purely
        informational findings).
    message
        What was found, in words, with the numbers.
    zone
        The zone the finding advises trying (a start found outside the
        given one), as the command-line options that give it name it, in
        the given zone's own axes; ``None`` for most findings.  The message
        names it too (:meth:`~fgdoppler.zone.ZoneBox.options`).
    mirror
        Where the finding says the mirror image of the answer across a line
        of sensors fits the data (as well, or nearly): ``"sensors"``, the
        least-squares line of every sensor (a rival track or start that is
        the answer's mirror image); ``"reporting"``, the line the sensors of
        the pairs that reported lie on exactly (any track's image fits);
        ``"pairs"``, the line the sensors of :attr:`pairs` lie on exactly (the
        image fits their measurements exactly, and few others tell the two
        apart).  A half plane on either side of that line settles it.
        ``None`` for most findings.
    pairs
        The pairs (indices) whose sensors' line a ``mirror="pairs"`` finding
        is about; ``None`` for other findings.
    """

    code: str
    status: Status
    message: str
    zone: ZoneBox | None = None
    mirror: Mirror | None = None
    pairs: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")
        if self.mirror is not None and self.mirror not in MIRRORS:
            raise ValueError(f"mirror must be None or one of {MIRRORS}, got {self.mirror!r}")
        if (self.mirror == "pairs") != (self.pairs is not None and len(self.pairs) > 0):
            raise ValueError("mirror='pairs' needs the pairs of its line, and pairs go only with it")

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form (``zone``, ``mirror`` and ``pairs`` only where the finding has them)."""
        out: dict[str, object] = {"code": self.code, "status": self.status, "message": self.message}
        if self.zone is not None:
            out["zone"] = self.zone.to_dict()
        if self.mirror is not None:
            out["mirror"] = self.mirror
        if self.pairs is not None:
            out["pairs"] = list(self.pairs)
        return out


#: The finding of a tracker whose final smoothing hit its iteration cap (its events say more).
NOT_CONVERGED = Reason(code="not-converged", status="doubtful",
                       message="the final smoothing did not converge within its iteration cap")


@dataclass(frozen=True, kw_only=True)
class Event:
    """Something that happened while estimating, at a time (s)."""

    time: float
    message: str

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"time": self.time, "message": self.message}


def status_of(reasons: Iterable[Reason]) -> Status:
    """The worst status among ``reasons`` (``"ok"`` if there are none)."""
    return max((r.status for r in reasons), key=STATUSES.index, default="ok")


def message_of(reasons: Iterable[Reason]) -> str:
    """The messages of the reasons that set the status, joined (empty when the status is ``ok``)."""
    reasons = tuple(reasons)
    status = status_of(reasons)
    if status == "ok":
        return ""
    return "; ".join(r.message for r in reasons if r.status == status)


class Judged:
    """Mixin of every result: ``status`` and ``message`` derived from its ``reasons``."""

    reasons: tuple[Reason, ...]

    @property
    def status(self) -> Status:
        """``"ok"``, ``"doubtful"`` or ``"failed"`` (:mod:`fgdoppler.estimators.verdict`)."""
        return status_of(self.reasons)

    @property
    def message(self) -> str:
        """Why the status is what it is (empty when ``ok``)."""
        return message_of(self.reasons)
