"""``python -m engine.cli``: the ``gmwm`` command."""

from .main import main

raise SystemExit(main())
