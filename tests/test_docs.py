"""Every Python example in the README and docs/ runs (and every CLI subcommand is documented)."""

from __future__ import annotations

import os
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


UNRENDERED = re.compile(r":(?:math|class|func|meth|mod|attr|data|obj|doc|ref):`|\.\. (?:math|note|warning)::")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The documentation built by Sphinx with warnings as errors (tutorials executed)."""
    import subprocess
    import sys

    for mod in ("sphinx", "numpydoc", "sphinx_gallery", "furo", "myst_parser", "latex2mathml", "stonesoup"):
        pytest.importorskip(mod)
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(out / ".doctrees"), str(ROOT / "docs"), str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=900, env={**os.environ, "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr[-5000:]
    return out


def test_docs_build_strict(site: Path) -> None:
    """The site builds with no warning, with the API reference and every tutorial."""
    assert (site / "api" / "estimators.html").exists()
    tutorials = sorted(p.name for p in (site / "tutorials").glob("tutorial_*.html"))
    assert len(tutorials) == len(list((ROOT / "docs" / "examples").glob("tutorial_*.py"))), tutorials


def test_built_pages_have_no_unrendered_markup_and_typeset_maths(site: Path) -> None:
    """No raw reST role or directive on any page; maths is MathML (renders offline, no script)."""
    bad = {}
    for page in site.rglob("*.html"):
        if "_sources" in page.parts or "_downloads" in page.parts:
            continue
        hits = UNRENDERED.findall(page.read_text(encoding="utf-8"))
        if hits:
            bad[str(page.relative_to(site))] = sorted(set(hits))
    assert not bad, bad
    particle = (site / "api" / "generated" / "fgdoppler.estimators.particle.html")
    particle = particle.read_text(encoding="utf-8")
    assert "<math" in particle and "mathjax" not in particle.lower()


def test_tutorials_show_their_output_and_figures(site: Path) -> None:
    """Every tutorial page carries the printed output and at least one figure of its own run."""
    for page in (site / "tutorials").glob("tutorial_*.html"):
        text = page.read_text(encoding="utf-8")
        assert "sphx-glr-script-out" in text, page.name
        assert "sphx_glr_" in text and ".png" in text, page.name


def test_narrative_pages_show_what_their_code_prints(site: Path) -> None:
    """Each docs page with Python blocks shows their printed output, produced by the build's own run."""
    for page in sorted((ROOT / "docs").glob("*.md")):
        prints = [b for b in BLOCK.findall(page.read_text(encoding="utf-8")) if "print(" in b]
        if prints:
            html = (site / page.with_suffix(".html").name).read_text(encoding="utf-8")
            assert html.count('class="block-output') == len(prints), page.name


def test_settings_pages_show_every_true_default(site: Path) -> None:
    """Each settings dataclass's fields appear on its API page with their real defaults.

    (The old MkDocs reference copied one grouped parameter's default onto the
    next: ``Scenario.dt`` was shown as 30.0, ``GridSpec.speed_step`` as 200.0.)
    """
    import dataclasses

    import fgdoppler as fd
    from fgdoppler.analysis.montecarlo import MonteCarloSpec
    from fgdoppler.estimators.grid import GridSpec

    classes = (fd.Scenario, fd.InitiationSettings, GridSpec, fd.EKFSettings, fd.ISAM2Settings,
               fd.FixedLagSettings, fd.SmootherSettings, fd.ParticleSettings, fd.MapSettings,
               MonteCarloSpec)
    missing = []
    for cls in classes:
        page = site / "api" / "generated" / f"{cls.__module__}.{cls.__name__}.html"
        text = re.sub(r"<[^>]+>", "", page.read_text(encoding="utf-8"))
        text = text.replace("&#39;", "'").replace("&quot;", '"')
        for f in dataclasses.fields(cls):
            if f.default is dataclasses.MISSING or not f.init:
                continue
            if f"{f.name}={f.default!r}" not in text:
                missing.append(f"{cls.__name__}.{f.name}={f.default!r}")
    assert not missing, missing


def test_api_reference_has_one_page_per_object(site: Path) -> None:
    """Every class and function a documented module exports has a page of its own, linked from its module."""
    import importlib
    import inspect

    modules = []
    for page in (ROOT / "docs" / "api").glob("*.rst"):
        modules += re.findall(r"^   (fgdoppler[.\w]+)$", page.read_text(encoding="utf-8"), flags=re.M)
    assert len(modules) >= 40, modules
    missing = []
    for name in modules:
        module = importlib.import_module(name)
        listing = (site / "api" / "generated" / f"{name}.html").read_text(encoding="utf-8")
        for obj in module.__all__:
            value = getattr(module, obj)
            if not (inspect.isclass(value) or inspect.isroutine(value)):
                continue
            target = f"{name}.{obj}.html"
            if not (site / "api" / "generated" / target).exists() or f'href="{target}' not in listing:
                missing.append(target)
    assert not missing, missing
