"""MkDocs hook: the API reference page is generated from ``engine.__all__`` (the top level) and
``engine.MOVED`` (the names of the subpackages a user reaches as ``eg.<subpackage>.<name>``),
declared once in ``engine/__init__.py``. No name is written by hand anywhere in docs/.

The page ``api.md`` holds the marker ``<!-- engine-api -->``; this hook replaces it with one
mkdocstrings block (``::: path``) per public name, grouped by the subpackage that defines it,
each group introduced by the first paragraph of that subpackage's docstring.
"""

from __future__ import annotations

import importlib
import re
import sys
from typing import Any

MARKER = "<!-- engine-api -->"
#: Sphinx cross-reference roles (``:func:`x```) in the docstrings: mkdocstrings renders the
#: role's name as text before the code, so the page drops it (and a leading ``~``).
ROLE = re.compile(r":(?:func|class|meth|attr|data|mod|obj|exc):(<code>)~?")
#: The same role inside a type annotation, rendered verbatim: ``:func:`x``` -> ``x``.
ROLE_TEXT = re.compile(r":(?:func|class|meth|attr|data|mod|obj|exc):`~?([^`]+)`")


def _summary(module: str) -> str:
    """The first paragraph of a subpackage's docstring, on one line, without roles."""
    doc = (importlib.import_module(module).__doc__ or module).strip()
    para = " ".join(doc.split("\n\n", 1)[0].split())
    return ROLE_TEXT.sub(r"`\1`", para)


def _defining_path(engine: Any, name: str, home: str = "") -> str:
    """Dotted path at which mkdocstrings finds ``engine.<name>`` (``engine.<home>.<name>``)."""
    obj = getattr(importlib.import_module(f"engine.{home}") if home else engine, name)
    module = getattr(obj, "__module__", None)
    qualname = getattr(obj, "__qualname__", None)
    if isinstance(module, str) and module.startswith("engine.") and qualname == name:
        return f"{module}.{name}"
    # a constant (dict, tuple, float, str): the module that engine's table of names gives, else
    # the shortest engine module that holds this very object
    known = getattr(engine, "API", {}).get(name) or (f"engine.{home}" if home else None)
    if known is None:
        holders = [
            m
            for m, mod in list(sys.modules.items())
            if m.startswith("engine.") and getattr(mod, name, None) is obj
        ]
        known = min(holders, key=lambda m: (m.count("."), m))
    return f"{known}.{name}"


def _groups(engine: Any, names: dict[str, str]) -> list[str]:
    """One section per subpackage: its summary, then one ``:::`` block per name."""
    groups: dict[str, list[tuple[str, str]]] = {}
    for name, home in names.items():
        if name.startswith("__"):
            continue  # __version__: a string, stated in the page's text
        path = _defining_path(engine, name, home)
        sub = f"engine.{home}" if home else ".".join(path.split(".")[:2])
        groups.setdefault(sub, []).append((name, path))
    out: list[str] = []
    for sub in sorted(groups):
        out.append(f"### `{sub}`\n\n{_summary(sub)}\n")
        for _name, path in sorted(groups[sub], key=lambda t: t[0].lower()):
            out.append(f"::: {path}\n    options:\n      heading_level: 4\n")
    return out


def api_markdown() -> str:
    """The Markdown of the API reference: the top level (``engine.__all__``), then the names
    of the subpackages that ``engine.MOVED`` lists (the old top level), each where it lives."""
    engine = importlib.import_module("engine")
    out = ["## The top level: `import engine as eg`\n"]
    out += _groups(engine, dict.fromkeys(engine.__all__, ""))
    out.append("## In the subpackages: `eg.fit`, `eg.wv`, `eg.formats` ...\n")
    out += _groups(engine, dict(engine.MOVED))
    return "\n".join(out)


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    """Replace the marker of the API page by the generated blocks."""
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, api_markdown())


def on_page_content(html: str, page: Any, **kwargs: Any) -> str:
    """Drop the Sphinx role names that the docstrings show as text (the API page, and a guide
    that renders one docstring, e.g. fit-to-filter.md's ExportOptions)."""
    if page.file.src_uri != "api.md" and 'class="doc doc-' not in html:
        return html
    return ROLE_TEXT.sub(r"\1", ROLE.sub(r"\1", html))
