"""The ``gmwm`` command (``engine.cli:main``): wavelet variance, fits, model selection,
simulation, exports and the slope-method study from the shell.

* :mod:`engine.cli.main`: the parser and the subcommands ``wv``, ``fit``, ``select``,
  ``simulate``, ``study``;
* :mod:`engine.cli.common`: what they share (user errors, log options, one channel's WV);
* :mod:`engine.cli.export`: ``gmwm export``;
* :mod:`engine.cli.multi`: ``gmwm fit`` with several channels or recordings.
"""

from __future__ import annotations

from .main import build_parser, main

__all__ = ["main", "build_parser"]
