"""The package's shape: short functions, ``__init__`` modules that only re-export, text without control
characters."""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "fgdoppler"
MAX_LINES = 80


def _functions(tree: ast.AST) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]


def test_no_function_longer_than_80_lines() -> None:
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for fn in _functions(ast.parse(path.read_text(encoding="utf-8"))):
            n = (fn.end_lineno or fn.lineno) - fn.lineno + 1
            if n > MAX_LINES:
                long.append(f"{path.relative_to(PACKAGE.parent)}:{fn.lineno} {fn.name} ({n} lines)")
    assert not long, long


def test_init_modules_define_no_functions() -> None:
    offenders = [str(p.relative_to(PACKAGE.parent)) for p in sorted(PACKAGE.rglob("__init__.py"))
                 if _functions(ast.parse(p.read_text(encoding="utf-8")))]
    assert not offenders, offenders


CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


def test_no_control_characters_in_the_sources_and_docs() -> None:
    # A docstring's LaTeX in a string that is not raw turns \b (\bar, \bigl) into a backspace, \f (\frac) into a
    # form feed, \v (\vec) into a vertical tab: Sphinx renders them silently as something else.  Tabs and line
    # ends are the only control characters these files hold.
    root = PACKAGE.parent
    files = [*PACKAGE.rglob("*.py"), *(root / "tests").rglob("*.py"), *(root / "docs").rglob("*.md"),
             *(root / "benchmarks").rglob("*.py"), *(root / "studies").rglob("*.py"), root / "README.md"]
    found = []
    for path in sorted(files):
        text = path.read_text(encoding="utf-8")  # searched whole: splitlines() would break at \v and \f
        found += [f"{path.relative_to(root)}:{text.count(chr(10), 0, m.start()) + 1}" for m in CONTROL.finditer(text)]
    assert not found, found
