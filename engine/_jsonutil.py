"""JSON-ready values: NaN/Inf become None (JSON's null), NumPy scalars and arrays plain Python."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["json_ready"]


def json_ready(o: Any) -> Any:
    """``o`` with every non-finite float replaced by None and NumPy types made plain Python.

    Dictionaries (keys as strings), lists and tuples are converted recursively; other values
    are returned as they are. ``json.dumps(json_ready(o), allow_nan=False)`` then always works
    for numbers, whatever the strings contain.
    """
    if isinstance(o, dict):
        return {str(k): json_ready(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_ready(v) for v in o]
    if isinstance(o, np.ndarray):
        return json_ready(o.tolist())
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o
