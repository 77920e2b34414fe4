"""Text logs: CSV, TSV, semicolon-separated (decimal commas) and whitespace columns.

An optional header names the columns (``gyro_x [deg/s]``: name and unit); a column named like
a time (``time``, ``t``, ``timestamp``, ``time_ms``, ...) or, without a header, a strictly
increasing first column with a near-constant step, is the time column. ``#`` starts a
comment. Errors name the line (1-based, as in an editor) and the column.
"""

from __future__ import annotations

import io
import itertools
import os
from collections.abc import Callable, Generator, Iterator
from pathlib import Path
from typing import Any, cast

import numpy as np

from .._files import open_regular
from .._limits import check_memory
from ._assemble import (
    UNIT_RE,
    LoadOptions,
    RawLog,
    check_channel_count,
    clean_unit,
    finish_log,
)
from .log import ImuLog, LoadError
from .timecols import column_layout, header_field

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


#: Bytes decoded at a time (cut at a line end): the text is never held whole as a str.
BLOCK_BYTES = 1 << 18
#: Rows parsed by one np.loadtxt call.
CHUNK_ROWS = 16384


def _encoding(raw: bytes | bytearray, src: str) -> str:
    """The encoding of a text log (``utf-8-sig`` or ``latin-1``); LoadError for binary data.

    Checked block by block (line ends never fall inside a UTF-8 sequence), so no decoded copy
    of the whole file is made.
    """
    not_text = _not_text(src)
    if b"\x00" in raw[:65536]:
        raise not_text
    try:
        for k, block in enumerate(_blocks(raw)):
            block.decode("utf-8-sig" if k == 0 else "utf-8")
        return "utf-8-sig"
    except UnicodeDecodeError:
        sample = bytes(raw[:65536]).decode("latin-1")
        ctrl = sum(1 for c in sample if ord(c) < 32 and c not in "\t\r\n\f" or 127 <= ord(c) < 160)
        if ctrl > 0.01 * len(sample):
            raise not_text from None
        return "latin-1"


def _not_text(src: str) -> LoadError:
    return LoadError(
        f"file '{src}' is not a text file (binary data, or an encoding other than "
        "UTF-8/Latin-1) nor a binary format read here: CSV/TSV text, .npy/.npz, HDF5, "
        "ROS bags (.bag/.db3/.mcap), PX4 ULog (.ulg), ArduPilot DataFlash (.bin); "
        "convert other logs to CSV (ulog2csv, mavlogdump.py --format csv) or check the file"
    )


def _blocks(raw: bytes | bytearray) -> Iterator[bytes | bytearray]:
    """``raw`` in pieces of about :data:`BLOCK_BYTES`, each ending at a line end (``\\n``)."""
    start, n = 0, len(raw)
    while start < n:
        cut = raw.find(b"\n", min(start + BLOCK_BYTES, n) - 1)
        end = n if cut < 0 else cut + 1
        yield raw[start:end]
        start = end


def _content_lines(raw: bytes | bytearray, encoding: str) -> Generator[tuple[int, str], None, None]:
    """(1-based line number, content) of the lines that hold something besides a ``#``
    comment and blanks, decoded a block at a time."""
    lineno = 0
    for k, block in enumerate(_blocks(raw)):
        text = block.decode(encoding if k == 0 else encoding.replace("-sig", ""))
        for line in text.splitlines():
            lineno += 1
            s = line.split("#", 1)[0].strip()
            if s:
                yield lineno, s


def _last_content(raw: bytes | bytearray, encoding: str) -> str:
    """The last content line of ``raw`` (see :func:`_content_lines`), read from the end."""
    end = len(raw)
    while end > 0:
        start = max(0, end - BLOCK_BYTES)
        if start > 0:  # from a line end on, so that no line is cut
            cut = raw.rfind(b"\n", 0, start)
            start = 0 if cut < 0 else cut + 1
        text = raw[start:end].decode(encoding if start == 0 else encoding.replace("-sig", ""))
        for line in reversed(text.splitlines()):
            s = line.split("#", 1)[0].strip()
            if s:
                return s
        end = start
    return ""


