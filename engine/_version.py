"""The engine's version, in a module of its own so that submodules can read it without
importing the ``engine`` package (which would make an import cycle)."""

__version__ = "0.1.0"
