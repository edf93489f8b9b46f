"""The packages' public names are imported on first use: ``fgdoppler --help`` loads no estimator."""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import subprocess
import sys

import pytest

import fgdoppler
import fgdoppler.estimators
from fgdoppler._lazy import attach
from fgdoppler.estimators.names import ALIASES, DEFAULT_ESTIMATORS, METHODS, SUMMARIES

PACKAGES = (fgdoppler, fgdoppler.estimators)
#: What the estimators load and the command line's parser must not.
HEAVY = ("gtsam", "scipy", "matplotlib", "numba")


def _type_checking_imports(package: object) -> dict[str, tuple[str, ...]]:
    """The modules and names of the package's ``if TYPE_CHECKING:`` imports, read from its source."""
    tree = ast.parse(inspect.getsource(package))  # type: ignore[arg-type]
    block = next(n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "TYPE_CHECKING")
    return {n.module: tuple(a.name for a in n.names) for n in block.body if isinstance(n, ast.ImportFrom)
            if n.module is not None}


def test_every_subcommands_help_is_built_without_loading_an_estimator() -> None:
    code = (
        "import json, sys\n"
        "from fgdoppler.cli.main import build_parser\n"
        "parser = build_parser()\n"
        "parser.format_help()\n"
        "subs = next(a for a in parser._actions if a.dest == 'command')\n"
        "for sub in subs.choices.values():\n"
        "    sub.format_help()\n"
        f"print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_the_lazy_names_are_the_type_checkers_names(package: object) -> None:
    homes = package._HOMES  # type: ignore[attr-defined]
    assert homes == _type_checking_imports(package)
    names = [n for names in homes.values() for n in names]
    assert sorted(set(package.__all__) - {"__version__"}) == sorted(names)  # type: ignore[attr-defined]
    for module, held in homes.items():
        for name in held:
            assert getattr(package, name) is getattr(importlib.import_module(module), name)
    assert set(names) <= set(dir(package))


def test_a_submodule_is_found_as_an_attribute_and_an_unknown_name_is_not() -> None:
    assert fgdoppler.estimators.smoother is importlib.import_module("fgdoppler.estimators.smoother")  # type: ignore[attr-defined]
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        fgdoppler.no_such_name  # type: ignore[attr-defined]  # noqa: B018
    with pytest.raises(AttributeError):
        fgdoppler.__wrapped__  # type: ignore[attr-defined]  # noqa: B018


def test_two_modules_claiming_one_name_are_refused() -> None:
    with pytest.raises(ValueError, match=r"claimed by a\.b and a\.c"):
        attach("a", {"a.b": ("x",), "a.c": ("x", "y")})


def test_the_help_texts_names_are_the_registrys() -> None:
    from fgdoppler.analysis.montecarlo import DEFAULT_ESTIMATORS as study_default
    from fgdoppler.estimators.initiation import METHODS as refinements
    from fgdoppler.estimators.registry import ALIASES as aliases
    from fgdoppler.estimators.registry import ESTIMATORS

    assert list(ESTIMATORS) == list(SUMMARIES)
    assert all(info.summary == SUMMARIES[name] and info.name == name for name, info in ESTIMATORS.items())
    assert refinements is METHODS and aliases is ALIASES and study_default == DEFAULT_ESTIMATORS
    assert DEFAULT_ESTIMATORS == (*METHODS, *ESTIMATORS)
    assert set(ALIASES.values()) <= set(ESTIMATORS)