def _parse_rows(
    rows: Iterator[tuple[int, str]], delim: str | None, k: int, capacity: int
) -> tuple[np.ndarray, np.ndarray]:
    """The ``(k, n)`` float64 values (one contiguous row per column) and the line numbers of
    the data rows (int32 unless a file has 2**31 lines), parsed :data:`CHUNK_ROWS` lines at a
    time into arrays of ``capacity`` rows (grown if needed). ValueError as np.loadtxt's."""
    cap = max(int(capacity), 1)
    out = np.empty((k, cap))
    lines_of = np.empty(cap, dtype=np.int32 if cap < 2**31 - CHUNK_ROWS else np.int64)
    n = 0
    while True:
        chunk = list(itertools.islice(rows, CHUNK_ROWS))
        if not chunk:
            break
        block = np.loadtxt(
            [c for _, c in chunk],
            delimiter=delim,
            dtype=np.float64,
            ndmin=2,
            comments=None,
            quotechar='"',
        )
        if block.shape[1] != k:
            raise ValueError("header and data column counts differ")
        m = block.shape[0]
        if n + m > cap:  # grow (the first chunks' size is a guess; see read_text)
            cap = max(2 * cap, n + m)
            grown = np.empty((k, cap))
            grown[:, :n] = out[:, :n]
            out = grown
            lines_of = np.resize(lines_of.astype(np.int64), cap)
        out[:, n : n + m] = block.T
        lines_of[n : n + m] = [ln for ln, _ in chunk]
        n += m
    return out[:, :n], lines_of[:n]


#: Peak memory of loading a text log (bytes), measured with tracemalloc over CSV/TSV/whitespace
#: files of 1 to 12 columns and 5e4 to 2e5 rows (tests/engine/test_io_safety.py): per byte of the
#: file (its bytes, held while the rows are parsed block by block), per line (its line number), per
#: value (the float64 column and the log's checks), plus a fixed part (one chunk of
#: :data:`CHUNK_ROWS` rows as text and the parser's buffer).
PEAK_PER_BYTE, PEAK_PER_LINE, PEAK_PER_VALUE, PEAK_FIXED = 1.5, 4, 10, 8_000_000
_SAMPLE = 1 << 16  # bytes read first to estimate the lines and values of a file
_READ_BYTES = 1 << 24  # then read in blocks of 16 MB, each checked for NUL bytes


def text_memory_need(size: int, sample: bytes) -> int:
    """Estimated peak memory (bytes) of reading a text log of ``size`` bytes that starts with
    ``sample``: ``PEAK_PER_BYTE * size + PEAK_PER_LINE * lines + PEAK_PER_VALUE * values +
    PEAK_FIXED``, with the lines and values per byte of ``sample`` extrapolated to the file."""
    if not sample:
        return int(PEAK_PER_BYTE * size) + PEAK_FIXED
    lines = sample.count(b"\n") + (not sample.endswith(b"\n"))
    delim = next((d for d in (b"\t", b";", b",") if d in sample), None)
    values = sample.count(delim) + lines if delim else len(sample.split())
    per = size / len(sample)
    return (
        int(PEAK_PER_BYTE * size + per * (PEAK_PER_LINE * lines + PEAK_PER_VALUE * values))
        + PEAK_FIXED
    )


def _read(path: Path | io.BytesIO, src: str) -> bytes | bytearray:
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
        if b"\x00" in sample:  # binary (a sparse file of zeros): before reading the rest
            raise _not_text(src)
        check_memory(need, src, what=what, fix="convert it to .npy or HDF5", error=LoadError)
        buf = bytearray(max(size, len(sample)))  # filled in place: no second copy
        buf[: len(sample)] = sample
        pos = len(sample)
        with memoryview(buf) as view:
            while pos < len(buf):  # NUL is no text: refused as soon as a block holds one
                got = cast(io.BufferedReader, fh).readinto(view[pos : pos + _READ_BYTES])
                if not got:
                    break
                if buf.find(b"\x00", pos, pos + got) >= 0:
                    raise _not_text(src)
                pos += got
        del buf[pos:]  # (a file that shrank since its size was read)
        return buf


