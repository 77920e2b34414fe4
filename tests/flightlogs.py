"""The fixture maker of tests/fixtures/make_flight_logs.py, importable by the tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

_PATH = Path(__file__).parent / "fixtures" / "make_flight_logs.py"
_spec = importlib.util.spec_from_file_location("make_flight_logs", _PATH)
assert _spec is not None and _spec.loader is not None
make = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("make_flight_logs", make)
_spec.loader.exec_module(make)
