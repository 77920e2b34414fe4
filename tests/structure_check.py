"""Structure check over ``engine/`` and ``gmwm_app/``: import cycles, private imports, layers.

Run ``python tests/structure_check.py`` from the repository root. It prints one line per finding
and closing ``cycles/private imports: C/P`` and ``layer violations: L`` lines; the public-API
tests assert no finding. The size of a module is not checked: a module splits where its ideas
split, not at a line count.

* **Cycles**: strongly connected components of more than one module in the graph of every
  import statement of the project (top level, inside functions and under ``TYPE_CHECKING``
  alike: a type-only import still couples the two modules). ``from pkg import name`` is an edge
  to ``pkg.name`` when that is a module, else to ``pkg`` (its ``__init__``).
* **Private imports**: ``from module import _name`` where ``module`` is another project module
  and ``_name`` is not a dunder. A helper shared by two modules is public, or lives in a private
  *module* (``_optim.py``) whose names are public. ``gmwm_app`` uses the engine's public API
  only: its import of a private engine module (``engine._checks``, ``engine.wv._kernel``) is
  a finding too.
* **Layers** (:func:`layer_violations`): the packages of ``engine`` run one way, in the order of
  :data:`LAYERS`; an import (anywhere in the module, as for cycles) of a package of the same or
  a higher layer is a finding, and so is a package missing from the table. Only the shared
  private modules (``engine/_*.py``, layer 0) may import each other (the cycle check keeps
  them acyclic).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("engine", "gmwm_app")

#: The layers of the project, lowest first: a package imports only packages of lower layers.
#: ``engine.io`` sits low (loaders need no fit); the API (``engine/__init__.py``) sits above
#: the engine's packages and below the app.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("engine.errors",),  # the error classes (imports nothing of the project)
    ("engine._*",),  # shared private modules: _files, _limits, _parallel, _optim ...
    ("engine.models",),
    ("engine.units",),
    ("engine.wv",),
    ("engine.io", "engine.demo"),
    ("engine.fit",),
    ("engine.inference",),
    ("engine.multivariate", "engine.formats"),
    ("engine.teaching", "engine.batch", "engine.session"),
    ("engine.reporting",),
    ("engine.cli",),
    ("engine",),
    ("gmwm_app",),
)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(path)] = path
    return out


def _resolve(importer: str, is_pkg: bool, level: int, module: str | None) -> str:
    if level == 0:
        return module or ""
    base = importer.split(".")
    if not is_pkg:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def analyse() -> tuple[list[list[str]], list[str]]:
    """Return (cycles, private imports), each as a list of readable findings."""
    _mods, graph, private = _graph()
    return _sccs(graph), private


def package_of(module: str) -> str:
    """The layer unit of a module: ``engine.fit.gmwm`` -> ``engine.fit``, ``engine._files`` ->
    ``engine._*``, ``engine`` -> ``engine``, ``gmwm_app.state`` -> ``gmwm_app``."""
    parts = module.split(".")
    if parts[0] != "engine":
        return parts[0]
    if len(parts) == 1:
        return "engine"
    return "engine._*" if parts[1].startswith("_") else f"engine.{parts[1]}"


def layer_violations(graph: dict[str, set[str]] | None = None) -> list[str]:
    """Imports against :data:`LAYERS` (default: the project's import graph), as findings."""
    if graph is None:
        graph = _graph()[1]
    rank = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer}
    out: list[str] = []
    missing = sorted({package_of(m) for m in graph} - set(rank))
    out += [
        f"{pkg}: not in LAYERS (tests/structure_check.py): give it its layer" for pkg in missing
    ]
    for src in sorted(graph):
        a = package_of(src)
        for dst in sorted(graph[src]):
            b = package_of(dst)
            if a == b or a not in rank or b not in rank:
                continue
            if rank[b] > rank[a] or (rank[b] == rank[a] and a != "engine._*"):
                out.append(
                    f"{src} imports {dst}: {a} (layer {rank[a]}) may not import {b} "
                    f"(layer {rank[b]})"
                )
    return out


def _graph() -> tuple[dict[str, Path], dict[str, set[str]], list[str]]:
    """The modules, the import graph (module -> modules it imports) and the private imports."""
    mods = _modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    private: list[str] = []
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    target = alias.name
                    while target and target not in mods:
                        target = target.rpartition(".")[0]
                    if target and target != name:
                        graph[name].add(target)
            elif isinstance(node, ast.ImportFrom):
                src = _resolve(name, is_pkg, node.level, node.module)
                if src.split(".")[0] not in PACKAGES:
                    continue
                for alias in node.names:
                    sub = f"{src}.{alias.name}"
                    target = sub if sub in mods else src
                    while target and target not in mods:
                        target = target.rpartition(".")[0]
                    if target and target != name:
                        graph[name].add(target)
                    n = alias.name
                    if (
                        n.startswith("_")
                        and not (n.startswith("__") and n.endswith("__"))
                        and sub not in mods
                        and src != name
                    ):
                        private.append(f"{path.relative_to(ROOT)}:{node.lineno}: {src}.{n}")
        if name.startswith("gmwm_app"):  # the app uses the engine's public API only
            private += [
                f"{path.relative_to(ROOT)}: imports the private engine module {t}"
                for t in sorted(graph[name])
                if t.startswith("engine.") and any(p.startswith("_") for p in t.split("."))
            ]
    return mods, graph, private


def _sccs(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of size > 1 (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def main() -> int:
    cycles, private = analyse()
    for c in cycles:
        print("cycle:", " <-> ".join(c))
    for p in private:
        print("private import:", p)
    layers = layer_violations()
    for v in layers:
        print("layer:", v)
    print(f"cycles/private imports: {len(cycles)}/{len(private)}")
    print(f"layer violations: {len(layers)}")
    return 0 if not (cycles or private or layers) else 1


if __name__ == "__main__":
    sys.exit(main())
