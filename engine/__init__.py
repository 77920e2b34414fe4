"""GMWM engine: wavelet variance, latent processes, GMWM fitting, loaders (pure numerics, no UI).

>>> import engine as eg
>>> wv = eg.wavelet_variance(x, fs=100.0)                 # doctest: +SKIP
>>> res = eg.fit_gmwm(wv, eg.WN() + eg.RW() + 2 * eg.GM())  # doctest: +SKIP
>>> print(res.summary())                                  # doctest: +SKIP

The public surface is the union of the ``__all__`` of the subpackages in :data:`SUBPACKAGES`
(one concept each; see README, "Developers"). ``models``, ``wv``, ``fit`` and ``units`` are
imported with ``engine``; every other name is imported on first use (PEP 562), so that
``import engine`` and the ``gmwm`` command stay light (SciPy, h5py and the multivariate code
cost tenths of a second). The lazy names are read from each subpackage's literal ``__all__``
without importing it; ``tests/test_public_api.py`` checks that every name resolves and that no
two subpackages export the same name.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path
from typing import Any

from . import fit, models, units, wv
from ._version import __version__ as __version__

#: The subpackages whose ``__all__`` make up ``engine``'s public names, in this order.
SUBPACKAGES: tuple[str, ...] = (
    "models",
    "wv",
    "fit",
    "units",
    "inference",
    "multivariate",
    "io",
    "formats",
    "teaching",
    "demo",
    "batch",
    "reporting",
    "session",
)
_EAGER = {"models": models, "wv": wv, "fit": fit, "units": units}


def _literal_all(package: str) -> list[str]:
    """A subpackage's ``__all__``, read from its source (a literal list), not imported."""
    init = Path(__file__).with_name(package)
    path = init / "__init__.py" if init.is_dir() else init.with_suffix(".py")
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return list(ast.literal_eval(node.value))
    raise ImportError(f"engine.{package} has no literal __all__ (engine's API is built from it)")


#: Public name -> the subpackage that defines it.
_SOURCE: dict[str, str] = {}
for _pkg in SUBPACKAGES:
    _names = list(_EAGER[_pkg].__all__) if _pkg in _EAGER else _literal_all(_pkg)
    for _name in _names:
        _SOURCE.setdefault(_name, _pkg)
    # names an eager subpackage already holds are bound now; its own lazy names stay lazy
    if _pkg in _EAGER:
        for _name in _names:
            if _name in vars(_EAGER[_pkg]):
                globals()[_name] = vars(_EAGER[_pkg])[_name]

__all__ = sorted(_SOURCE)


def __getattr__(name: str) -> Any:
    pkg = _SOURCE.get(name)
    if pkg is None:
        raise AttributeError(f"module 'engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{pkg}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SOURCE))
