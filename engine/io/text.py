"""Text logs: CSV, TSV, semicolon-separated (decimal commas) and whitespace columns.

An optional header names the columns (``gyro_x [deg/s]``: name and unit); a column named like
a time (``time``, ``t``, ``timestamp``, ``time_ms``, ...) or, without a header, a strictly
increasing first column with a near-constant step, is the time column. ``#`` starts a
comment. Errors name the line (1-based, as in an editor) and the column.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._files import check_memory, open_regular
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


#: Peak memory of :func:`read_text` (bytes), measured with tracemalloc over CSV/TSV/whitespace
#: files of 1 to 12 columns (tests/test_io_safety.py): per byte of the file (the bytes, the
#: decoded text, the stripped lines), per line (two str objects and a list slot each, the line
#: number) and per value (the float64 result and the parser's buffer).
PEAK_PER_BYTE, PEAK_PER_LINE, PEAK_PER_VALUE = 3.5, 110, 16
_SAMPLE = 1 << 16  # bytes read first to estimate the lines and values of a file


def text_memory_need(size: int, sample: bytes) -> int:
    """Estimated peak memory (bytes) of reading a text log of ``size`` bytes that starts with
    ``sample``: ``PEAK_PER_BYTE * size + PEAK_PER_LINE * lines + PEAK_PER_VALUE * values``,
    with the lines and values per byte of ``sample`` extrapolated to the file."""
    if not sample:
        return int(PEAK_PER_BYTE * size)
    lines = sample.count(b"\n") + (not sample.endswith(b"\n"))
    delim = next((d for d in (b"\t", b";", b",") if d in sample), None)
    values = sample.count(delim) + lines if delim else len(sample.split())
    per = size / len(sample)
    return int(PEAK_PER_BYTE * size + per * (PEAK_PER_LINE * lines + PEAK_PER_VALUE * values))


def _read(path: Path | io.BytesIO, src: str) -> bytes:
    """The bytes of a text log, once its parsing is known to fit in the available memory."""
    if isinstance(path, io.BytesIO):  # content already in memory: the rest of the peak
        raw = path.getvalue()
        need = text_memory_need(len(raw), raw[:_SAMPLE]) - len(raw)
        check_memory(need, src, what="to parse it as text", error=LoadError)
        return raw
    with open_regular(path, src, error=LoadError) as fh:
        size = os.fstat(fh.fileno()).st_size
        sample = fh.read(_SAMPLE)
        need = text_memory_need(size, sample)
        what = f"to parse {size / 1e6:.3g} MB of text"
        check_memory(need, src, what=what, fix="convert it to .npy or HDF5", error=LoadError)
        return sample + fh.read()


def read_text(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    raw = _read(path, src)
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
            raise LoadError(  # the header is not named: it may not be a header at all
                f"file '{src}' has a header line ({len(names)} column(s)) but no data rows: "
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
    except ValueError:
        _diagnose(src, contents, linenos, delim, names, header)
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


def _row_problem(fields: list[str], k: int) -> str | int | None:
    """What is wrong with a row of ``fields``: a sentence (its length), the index of its first
    field that is not a number, or None (k numbers)."""
    if len(fields) != k:
        return f"{len(fields)} value(s) where {k} were expected"
    return next((j for j, f in enumerate(fields) if _num(f) is None), None)


def _diagnose(
    src: str,
    contents: list[str],
    linenos: list[int],
    delim: str | None,
    names: list[str],
    header: bool,
) -> None:
    """Find the first ragged row or non-number after np.loadtxt failed, and raise.

    The message names the line and the column by number; it never quotes the file (which may
    be anything, e.g. a server's /etc/passwd given by path). The header's column names are
    given only when a row of numbers follows it (then it is a log's header).
    """
    k = len(names)
    problems = ((i, _row_problem(_split(c, delim), k)) for i, c in enumerate(contents))
    i, problem = next(((i, p) for i, p in problems if p is not None), (0, None))
    if problem is None:
        raise LoadError(f"file '{src}' could not be parsed as numbers: check its format")
    known = (
        not header
        or i > 0
        or any(_row_problem(_split(c, delim), k) is None for c in contents[1:10_000])
    )
    where = f"file '{src}', line {linenos[i]}"
    if isinstance(problem, str):
        cols = f" (columns: {', '.join(names)})" if known and header else ""
        raise LoadError(
            f"{where}: {problem}{cols}: give every row one value per column, or remove the line"
        )
    field = _split(contents[i], delim)[problem]
    what = "an empty field" if not field else "a value that is not a number"
    col = f"column {problem + 1} of {k}" + (f" ('{names[problem]}')" if known else "")
    raise LoadError(f"{where}, {col}: {what}: fix the value or remove the line")
