"""MkDocs hook: the API reference page is generated from ``engine.__all__``, the one list of
public names (``engine/__init__.py``). No name is written by hand anywhere in docs/.

The page ``api.md`` holds the marker ``<!-- engine-api -->``; this hook replaces it with one
mkdocstrings block (``::: path``) per public name, grouped by the subpackage that defines it,
each group titled by the first line of that subpackage's docstring.
"""

from __future__ import annotations

import importlib
from typing import Any

MARKER = "<!-- engine-api -->"


def _defining_path(engine: Any, name: str) -> str:
    """Dotted path at which mkdocstrings finds ``engine.<name>``."""
    obj = getattr(engine, name)
    module = getattr(obj, "__module__", None)
    qualname = getattr(obj, "__qualname__", None)
    if isinstance(module, str) and module.startswith("engine.") and qualname == name:
        return f"{module}.{name}"
    # a constant (dict, tuple, float, str): the module the API table names for it
    return f"{engine.API[name]}.{name}"


def api_markdown() -> str:
    """The Markdown of the API reference, one ``:::`` block per name of ``engine.__all__``."""
    engine = importlib.import_module("engine")
    groups: dict[str, list[tuple[str, str]]] = {}
    for name in engine.__all__:
        if name.startswith("__"):
            continue  # __version__: a string, stated in the page's text
        path = _defining_path(engine, name)
        sub = ".".join(path.split(".")[:2])
        groups.setdefault(sub, []).append((name, path))
    out: list[str] = []
    for sub in sorted(groups):
        doc = (importlib.import_module(sub).__doc__ or sub).strip().splitlines()[0]
        out.append(f"## `{sub}`: {doc.rstrip('.')}\n")
        for _name, path in sorted(groups[sub], key=lambda t: t[0].lower()):
            out.append(f"::: {path}\n    options:\n      heading_level: 3\n")
    return "\n".join(out)


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    """Replace the marker of the API page by the generated blocks."""
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, api_markdown())
