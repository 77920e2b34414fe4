"""The ``gmwm`` command (``engine.cli:main``): wavelet variance, fits, model selection,
simulation, exports and the slope-method study from the shell.

* :mod:`engine.cli.commands`: the table of sub-commands, the parser and :func:`main` (a
  sub-command's module is imported only when it runs);
* :mod:`engine.cli.core`: the sub-commands ``wv``, ``fit``, ``select``, ``simulate``, ``study``;
* :mod:`engine.cli.common`: what they share (user errors, log options, one channel's WV);
* :mod:`engine.cli.export`: ``gmwm export``; :mod:`engine.cli.plan`: ``gmwm plan``; one module
  per other sub-command;
* :mod:`engine.cli.multi`: ``gmwm fit`` with several channels or recordings.
"""

from __future__ import annotations

from .commands import build_parser, main

__all__ = ["main", "build_parser"]
