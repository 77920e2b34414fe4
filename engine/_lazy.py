"""Attributes of a package imported on first use (PEP 562), for packages that keep
``import engine`` light (SciPy, h5py and the multivariate code cost tenths of a second)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence
from typing import Any


def lazy_attributes(
    package: str, modules: Mapping[str, Sequence[str]], namespace: dict[str, Any]
) -> tuple[Callable[[str], Any], Callable[[], list[str]], tuple[str, ...]]:
    """Module ``__getattr__`` and ``__dir__`` that import a module's names on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``; ``modules`` keys are modules relative to it.
    modules : mapping of str to sequence of str
        A (relative) module to the names it defines, e.g. ``{"allan": ("allan_variance",)}``.
    namespace : dict
        The package's ``globals()``: an imported attribute is cached there, so the module
        ``__getattr__`` runs once per name.

    Returns
    -------
    (__getattr__, __dir__, names)
        To assign in the package: ``__getattr__, __dir__, lazy = lazy_attributes(...)``;
        ``names`` are the lazy names in order (for the package's ``__all__``).
    """
    table = {name: module for module, names in modules.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__, tuple(table)
