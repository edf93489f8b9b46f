"""Sphinx extension: render every math node to MathML at build time (no JavaScript, no network).

Browsers render MathML Core natively (Chromium 109+, Firefox, Safari), so the
built site shows typeset maths when opened offline.  The LaTeX → MathML
conversion is ``latex2mathml``'s; a formula it cannot convert is kept as
LaTeX source in a ``<code>`` element and reported as a build warning (the
strict build then fails).
"""

from __future__ import annotations

import html
import re
from typing import Any

from docutils import nodes
from latex2mathml.converter import convert
from sphinx.application import Sphinx
from sphinx.util import logging

logger = logging.getLogger(__name__)


_BOLD = re.compile(r'<mi mathvariant="bold">([A-Za-z])</mi>')


def _bold_letter(m: re.Match[str]) -> str:
    # MathML Core (Chromium) renders only mathvariant="normal"; bold vectors become the Unicode
    # mathematical bold letters (U+1D400 A, U+1D41A a), upright like \mathbf.
    c = m.group(1)
    code = 0x1D400 + (ord(c) - ord("A") if c.isupper() else 26 + ord(c) - ord("a"))
    return f'<mi mathvariant="normal">&#x{code:X};</mi>'


def _mathml(latex: str, node: nodes.Element, *, block: bool) -> str:
    try:
        return _BOLD.sub(_bold_letter, convert(latex, display="block" if block else "inline"))
    except Exception as exc:  # latex2mathml raises several exception types on unsupported input
        logger.warning("cannot render maths %r: %s", latex, exc, location=node)
        return f"<code>{html.escape(latex)}</code>"


def visit_math(self: Any, node: nodes.Element) -> None:
    self.body.append(f'<span class="math">{_mathml(node.astext(), node, block=False)}</span>')
    raise nodes.SkipNode


def visit_displaymath(self: Any, node: nodes.Element) -> None:
    latex = node.astext()
    if not node.get("nowrap"):
        parts = [p for p in latex.split("\n\n") if p.strip()]
    else:
        parts = [latex]
    self.body.append(self.starttag(node, "div", CLASS="math"))
    if node.get("number"):
        self.body.append(f'<span class="eqno">({node["number"]})</span>')
    for part in parts:
        self.body.append(_mathml(part, node, block=True))
    self.body.append("</div>\n")
    raise nodes.SkipNode


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_html_math_renderer("mathml", (visit_math, None), (visit_displaymath, None))
    return {"parallel_read_safe": True, "parallel_write_safe": True}
