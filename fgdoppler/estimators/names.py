"""The trackers' and initiation methods' names and one-line summaries, apart from their code.

What the command line's choices and help texts need, importable without
loading an estimator (GTSAM, SciPy): ``fgdoppler --help`` reads this module,
and :data:`fgdoppler.estimators.registry.ESTIMATORS` takes its entries' names
and summaries from :data:`SUMMARIES`, in the same order.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Literal, get_args

__all__ = ["ALIASES", "DEFAULT_ESTIMATORS", "METHODS", "SUMMARIES", "Method"]

Method = Literal["grid", "ils", "lm"]
#: The initiation's refinement methods, also the initiation-only "estimators" of Monte Carlo studies.
METHODS: tuple[Method, ...] = get_args(Method)

#: Every registered tracker's name and its line for help texts, in the registry's order.
SUMMARIES: Mapping[str, str] = MappingProxyType({
    "ekf": "extended Kalman filter (the paper's dynamic estimator)",
    "isam2": "iSAM2: the factor graph updated scan by scan",
    "fixed-lag": "fixed-lag smoother: each state estimated lag seconds after its time",
    "smoother": "offline smoother: the whole recording by Levenberg-Marquardt",
    "particle": "particle filter: the posterior by sequential Monte Carlo (resample-move)",
    "map": "filtered MAP: the particle posterior's mode given all data so far (its mean where skewed)",
})

#: Old names still accepted (the documentation used them), with a DeprecationWarning.
ALIASES: Mapping[str, str] = MappingProxyType({"batch": "smoother"})

#: What a Monte Carlo study runs unless told otherwise: every initiation method, then every tracker.
DEFAULT_ESTIMATORS: tuple[str, ...] = (*METHODS, *SUMMARIES)
