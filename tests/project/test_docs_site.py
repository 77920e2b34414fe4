"""The documentation site: MkDocs builds it with no warning, and its API reference is generated
from ``engine.__all__``, the one list of public names (no hand-written table of API names).

The build needs the ``docs`` extra (``pip install -e ".[docs]"``); without it the build test is
skipped with that reason. ``.ci/run`` installs the extra and builds the site before the tests.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

import engine

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def _hook():
    path = DOCS / "_hooks" / "api_reference.py"
    spec = importlib.util.spec_from_file_location("api_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _nav_pages() -> list[str]:
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text.split("\nnav:\n", 1)[1]
    return re.findall(r":\s*([\w./-]+\.md)\s*$", nav, re.M)


def test_api_reference_is_generated_from_engine_all() -> None:
    """Every public name (engine.__all__ but __version__, and the subpackages' names of
    engine.MOVED) gets one mkdocstrings block, and nothing else does; the page itself names no
    API name by hand."""
    blocks = re.findall(r"^::: (engine\.[\w.]+)$", _hook().api_markdown(), re.M)
    names = [b.rsplit(".", 1)[1] for b in blocks]
    public = [n for n in engine.__all__ if not n.startswith("__")] + list(engine.MOVED)
    assert sorted(names) == sorted(public)
    assert len(set(blocks)) == len(blocks)
    page = (DOCS / "api.md").read_text(encoding="utf-8")
    assert "<!-- engine-api -->" in page
    assert not re.search(r"^::: ", page, re.M)  # no hand-written block
    # no hand-written table of API names anywhere in the docs or the front page
    for md in [ROOT / "README.md", *DOCS.glob("*.md")]:
        rows = re.findall(r"^\| `([A-Za-z_]\w*)` \|", md.read_text(encoding="utf-8"), re.M)
        listed = set(rows) & (set(engine.__all__) | set(engine.MOVED))
        assert len(listed) < 10, (md.name, sorted(listed))


def test_every_nav_entry_exists_and_the_guides_are_there() -> None:
    pages = _nav_pages()
    assert pages and all((DOCS / p).is_file() for p in pages), pages
    assert len(set(pages)) == len(pages)
    for required in ("getting-started.md", "api.md", "conventions.md", "class-server.md"):
        assert required in pages


@pytest.mark.slow
def test_site_builds_strict_with_no_warning(tmp_path: Path) -> None:
    """``mkdocs build --strict`` (every warning an error: broken links, missing pages, bad
    docstring references) passes, and the built API page has an anchor per public name."""
    if not all(importlib.util.find_spec(m) for m in ("mkdocs", "mkdocstrings_handlers.python")):
        pytest.skip('mkdocs/mkdocstrings not installed: pip install -e ".[docs]"')
    site = tmp_path / "site"
    p = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert p.returncode == 0, p.stderr[-3000:]
    assert "WARNING" not in p.stderr, p.stderr[-3000:]
    html = (site / "api" / "index.html").read_text(encoding="utf-8")
    ids = set(re.findall(r'id="(engine\.[\w.]+)"', html))
    for name in engine.__all__:
        if not name.startswith("__"):
            assert any(i.endswith("." + name) for i in ids), name


def test_front_page_links_resolve() -> None:
    """README is the front page on GitHub and PyPI, outside the site's link check: every
    relative link and image it has must name a file or folder of the repository."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", readme)
    local = [t for t in targets if not re.match(r"[a-z]+://", t)]
    assert len(local) >= 10, local  # the links into docs/
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, missing
