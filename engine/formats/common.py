"""Helpers shared by the export formats: channel axes, exact number text, and the one place
where user-given text (file and channel names, units, topics) is made safe for a file.

Every text format builds its lines and joins them with :func:`text_lines`, which escapes
control characters inside each line (:func:`clean_text`): a newline in a file name stays
``\\n`` inside its comment and cannot start a line of its own (a PX4 parameter, a YAML key).
CSV cells go through :func:`csv_cells`, YAML string values through :func:`yaml_str`; the JSON
formats are safe by encoding (``json.dumps`` escapes control characters and U+2028/2029).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Iterable
from typing import Any

from .._text import spreadsheet_safe

__all__ = [
    "fmt_float",
    "yaml_float",
    "clean_text",
    "text_lines",
    "csv_cells",
    "yaml_str",
    "source_text",
]

# C0 controls, DEL, C1 controls (with NEL U+0085) and the Unicode line/paragraph separators:
# every character str.splitlines(), a YAML parser or a terminal may take as a line break.
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
_PLAIN_YAML = re.compile(r"[A-Za-z_/][A-Za-z0-9_/.\-]*")
_YAML_WORDS = {"true", "false", "null", "yes", "no", "on", "off", "~"}  # PyYAML words


def _escape(m: re.Match[str]) -> str:
    c = m.group()
    if c in _NAMED:
        return _NAMED[c]
    return f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}"


def clean_text(text: Any) -> str:
    """``text`` (a str, path or anything with ``str``) with every control character escaped:
    ``\\n``, ``\\r``, ``\\t``, ``\\xNN`` (other C0/C1 controls, DEL), ``\\u2028``,
    ``\\u2029``. Printable text, backslashes included, is unchanged."""
    s = os.fspath(text) if isinstance(text, os.PathLike) else str(text)
    return _CONTROL.sub(_escape, s)


def text_lines(lines: Iterable[str], end: str = "\n") -> str:
    """The file text of ``lines``: each line's control characters escaped
    (:func:`clean_text`), joined by newlines, then ``end``."""
    return "\n".join(clean_text(line) for line in lines) + end


def csv_cells(row: Iterable[Any]) -> list[Any]:
    """A CSV row with its text cells cleaned (:func:`clean_text`) and never a spreadsheet
    formula (:func:`engine._text.spreadsheet_safe`); numbers unchanged."""
    return [spreadsheet_safe(clean_text(c)) if isinstance(c, str) else c for c in row]


def yaml_str(text: Any) -> str:
    """A YAML scalar for a user-given string: plain when it is a simple name or topic
    (``/imu0``), else double-quoted with JSON escapes (valid YAML), so that ``:``, ``#`` or a
    control character cannot make a new key."""
    s = os.fspath(text) if isinstance(text, os.PathLike) else str(text)
    if _PLAIN_YAML.fullmatch(s) and s.lower() not in _YAML_WORDS:
        return s
    return json.dumps(s)


def source_text(source: Any) -> str:
    """The source name of an export as text: a path (``os.PathLike``) as its string, None as
    ``""``."""
    if source is None:
        return ""
    return os.fspath(source) if isinstance(source, os.PathLike) else str(source)


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
