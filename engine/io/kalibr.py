"""Reading a Kalibr ``imu.yaml``: :func:`read_kalibr` (no YAML library needed).

A reader, so it lives with the loaders: the datasheet check (:mod:`engine.inference`) reads
a Kalibr file as a datasheet, and the Kalibr export format (:mod:`engine.formats.kalibr`)
reads back what it writes, both from here.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

from .._files import read_regular
from ..units import ExportError

__all__ = ["read_kalibr"]


def _yscalar(s: str) -> Any:
    s = s.strip()
    if len(s) >= 2 and s[0] == s[-1] and s[0] in "'\"":
        return s[1:-1]
    low = s.lower()
    if low in (".nan", "nan"):
        return math.nan
    if low in (".inf", "+.inf", "inf"):
        return math.inf
    if low in ("-.inf", "-inf"):
        return -math.inf
    if low in ("true", "false"):
        return low == "true"
    try:
        return int(s)
    except ValueError:
        pass
    try:
        return float(s)
    except ValueError:
        return s


def _strip_comment(line: str) -> str:
    quote = ""
    for i, c in enumerate(line):
        if c in "'\"":
            quote = "" if quote == c else (quote or c)
        elif c == "#" and not quote and (i == 0 or line[i - 1] in " \t"):
            return line[:i]
    return line


def read_kalibr(source: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a Kalibr ``imu.yaml`` (path, or the YAML text itself) into a dict.

    Reads the flat ``key: value`` layout of Kalibr IMU files, with flow mappings/lists
    (``{x: 1.0, y: 2.0}``), and the first ``imuN:`` block of Kalibr's nested output and of an
    OpenVINS ``kalibr_imu_chain.yaml`` (``%YAML:1.0``) as if its keys were top-level; other
    indented blocks are skipped. No YAML library is needed.

    Raises
    ------
    ExportError
        Unreadable file, or a line that is not ``key: value``.
    """
    text = str(source)
    if isinstance(source, os.PathLike) or (
        "\n" not in text and ":" not in text.split("/")[0] and Path(text).exists()
    ):
        data = read_regular(source, error=ExportError)  # no FIFO or device: engine._files
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise ExportError(f"Kalibr file '{source}' is not UTF-8 text") from None
    out: dict[str, Any] = {}
    block, block_indent, used_block = "", 0, ""
    for i, raw in enumerate(text.splitlines(), start=1):
        line = _strip_comment(raw).rstrip()
        if not line.strip() or line.strip() == "---" or line.startswith("%"):
            continue
        if line[0] in " \t-":
            # the first imuN: block of Kalibr's imu-chain output or OpenVINS's
            # kalibr_imu_chain.yaml: its direct key: value lines count as top-level keys
            ind = len(line) - len(line.lstrip())
            if not block or line.lstrip().startswith("-"):
                continue
            if block_indent == 0:
                block_indent = ind
            if ind != block_indent or used_block not in ("", block):
                continue
            used_block = block
            line = line.strip()
        else:
            key0, _, val0 = line.partition(":")
            block = (
                key0.strip() if re.fullmatch(r"imu\d+", key0.strip()) and not val0.strip() else ""
            )
            block_indent = 0
            if block:
                continue
        key, sep, val = line.partition(":")
        if not sep or not key.strip():
            raise ExportError(f"Kalibr YAML line {i} is not 'key: value': fix or remove it")
        val = val.strip()
        if val.startswith("{") and val.endswith("}"):
            items = [it for it in val[1:-1].split(",") if it.strip()]
            d = {}
            for it in items:
                k, s2, v = it.partition(":")
                if not s2:
                    raise ExportError(
                        f"Kalibr YAML line {i}: an item of its {{...}} map is not 'key: value'"
                    )
                d[k.strip()] = _yscalar(v)
            out[key.strip()] = d
        elif val.startswith("[") and val.endswith("]"):
            out[key.strip()] = [_yscalar(v) for v in val[1:-1].split(",") if v.strip()]
        else:
            out[key.strip()] = _yscalar(val) if val else None
    return out
