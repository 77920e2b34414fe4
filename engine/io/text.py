"""Text logs: CSV, TSV, semicolon-separated (decimal commas) and whitespace columns.

An optional header names the columns (``gyro_x [deg/s]``: name and unit); a column named like
a time (``time``, ``t``, ``timestamp``, ``time_ms``, ...) or, without a header, a strictly
increasing first column with a near-constant step, is the time column. ``#`` starts a
comment. Errors name the line (1-based, as in an editor) and the column.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from ._assemble import UNIT_RE, LoadOptions, RawLog, clean_unit, finish_log, time_divisor
from .log import ImuLog, LoadError

__all__ = ["read_text"]


def _split(line: str, delim: str | None) -> list[str]:
    return [f.strip().strip("\"'").strip() for f in line.split(delim)]


def _num(s: str) -> float | None:
    try:
        return float(s)
    except ValueError:
        return None


def _split_header(line: str, delim: str | None) -> list[str]:
    if delim is not None:
        return _split(line, delim)
    out: list[str] = []  # whitespace: keep "gyro_x [deg/s]" together
    for tok in line.split():
        if out and (
            tok[0] in "[("
            or out[-1].count("[") + out[-1].count("(") > out[-1].count("]") + out[-1].count(")")
        ):
            out[-1] += " " + tok
        else:
            out.append(tok.strip("\"'"))
    return out


def _decode(raw: bytes, src: str) -> str:
    not_text = LoadError(
        f"file '{src}' is not a text file (binary data, or an encoding other than "
        "UTF-8/Latin-1): expected CSV/TSV text, .npy/.npz or HDF5; check the "
        "file and its extension"
    )
    if b"\x00" in raw[:65536]:
        raise not_text
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
        sample = text[:65536]
        ctrl = sum(1 for c in sample if ord(c) < 32 and c not in "\t\r\n\f" or 127 <= ord(c) < 160)
        if ctrl > 0.01 * len(sample):
            raise not_text from None
        return text


def read_text(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    raw = path.getvalue() if isinstance(path, io.BytesIO) else path.read_bytes()
    text = _decode(raw, src)
    contents: list[str] = []
    linenos: list[int] = []
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.split("#", 1)[0].strip()
        if s:
            contents.append(s)
            linenos.append(i)
    if not contents:
        raise LoadError(
            f"file '{src}' is empty (no data rows, only blank or '#' comment "
            "lines): check that the logger wrote samples"
        )
    probe = contents[min(1, len(contents) - 1)]
    delim = next((d for d in ("\t", ";", ",") if d in probe), None)
    notes: list[str] = []
    if delim == ";" and "," in probe:  # European CSV: 1,5;2,3
        contents = [c.replace(",", ".") for c in contents]
        notes.append("semicolon-separated with decimal commas")
    if delim is not None and contents[-1].endswith(delim):  # trailing delimiter on every row
        contents = [c.rstrip(delim).rstrip() for c in contents]
        keep = [i for i, c in enumerate(contents) if c]  # a row of delimiters only: blank
        contents, linenos = [contents[i] for i in keep], [linenos[i] for i in keep]
        if not contents:
            raise LoadError(
                f"file '{src}' holds only delimiters, no values: check that the "
                "logger wrote samples"
            )
    first = _split(contents[0], delim)
    header = any(_num(f) is None for f in first)
    names: list[str] = []
    units: dict[str, str] = {}
    if header:
        for j, tok in enumerate(_split_header(contents[0], delim)):
            m = UNIT_RE.fullmatch(tok)
            name, unit = (m.group(1).strip(), m.group(2)) if m else (tok.strip(), "")
            name = name or f"col{j}"
            if name in names:
                notes.append(f"duplicate column name '{name}' renamed '{name}_{j}'")
                name = f"{name}_{j}"
            names.append(name)
            units[name] = clean_unit(unit)
        contents, linenos = contents[1:], linenos[1:]
        if not contents:
            raise LoadError(
                f"file '{src}' has a header ({', '.join(names)}) but no data rows: "
                "check that the logger wrote samples"
            )
    else:
        names = [f"col{j}" for j in range(len(first))]
    rows = np.asarray(linenos)
    try:
        data = np.loadtxt(
            contents, delimiter=delim, dtype=np.float64, ndmin=2, comments=None, quotechar='"'
        )
        if data.shape[1] != len(names):
            raise ValueError("header and data column counts differ")
    except ValueError as exc:
        _diagnose(src, contents, linenos, delim, names, exc)
    cols = {name: data[:, j] for j, name in enumerate(names)}
    time = None
    for name in names:  # a named time column (the first one gives fs)
        div = time_divisor(name, units.get(name, ""))
        if div is not None:
            time = time or (name, cols[name], div)
            del cols[name]
    if (
        not header
        and len(names) >= 2
        and _looks_like_time(cols["col0"])
        and not any(_looks_like_time(cols[k], strict_only=True) for k in names[1:])
    ):
        time = ("col0", cols.pop("col0"), (1.0, False))
        notes.append(
            "first column read as a time column in seconds (strictly increasing, "
            "near-constant step); pass fs= to set the rate explicitly"
        )
    meta = {"delimiter": {None: "whitespace", "\t": "tab"}.get(delim, delim), "header": header}
    raw = RawLog(cols, units, time=time, rows=rows, meta=meta, notes=notes)
    return finish_log(src, raw, fmt="text", channel=channel, opts=opts)


def _looks_like_time(a: np.ndarray, strict_only: bool = False) -> bool:
    d = np.diff(a)
    if d.size < 2 or not np.all(d > 0):
        return False
    return strict_only or bool(np.mean(np.abs(d - np.median(d)) <= 0.1 * np.median(d)) >= 0.99)


def _diagnose(
    src: str,
    contents: list[str],
    linenos: list[int],
    delim: str | None,
    names: list[str],
    exc: Exception,
) -> None:
    """Find the first ragged row or non-number after np.loadtxt failed, and raise."""
    k = len(names)
    for line, ln in zip(contents, linenos, strict=True):
        fields = _split(line, delim)
        if len(fields) != k:
            raise LoadError(
                f"file '{src}', line {ln}: {len(fields)} value(s) where {k} were expected "
                f"(columns: {', '.join(names)}): give every row one value per column, "
                "or remove the line"
            )
        for j, s in enumerate(fields):
            if _num(s) is None:
                what = "an empty field" if not s else f"{s!r}"
                raise LoadError(
                    f"file '{src}', column '{names[j]}', line {ln}: {what} is not a "
                    "number: fix the value or remove the line"
                )
    raise LoadError(f"file '{src}' could not be parsed as numbers ({exc}): check the format")
