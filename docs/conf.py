"""Sphinx configuration: numpydoc API reference, MyST Markdown pages, executed sphinx-gallery tutorials.

Maths is rendered to MathML at build time (``_ext/mathml.py``), so the site
needs no network and no JavaScript to show it.  Build:
``python -m sphinx -W -b html docs output/site`` (``-W``: warnings are errors).
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

import fgdoppler  # noqa: E402

project = "fgdoppler"
author = "the fgdoppler developers"
copyright = "2026, the fgdoppler developers"
release = fgdoppler.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "mathml",
    "run_blocks",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "examples/README.txt", "tutorials/*.ipynb", "tutorials/*.py", "tutorials/*.md5",
                    "tutorials/*.codeobj.json", "tutorials/*.zip"]
html_math_renderer = "mathml"
html_theme = "furo"
html_title = "fgdoppler"
html_static_path = ["_static"]
html_css_files = ["fgdoppler.css"]

myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3

templates_path = ["_templates"]
autosummary_generate = True
# The stubs are regenerated on every build; a stale one left in a checkout by an object since removed from
# the reference is in no toctree, which a -W build reports as an error.
shutil.rmtree(HERE / "api" / "generated", ignore_errors=True)
autosummary_ignore_module_all = False  # one page per name in each module's __all__


def _write_object_index() -> None:
    """``api/generated/objects.rst``: an orphan page whose autosummary makes the page of every class and function.

    Each module page lists its objects in a table that links to their pages, but the pages hang off this
    page's toctree, outside the site's navigation: furo builds every page's sidebar from the whole
    navigation tree, and with the 313 object pages in it that took two thirds of the build (O(pages²)).
    """
    import importlib
    import inspect
    import re

    names = []
    for page in sorted((HERE / "api").glob("*.rst")):
        for module_name in re.findall(r"^   (fgdoppler[.\w]+)$", page.read_text(encoding="utf-8"), flags=re.M):
            module = importlib.import_module(module_name)
            # routines, not only functions: gtsam's symbol shorthand (factors.X) is a builtin
            names += [f"{module_name}.{name}" for name in module.__all__
                      if inspect.isclass(getattr(module, name)) or inspect.isroutine(getattr(module, name))]
    body = "\n".join(f"   {n}" for n in names)
    (HERE / "api" / "generated").mkdir(exist_ok=True)
    (HERE / "api" / "generated" / "objects.rst").write_text(
        f":orphan:\n\nEvery class and function\n========================\n\n.. autosummary::\n   :toctree: .\n"
        f"   :nosignatures:\n\n{body}\n", encoding="utf-8")


_write_object_index()
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types
autodoc_default_options = {"members": True, "show-inheritance": True}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

sphinx_gallery_conf = {
    "examples_dirs": ["examples"],
    "gallery_dirs": ["tutorials"],
    "filename_pattern": r"/tutorial_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "within_subsection_order": "FileNameSortKey",
}