def read_text(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    raw = _read(path, src)
    # No whole-file copies (an upload may be 200 MB): the bytes are decoded a block at a
    # time, rows parsed in chunks into one array per column (what the log keeps); at the
    # peak, the file's bytes plus its values plus one chunk's text.
    encoding = _encoding(raw, src)
    lines = _content_lines(raw, encoding)
    head = list(itertools.islice(lines, 2))
    lines.close()  # (its decoded block)
    if not head:
        raise LoadError(
            f"file '{src}' is empty (no data rows, only blank or '#' comment "
            "lines): check that the logger wrote samples"
        )
    probe = head[min(1, len(head) - 1)][1]
    delim = next((d for d in ("\t", ";", ",") if d in probe), None)
    notes: list[str] = []
    euro = delim == ";" and "," in probe  # European CSV: 1,5;2,3
    if euro:
        notes.append("semicolon-separated with decimal commas")
    trailing = delim is not None and _last_content(raw, encoding).endswith(delim)

    def content_rows() -> Iterator[tuple[int, str]]:
        for ln, c in _content_lines(raw, encoding):
            if euro:
                c = c.replace(",", ".")
            if trailing:  # trailing delimiter on every row
                c = c.rstrip(delim).rstrip()
                if not c:  # a row of delimiters only: blank
                    continue
            yield ln, c

    rows_it = content_rows()
    first_row = next(rows_it, None)
    if first_row is None:
        raise LoadError(
            f"file '{src}' holds only delimiters, no values: check that the logger wrote samples"
        )
    first = _split(first_row[1], delim)
    header = any(_num(f) is None for f in first)
    names: list[str] = []
    units: dict[str, str] = {}  # also the set of names so far: linear in the columns
    if header:
        for j, tok in enumerate(_split_header(first_row[1], delim)):
            name, unit = header_field(tok, UNIT_RE)  # gyro_rad[1] -> gyro_rad_y (timecols)
            name = name or f"col{j}"
            if name in units:
                notes.append(f"duplicate column name '{name}' renamed '{name}_{j}'")
                name = f"{name}_{j}"
            names.append(name)
            units[name] = clean_unit(unit)
        second = next(rows_it, None)
        if second is None:
            raise LoadError(  # the header is not named: it may not be a header at all
                f"file '{src}' has a header line ({len(names)} column(s)) but no data rows: "
                "check that the logger wrote samples"
            )
        data_rows = itertools.chain([second], rows_it)
    else:
        names = [f"col{j}" for j in range(len(first))]
        data_rows = itertools.chain([first_row], rows_it)
    if channel is None:  # before parsing: a file of 1e6 columns is refused at its header
        check_channel_count(src, len(names))
    try:
        # every row ends with a line feed but maybe the last (old Mac files: grown as needed)
        values, rows = _parse_rows(data_rows, delim, len(names), raw.count(b"\n") + 1)
    except ValueError:  # walk the rows again (lazily) for the line at fault
        skip = 1 if header else 0
        _diagnose(src, lambda: itertools.islice(content_rows(), skip, None), delim, names, header)
    cols = {name: values[j] for j, name in enumerate(names)}  # contiguous: no copy later
    # time, instance, temperature and counter columns; converter profiles (timecols)
    layout = column_layout(src, cols, units, rows, notes)
    cols, units, time = layout.cols, layout.units, layout.time
    rows = rows if layout.rows is None else layout.rows
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
    if layout.profile:
        meta["profile"] = layout.profile
    parsed = RawLog(cols, units, time=time, rows=rows, meta=meta, notes=notes, aux=layout.aux)
    return finish_log(src, parsed, fmt="text", channel=channel, opts=opts)


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
    data_rows: Callable[[], Iterator[tuple[int, str]]],
    delim: str | None,
    names: list[str],
    header: bool,
) -> None:
    """Find the first ragged row or non-number after the parser failed, and raise.

    ``data_rows()`` walks the data rows (line number, content) again, lazily. The message names
    the line and the column by number; it never quotes the file (which may be anything, e.g. a
    server's /etc/passwd given by path). The header's column names are given only when a row
    of numbers follows it (then it is a log's header).
    """
    k = len(names)
    found = next(
        (
            (i, ln, c, p)
            for i, (ln, c) in enumerate(data_rows())
            if (p := _row_problem(_split(c, delim), k)) is not None
        ),
        None,
    )
    if found is None:
        raise LoadError(f"file '{src}' could not be parsed as numbers: check its format")
    i, ln, content, problem = found
    known = (
        not header
        or i > 0
        or any(
            _row_problem(_split(c, delim), k) is None
            for _, c in itertools.islice(data_rows(), 1, 10_000)
        )
    )
    where = f"file '{src}', line {ln}"
    if isinstance(problem, str):
        cols = f" (columns: {', '.join(names)})" if known and header else ""
        raise LoadError(
            f"{where}: {problem}{cols}: give every row one value per column, or remove the line"
        )
    field = _split(content, delim)[problem]
    what = "an empty field" if not field else "a value that is not a number"
    col = f"column {problem + 1} of {k}" + (f" ('{names[problem]}')" if known else "")
    raise LoadError(f"{where}, {col}: {what}: fix the value or remove the line")
