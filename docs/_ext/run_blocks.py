"""Run the Python blocks of the narrative pages at build time and show what they print.

A page's ```python blocks run in order in one namespace (as a reader would run them) in a
temporary working folder; each block's standard output is inserted below it as an output
block.  A block that raises fails the build, so a page can never show code that does not run
or an output the code does not produce.
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
from typing import Any

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.errors import ExtensionError


def _run_page(app: Sphinx, doctree: nodes.document) -> None:
    blocks = [n for n in doctree.findall(nodes.literal_block) if n.get("language") == "python"]
    if not blocks:
        return
    docname = app.env.docname
    namespace: dict[str, Any] = {"__name__": f"docs.{docname}"}
    with tempfile.TemporaryDirectory() as tmp, contextlib.chdir(tmp):
        for number, node in enumerate(blocks, start=1):
            buffer = io.StringIO()
            try:
                with contextlib.redirect_stdout(buffer):
                    exec(compile(node.astext(), f"<{docname} block {number}>", "exec"), namespace)
            except Exception as exc:
                raise ExtensionError(f"{docname}: Python block {number} failed: {exc!r}") from exc
            text = buffer.getvalue().rstrip("\n")
            if text:
                out = nodes.literal_block(text, text, classes=["block-output"])
                out["language"] = "text"
                node.parent.insert(node.parent.index(node) + 1, out)


def setup(app: Sphinx) -> dict[str, Any]:
    """Register the doctree hook."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    app.connect("doctree-read", _run_page)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
