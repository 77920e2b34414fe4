"""Helpers shared by the export formats: channel axes and exact number text."""

from __future__ import annotations

import math
import re

__all__ = ["channel_axis", "fmt_float", "yaml_float"]


def channel_axis(name: str) -> str:
    """Axis letter of a channel name (``gyro_x`` -> ``x``, ``imu/acc[1]`` -> ``y``), else the
    name itself."""
    n = name.strip().lower()
    m = re.search(r"\[(\d)\]$", n)
    if m and int(m.group(1)) < 3:
        return "xyz"[int(m.group(1))]
    m = re.search(r"(?:^|[^a-z])([xyz])$", n) or re.search(r"([xyz])$", n)
    return m.group(1) if m else name


def fmt_float(v: float) -> str:
    """17 significant digits (exact round trip), empty for NaN/Inf (CSV cells)."""
    return repr(float(v)) if math.isfinite(v) else ""


def yaml_float(v: float) -> str:
    """A float that YAML 1.1 (PyYAML) reads as a float: ``1.0e-05``, not ``1e-05``."""
    v = float(v)
    if not math.isfinite(v):
        return ".nan" if v != v else (".inf" if v > 0 else "-.inf")
    s = repr(v)
    if "e" in s:
        mant, exp = s.split("e")
        if "." not in mant:
            mant += ".0"
        if exp[0] not in "+-":
            exp = "+" + exp
        s = f"{mant}e{exp}"
    elif "." not in s:
        s += ".0"
    return s
