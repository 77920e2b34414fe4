"""Structure check over ``engine/`` and ``gmwm_app/``: import cycles, private imports, big modules.

Run ``python tests/structure_check.py`` from the repository root. It prints one line per finding
and a closing ``cycles/private imports/big modules: C/P/B`` line; ``tests/test_structure.py``
asserts ``0/0/0``.

* **Cycles**: strongly connected components of more than one module in the graph of every
  import statement of the project (top level, inside functions and under ``TYPE_CHECKING``
  alike: a type-only import still couples the two modules). ``from pkg import name`` is an edge
  to ``pkg.name`` when that is a module, else to ``pkg`` (its ``__init__``).
* **Private imports**: ``from module import _name`` where ``module`` is another project module
  and ``_name`` is not a dunder. A helper shared by two modules is public, or lives in a private
  *module* (``_optim.py``) whose names are public.
* **Big modules**: more than ``MAX_LINES`` lines.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("engine", "gmwm_app")
MAX_LINES = 800


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


def analyse() -> tuple[list[list[str]], list[str], list[str]]:
    """Return (cycles, private imports, big modules), each as a list of readable findings."""
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
    cycles = _sccs(graph)
    big = [
        f"{p.relative_to(ROOT)}: {n} lines"
        for p in mods.values()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    ]
    return cycles, private, big


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
    cycles, private, big = analyse()
    for c in cycles:
        print("cycle:", " <-> ".join(c))
    for p in private:
        print("private import:", p)
    for b in big:
        print("big module:", b)
    print(f"cycles/private imports/big modules: {len(cycles)}/{len(private)}/{len(big)}")
    return 0 if not (cycles or private or big) else 1


if __name__ == "__main__":
    sys.exit(main())
