"""The engine's version (one place; ``engine.__version__`` and reports read it here)."""

__version__ = "0.1.0"
