"""Public names of a package, imported from their modules on first use (PEP 562).

``import fgdoppler`` would otherwise load GTSAM, SciPy's statistics and every
estimator before ``fgdoppler --help`` prints a line: about 0.7 s on a warm
2-core machine, most of it ``scipy.stats``.  A package lists where each of its
public names lives and hands :func:`attach`'s pair to the module as its
``__getattr__`` and ``__dir__``; type checkers read the same names from the
package's ``if TYPE_CHECKING:`` imports, which ``tests/test_lazy_imports.py``
holds equal to the list.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from importlib import import_module
from typing import Any


def attach(package: str, homes: Mapping[str, Sequence[str]]
           ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A module ``__getattr__`` and ``__dir__`` for ``package`` whose public names live in other modules.

    Parameters
    ----------
    package
        The package's ``__name__``, for the error a missing name raises.
    homes
        Each module (absolute name) and the public names it holds.

    Returns
    -------
    tuple
        ``__getattr__(name)``, which imports the module that holds ``name`` and returns the name's value, or
        else the submodule ``name`` (``AttributeError`` where there is neither), and ``__dir__()``, the
        package's names.

    Raises
    ------
    ValueError
        Where two modules claim the same name.
    """
    where: dict[str, str] = {}
    for module, names in homes.items():
        for name in names:
            if where.setdefault(name, module) != module:
                raise ValueError(f"{package}.{name} is claimed by {where[name]} and {module}")

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is not None:
            return getattr(import_module(module), name)
        if name.startswith("__"):  # what tools probe for (__wrapped__, __test__, ...) is never a submodule
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        # a submodule, as `import fgdoppler as fd; fd.estimators.smoother` found it when the package imported all
        try:
            return import_module(f"{package}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{package}.{name}":  # the submodule exists but needs what is not installed
                raise
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted({*vars(import_module(package)), *where})

    return __getattr__, __dir__
