"""``python -m engine.cli``: the ``gmwm`` command."""

from .commands import main

raise SystemExit(main())
