"""Attributes of a package imported on first use (PEP 562), for packages that keep
``import engine`` light (SciPy, h5py and the multivariate code cost tenths of a second)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_attributes(
    package: str, table: Mapping[str, str], namespace: dict[str, Any]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Module ``__getattr__`` and ``__dir__`` that import ``table[name]`` on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``; ``table`` values are modules relative to it.
    table : mapping of str to str
        Attribute name to the (relative) module that defines it, e.g. ``{"wv_matrix": "wccv"}``.
    namespace : dict
        The package's ``globals()``: an imported attribute is cached there, so the module
        ``__getattr__`` runs once per name.

    Returns
    -------
    (__getattr__, __dir__)
        To assign in the package: ``__getattr__, __dir__ = lazy_attributes(...)``.
    """

    def __getattr__(name: str) -> Any:
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__
