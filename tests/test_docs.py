"""Every Python example in the README and docs/ runs (and every CLI subcommand is documented)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fgdoppler.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)


def _pages_with_examples() -> list[tuple[str, list[str]]]:
    out = []
    for page in PAGES:
        blocks = BLOCK.findall(page.read_text(encoding="utf-8"))
        if blocks:
            out.append((str(page.relative_to(ROOT)), blocks))
    return out


@pytest.mark.parametrize(("where", "blocks"), _pages_with_examples(), ids=[w for w, _ in _pages_with_examples()])
def test_python_examples_run(where: str, blocks: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A page's blocks run in order in one namespace, as a reader runs a tutorial."""
    if "stonesoup" in where:
        pytest.importorskip("stonesoup", reason="extra 'stonesoup' not installed")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for i, code in enumerate(blocks):
        exec(compile(code, f"{where}#{i}", "exec"), namespace)


def test_every_subcommand_is_documented() -> None:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    text = (ROOT / "docs" / "cli.md").read_text()
    for name in sub.choices:  # type: ignore[union-attr]
        assert f"fgdoppler {name}" in text, name


def test_every_long_option_is_documented() -> None:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    text = (ROOT / "docs" / "cli.md").read_text()
    missing = [
        f"{name} {opt}"
        for name, parser in sub.choices.items()  # type: ignore[union-attr]
        for action in parser._actions
        for opt in action.option_strings
        if opt.startswith("--") and opt != "--help" and not re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", text)
    ]
    assert not missing, missing


def test_docs_build_strict(tmp_path: Path) -> None:
    """The MkDocs site (with the API reference from docstrings) builds with no warning."""
    import subprocess
    import sys

    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (tmp_path / "site" / "api" / "estimators" / "index.html").exists()
