"""Loading and saving static IMU logs: text (CSV/TSV/whitespace), NPY/NPZ, HDF5, ROS bags.

:func:`load_log` returns an :class:`ImuLog`: raw channels (1-D arrays) with their sampling
frequency and units, or, for the wavelet-variance summary files of ``shared/data/derived``,
one precomputed :class:`~engine.wavelet.WaveletVariance` per channel. Every failure raises
:class:`LoadError`, whose message names the file, the column or dataset, what is wrong and
how to fix it (library errors on damaged files are converted too).

Time columns (and ROS message stamps) are checked for gaps, duplicates and jitter
(:mod:`engine.timecheck`); ``segment=`` chooses between stopping with a report (default),
the longest clean segment, or keeping every sample with a note. ``scale=`` turns raw integer
counts into units; float32 samples stay float32. ROS 1/2 bags with ``sensor_msgs/Imu`` are
read through :mod:`engine.rosbag` (the pure-Python ``rosbags`` package).

:func:`save_log` writes the raw HDF5 layout of ``shared/data`` (``kind = "raw"``),
a ``.npy`` array or a ``.csv`` file with a time column.

Sample indices in messages are 0-based; line numbers are 1-based, as in an editor.
"""

from __future__ import annotations

import json
import math
import os
import re
import struct
import zipfile
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .wv import WaveletVariance

if TYPE_CHECKING:  # pragma: no cover
    import h5py

__all__ = ["LoadError", "ImuLog", "load_log", "save_log"]

_H5_EXT = {".h5", ".hdf5", ".hdf", ".he5"}
_MAGIC = {
    b"\x89HDF\r\n\x1a\n": "hdf5",
    b"\x93NUMPY": "npy",
    b"PK\x03\x04": "npz",
    b"#ROSBAG V2.0": "bag",
    b"\x89MCAP0\r\n": "bag",
    b"SQLite format 3\x00": "bag",
}
_TIME_RE = re.compile(r"(time|t|timestamp|stamp|sec|seconds)(?:_(s|ms|us|ns))?|(ms|us|ns)")
_TIME_DIV = {"s": 1.0, "sec": 1.0, "seconds": 1.0, "ms": 1e3, "us": 1e6, "µs": 1e6, "ns": 1e9}
_UNIT_RE = re.compile(r"(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*")
_FS_KEYS = ("fs_hz", "fs", "sample_rate", "sampling_rate")
_SUMMARY_KINDS = {"wavelet_and_allan_variance", "wavelet_variance"}
_NO_UNIT = {"", "unknown", "none", "n/a", "-", "?"}
_RESERVED = {"fs_hz", "n_samples", "duration_s", "units", "kind", "schema_version"}


class LoadError(ValueError):
    """A log could not be loaded (or saved); the message says which file, where, and the fix."""


@dataclass(frozen=True, eq=False)
class ImuLog:
    """A loaded IMU log: raw channels, or precomputed wavelet variances for summary files.

    Attributes
    ----------
    channels : dict of str to ndarray
        Channel name to 1-D float64 (or float32) samples; empty for summary files.
    fs : float
        Sampling frequency (Hz).
    fs_source : str
        Where ``fs`` came from: ``"file"``, ``"time column"``, ``"user"`` or ``"default"``.
    units : dict of str to str
        Channel name to signal unit (``"deg/s"``, ``"g"``, ...), ``""`` when unknown.
    source : str
        The path as given to :func:`load_log`.
    wv : dict of str to WaveletVariance
        Precomputed WV per channel (summary files only).
    meta : dict
        Format, file attributes (sensor, description, n_samples, ...) and ``notes``.
    """

    channels: dict[str, np.ndarray]
    fs: float
    fs_source: str = "default"
    units: dict[str, str] = field(default_factory=dict)
    source: str = ""
    wv: dict[str, WaveletVariance] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def is_summary(self) -> bool:
        """True for a wavelet-variance summary file (``wv`` set, no raw samples)."""
        return bool(self.wv) and not self.channels

    @property
    def names(self) -> list[str]:
        """Channel names: raw channels, or the WV channels of a summary file."""
        return list(self.wv) if self.is_summary else list(self.channels)

    @property
    def n(self) -> int:
        """Samples per channel (for summaries: length of the underlying raw log)."""
        if self.is_summary:
            return int(next(iter(self.wv.values())).n)
        return int(next(iter(self.channels.values())).size) if self.channels else 0

    @property
    def duration_s(self) -> float:
        """Length of the log in seconds, ``n / fs``."""
        return self.n / self.fs

    def __getitem__(self, name: str | int) -> np.ndarray:
        if self.is_summary:
            raise LoadError(
                f"file '{self.source}' is a wavelet-variance summary without raw samples: "
                f"use log.wv[name] (channels: {', '.join(self.names)})"
            )
        return self.channels[_pick(self.source, self.names, name)]

    def __repr__(self) -> str:
        what = "WV summary" if self.is_summary else "log"
        return (
            f"ImuLog({what} '{self.source}': {len(self.names)} channel(s) "
            f"[{', '.join(self.names)}] x {self.n} samples at {self.fs:g} Hz ({self.fs_source}))"
        )


# ----------------------------------------------------------------------------- helpers
def _attr(v: Any) -> Any:
    """HDF5/NumPy attribute value as a plain Python value (None when not worth showing)."""
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.generic):
        return _attr(v.item())
    if isinstance(v, np.ndarray):
        return [_attr(x) for x in v.tolist()] if v.size <= 64 else None
    return v


def _unit(u: Any) -> str:
    u = str(_attr(u)).strip() if u is not None else ""
    return "" if u.lower() in _NO_UNIT else u


def _units_map(v: Any, src: str, notes: list[str]) -> dict[str, str]:
    """Parse a JSON ``units`` map (``{"gyro_x": "deg/s", ...}``); ignore it when malformed."""
    v = _attr(v)
    if isinstance(v, str):
        try:
            v = json.loads(v)
        except json.JSONDecodeError:
            notes.append(f"the 'units' attribute of '{src}' is not a JSON map; units ignored")
            return {}
    return {str(k): _unit(x) for k, x in v.items()} if isinstance(v, dict) else {}


def _time_div(name: str, unit: str = "") -> tuple[float, bool] | None:
    """(divisor to seconds, explicit) if ``name`` names a time column, else None."""
    m = _TIME_RE.fullmatch(name.strip().lower())
    if m is None:
        return None
    suffix = m.group(2) or m.group(3) or unit.strip().lower()
    return _TIME_DIV.get(suffix, 1.0), suffix in _TIME_DIV


def _check_fs(value: Any, src: str, what: str, fix: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not math.isfinite(v) or v <= 0:
        raise LoadError(
            f"file '{src}': {what} = {value!r} is not a valid sampling frequency "
            f"(it must be a finite number of Hz > 0): {fix}"
        )
    return v


def _pick(src: str, names: list[str], channel: str | int) -> str:
    """Resolve ``channel`` (name, index, or digit string) against ``names``."""
    shown = ", ".join(names[:50]) + (", ..." if len(names) > 50 else "")
    if isinstance(channel, str) and channel in names:
        return channel
    if isinstance(channel, str) and channel.strip().lstrip("-").isdigit():
        channel = int(channel)
    if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool):
        if -len(names) <= int(channel) < len(names):
            return names[int(channel)]
        raise LoadError(
            f"file '{src}': channel index {int(channel)} is out of range; the file has "
            f"{len(names)} channel(s) (indices 0..{len(names) - 1}): {shown}"
        )
    raise LoadError(
        f"file '{src}' has no channel {channel!r}; available channels: {shown}. "
        "Pass one of these names or an integer index"
    )


def _ordered(names: list[str], units: Mapping[str, str]) -> list[str]:
    """Names in the order of the file's ``units`` map first (gyro_x..accel_z), then as found."""
    first = [k for k in units if k in names]
    return first + [k for k in names if k not in first]


def _where(i: int, rows: np.ndarray | None) -> str:
    return f"line {int(rows[i])} (sample {i})" if rows is not None else f"sample {i}"


def _as_float(src: str, name: str, a: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
    """Float64 (float32 kept) contiguous copy, rejecting non-numeric data and NaN/Inf."""
    a = np.asarray(a)
    if a.dtype.kind in "iub" or (a.dtype.kind == "f" and a.dtype.itemsize > 8):
        a = a.astype(np.float64)
    elif a.dtype == np.float16:
        a = a.astype(np.float32)
    elif a.dtype.kind != "f":
        raise LoadError(
            f"file '{src}', column '{name}': dtype {a.dtype} is not real-valued numeric data: "
            "store the samples as integers or floats"
        )
    # NaN and Inf propagate to the extremes: two passes, no temporaries, for clean data
    finite = a.size == 0 or (math.isfinite(float(np.min(a))) and math.isfinite(float(np.max(a))))
    bad = np.flatnonzero(~np.isfinite(a)) if not finite else np.empty(0, dtype=np.intp)
    if bad.size:
        raise LoadError(
            f"file '{src}': column '{name}' has {bad.size} NaN/Inf value(s), first at "
            f"{_where(int(bad[0]), rows)}: remove or interpolate them"
        )
    return np.ascontiguousarray(a)


@dataclass(frozen=True)
class _Opts:
    """Loader options shared by every reader (see :func:`load_log`)."""

    fs_user: float | None = None
    segment: str | tuple[int, int] | None = None
    scale: float | Mapping[str, float] | None = None
    units: str | Mapping[str, str] | None = None
    topic: str | None = None


_SEGMENT_HELP = (
    "choose segment='longest' (CLI: --segment longest) to analyse the longest "
    "clean segment, segment=(start, stop) for another one, or segment='report' to "
    "keep every sample as if uniformly spaced (samples joined across the breaks); "
    "or fix the log, or pass fs= to ignore the time column"
)


def _time_scale(name: str, t: np.ndarray, div: tuple[float, bool], notes: list[str]) -> float:
    """Divisor of the stamps to seconds; unitless stamps with huge steps are nanoseconds."""
    scale, explicit = div
    if explicit:
        return scale
    with np.errstate(invalid="ignore"):
        d = np.diff(np.asarray(t[: min(t.size, 100_001)], dtype=np.float64))
    pos = d[d > 0]
    med = float(np.median(pos)) if pos.size else 0.0
    if med > 1e5:
        notes.append(
            f"time column '{name}' has a median step of {med:g}: read as nanoseconds "
            "(name it time_s, time_ms or time_ns, or pass fs=, to be explicit)"
        )
        return 1e9
    return scale


def _check_scale(src: str, scale: Any, names: list[str]) -> dict[str, float]:
    """Per-channel scale factors from a number or a {channel: factor} mapping."""

    def num(v: Any, what: str) -> float:
        try:
            f = float(v)
        except (TypeError, ValueError):
            f = math.nan
        if isinstance(v, bool) or not math.isfinite(f) or f == 0:
            raise LoadError(
                f"file '{src}': {what} = {v!r} is not a valid scale factor (a finite, "
                "non-zero number of units per count, e.g. scale=0.05)"
            )
        return f

    if isinstance(scale, Mapping):
        unknown = [k for k in scale if k not in names]
        if unknown:
            raise LoadError(
                f"file '{src}': scale given for unknown channel(s) {unknown}; "
                f"channels: {', '.join(names)}"
            )
        return {str(k): num(v, f"scale[{k!r}]") for k, v in scale.items()}
    s = num(scale, "scale")
    return dict.fromkeys(names, s)


def _apply_time(
    src: str,
    cols: dict[str, Any],
    n: int,
    time: tuple[str, np.ndarray, tuple[float, bool]],
    rows: np.ndarray | None,
    opts: _Opts,
    notes: list[str],
    meta: dict[str, Any],
) -> tuple[dict[str, Any], np.ndarray | None, float]:
    """Check the time column, apply the segment policy; return (cols, rows, fs of the stamps)."""
    from .timecheck import check_time, segment_fs

    name, t, div = time
    scale = _time_scale(name, t, div, notes)
    rep = check_time(t, scale=scale, rows=rows, column=name)
    meta["time_report"] = rep.to_dict()
    policy = opts.segment
    if policy is None:
        policy = "report" if opts.fs_user is not None else "stop"
    if isinstance(policy, str) and policy not in ("stop", "longest", "report"):
        raise LoadError(
            f"file '{src}': segment={policy!r} is not a choice: use 'stop', "
            "'longest', 'report' or a (start, stop) pair of sample indices"
        )
    if rep.jitter > 0.01:
        notes.append(
            f"time column '{name}' jitters: the regular steps vary by "
            f"{100 * rep.jitter:.3g} % (relative std); samples are treated as "
            "uniformly spaced"
        )
    ts = None
    if not isinstance(policy, str):
        a, b = _segment_range(src, policy, n)
        inside = [
            e for e in rep.events if a < e.index < b or (e.kind == "invalid" and a <= e.index < b)
        ]
        if inside:
            raise LoadError(
                f"file '{src}': segment=({a}, {b}) is not clean: "
                f"{inside[0].describe()}; clean segments are listed in the time "
                "report (segment='report' keeps every sample)"
            )
        sel = (a, b)
    elif rep.ok or policy == "report":
        sel = (0, n)
        if not rep.ok:
            notes.append(
                f"{rep.message()}; segment='report': every sample kept as if "
                "uniformly spaced (samples joined across the breaks)"
            )
    elif policy == "longest":
        sel = rep.longest
        notes.append(
            f"{rep.message()}; segment='longest': samples {sel[0]} to {sel[1] - 1} "
            "analysed, the rest dropped"
        )
    else:
        raise LoadError(f"file '{src}': {rep.message()}. To go on, {_SEGMENT_HELP}")
    if sel != (0, n):
        cols = {k: _slice(v, *sel) for k, v in cols.items()}
        rows = None if rows is None else rows[sel[0] : sel[1]]
        meta["segment"] = [int(sel[0]), int(sel[1])]
        ts = np.asarray(t[sel[0] : sel[1]])
    if rep.ok or sel != (0, n):
        from .timecheck import as_seconds

        fs = segment_fs(as_seconds(ts if ts is not None else t, scale))
    else:  # report mode across breaks: the median step
        fs = float(f"{1.0 / rep.median_step:.12g}") if rep.median_step > 0 else math.nan
    return cols, rows, fs


def _check_magnitude(src: str, name: str, x: np.ndarray) -> None:
    """Refuse samples so large that the squares in a variance overflow float64."""
    if x.size and x.dtype.itemsize == 8:
        big = max(float(np.max(x)), -float(np.min(x)))  # no |x| temporary
        if big * x.size > 1e150:
            raise LoadError(
                f"file '{src}', column '{name}': values up to {big:.3g} are too large "
                "for a variance in float64 (their squares overflow): check the units "
                "or the scale factor"
            )


def _segment_range(src: str, segment: Any, n: int) -> tuple[int, int]:
    """Validate an explicit ``segment=(start, stop)``."""
    try:
        a, b = (int(v) for v in segment)
    except (TypeError, ValueError):
        raise LoadError(
            f"file '{src}': segment={segment!r} is not a (start, stop) pair of sample indices"
        ) from None
    if not 0 <= a < b <= n:
        raise LoadError(
            f"file '{src}': segment=({a}, {b}) is outside the log's samples "
            f"0..{n}: give 0 <= start < stop <= {n}"
        )
    return a, b


def _slice(a: Any, start: int, stop: int) -> Any:
    if callable(a):
        return lambda: a()[start:stop]
    return a[start:stop]


def _length(a: Any) -> int:
    shape = getattr(a, "shape", None)
    if shape is not None and len(shape) >= 1:
        return int(shape[0])
    return int(np.asarray(a() if callable(a) else a).shape[0])


def _finish(
    src: str,
    cols: dict[str, Any],
    units: Mapping[str, str],
    *,
    fmt: str,
    channel: str | int | None,
    opts: _Opts,
    fs_file: tuple[Any, str] | None = None,
    time: tuple[str, np.ndarray, tuple[float, bool]] | None = None,
    rows: np.ndarray | None = None,
    meta: dict[str, Any] | None = None,
    notes: list[str] | None = None,
) -> ImuLog:
    """Select, check the time column, convert and scale the channels, resolve fs, build the log.

    ``cols`` values are arrays or zero-argument callables returning arrays (lazy HDF5 reads).
    """
    notes = notes if notes is not None else []
    meta = {"format": fmt, **(meta or {})}
    if not cols:
        raise LoadError(
            f"file '{src}' contains no numeric channel: expected 1-D numeric "
            "columns/datasets of samples"
        )
    if channel is not None:
        name = _pick(src, list(cols), channel)
        cols = {name: cols[name]}
    n = _length(next(iter(cols.values())))
    fs_time = None
    if time is not None:
        meta["time_column"] = time[0]
        if np.asarray(time[1]).shape == (n,):
            cols, rows, fs_time = _apply_time(src, cols, n, time, rows, opts, notes, meta)
        else:
            notes.append(
                f"time column '{time[0]}' has {np.asarray(time[1]).size} stamps for "
                f"{n} samples: ignored"
            )
            time = None
    if time is None and opts.segment is not None and not isinstance(opts.segment, str):
        a, b = _segment_range(src, opts.segment, n)  # a sample range, without time stamps
        cols = {k: _slice(v, a, b) for k, v in cols.items()}
        rows = None if rows is None else rows[a:b]
        meta["segment"] = [a, b]
    elif time is None and opts.segment not in (None, "stop", "longest", "report"):
        raise LoadError(
            f"file '{src}': segment={opts.segment!r} is not a choice: use 'stop', "
            "'longest', 'report' or a (start, stop) pair of sample indices"
        )
    scales = {} if opts.scale is None else _check_scale(src, opts.scale, list(cols))
    out: dict[str, np.ndarray] = {}
    for name, a in cols.items():
        x = _as_float(src, name, a() if callable(a) else a, rows)
        if name in scales:
            with np.errstate(over="ignore", invalid="ignore"):  # checked just below
                x = np.multiply(x, scales[name], dtype=np.float64)  # counts x scale: 1 rounding
            if not np.all(np.isfinite(x)):
                raise LoadError(
                    f"file '{src}', column '{name}': the scale factor "
                    f"{scales[name]:g} makes values overflow: check it"
                )
        _check_magnitude(src, name, x)
        out[name] = x
    if scales:
        meta["scale"] = {k: scales[k] for k in out if k in scales}
    n = next(iter(out.values())).size
    if n < 4:
        what = " in the selected segment" if "segment" in meta else " per channel"
        raise LoadError(
            f"file '{src}' has only {n} sample(s){what}: a wavelet variance "
            "needs at least 4 (a static log of minutes to hours is typical)"
        )
    if opts.fs_user is not None:
        fs, fs_source = opts.fs_user, "user"
    elif fs_file is not None:
        fix = "fix it in the file, or pass fs= to override it"
        fs, fs_source = _check_fs(fs_file[0], src, fs_file[1], fix), "file"
        if fs_time is not None and math.isfinite(fs_time) and abs(fs_time / fs - 1) > 0.01:
            notes.append(
                f"the time column gives {fs_time:g} Hz but {fs_file[1]} says {fs:g} Hz; "
                "the file's value is used"
            )
    elif fs_time is not None and math.isfinite(fs_time):
        fs, fs_source = fs_time, "time column"
    else:
        fs, fs_source = 1.0, "default"
        notes.append("no sampling frequency in the file: fs = 1 Hz assumed (pass fs= to set it)")
    unit_map = {k: _unit(units.get(k, "")) for k in out}
    if opts.units is not None:
        if isinstance(opts.units, Mapping):
            unknown = [k for k in opts.units if k not in out]
            if unknown:
                raise LoadError(
                    f"file '{src}': units given for unknown channel(s) {unknown}; "
                    f"channels: {', '.join(out)}"
                )
            unit_map.update({str(k): _unit(v) for k, v in opts.units.items()})
        else:
            unit_map = dict.fromkeys(out, _unit(opts.units))
    if notes:
        meta["notes"] = notes
    return ImuLog(channels=out, fs=fs, fs_source=fs_source, units=unit_map, source=src, meta=meta)


# ----------------------------------------------------------------------------- text
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


def _read_text(path: Path, src: str, channel: Any, opts: _Opts) -> ImuLog:
    text = _decode(path.read_bytes(), src)
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
            m = _UNIT_RE.fullmatch(tok)
            name, unit = (m.group(1).strip(), m.group(2)) if m else (tok.strip(), "")
            name = name or f"col{j}"
            if name in names:
                notes.append(f"duplicate column name '{name}' renamed '{name}_{j}'")
                name = f"{name}_{j}"
            names.append(name)
            units[name] = _unit(unit)
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
        div = _time_div(name, units.get(name, ""))
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
    return _finish(
        src,
        cols,
        units,
        fmt="text",
        channel=channel,
        opts=opts,
        time=time,
        rows=rows,
        meta=meta,
        notes=notes,
    )


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


# ----------------------------------------------------------------------------- npy / npz
def _columns(
    key: str, a: np.ndarray, notes: list[str], fmt: str = "{key}[{j}]"
) -> dict[str, np.ndarray]:
    """Channels of a 1-D (one channel) or 2-D (N, k) array; a (k, N) array with k < N is
    read as k rows of samples."""
    if a.ndim == 1:
        return {key: a}
    if a.shape[0] < a.shape[1]:
        notes.append(f"'{key}' has shape {a.shape}: read as {a.shape[0]} channels in rows")
        a = a.T
    return {fmt.format(key=key, j=j): a[:, j] for j in range(a.shape[1])}


def _read_npy(path: Path, src: str, channel: Any, opts: _Opts) -> ImuLog:
    try:
        a = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise LoadError(
            f"file '{src}' is not a readable .npy array of numbers ({exc}): "
            "re-save it with numpy.save(path, array)"
        ) from exc
    notes: list[str] = []
    time = None
    if a.dtype.names and a.ndim == 1:  # structured array: one channel per field
        cols = {}
        for name in a.dtype.names:
            div = _time_div(name)
            if div is not None and a[name].ndim == 1:
                time = time or (name, a[name], div)
            else:
                cols.update(_columns(name, a[name], notes))
    elif a.ndim in (1, 2) and not a.dtype.names:
        cols = {"x": a} if a.ndim == 1 else _columns("array", a, notes, "col{j}")
    else:
        raise LoadError(
            f"file '{src}': array of shape {a.shape} is not 1-D (N,) or 2-D (N, k): "
            "save one column per channel"
        )
    return _finish(src, cols, {}, fmt="npy", channel=channel, opts=opts, time=time, notes=notes)


def _read_npz(path: Path, src: str, channel: Any, opts: _Opts) -> ImuLog:
    cols: dict[str, np.ndarray] = {}
    notes: list[str] = []
    meta: dict[str, Any] = {}
    units: dict[str, str] = {}
    fs_file = time = None
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise LoadError(
            f"file '{src}' is not a readable .npz archive ({exc}): re-save it with "
            "numpy.savez(path, gyro_x=..., fs=100.0)"
        ) from exc
    with z:
        for key in z.files:
            try:
                a = z[key]
            except ValueError:
                notes.append(f"key '{key}' holds Python objects and was skipped")
                continue
            if key.lower() in ("fs", "fs_hz", "sample_rate") and a.size == 1:
                fs_file = (a.item(), f"key '{key}'")
            elif key == "units" and a.dtype.kind in "US" and a.size == 1:
                units = _units_map(str(a.item()), src, notes)
            elif a.dtype.kind in "iufb" and a.ndim == 1 and _time_div(key) is not None:
                time = time or (key, a, _time_div(key))
            elif a.dtype.kind in "iufb" and a.ndim in (1, 2) and a.size > 1:
                cols.update(_columns(key, a, notes))
            elif a.ndim == 0:
                meta[key] = _attr(a.item())
            else:
                notes.append(f"key '{key}' (shape {a.shape}, dtype {a.dtype}) was skipped")
    return _finish(
        src,
        cols,
        units,
        fmt="npz",
        channel=channel,
        opts=opts,
        fs_file=fs_file,
        time=time,
        meta=meta,
        notes=notes,
    )


# ----------------------------------------------------------------------------- hdf5
def _read_h5(path: Path, src: str, channel: Any, opts: _Opts) -> ImuLog:
    import h5py  # lazily: 0.1 s to import, not needed for text and NPY logs

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise LoadError(
            f"file '{src}' is not a readable HDF5 file ({exc}): check that it is "
            "complete and really HDF5 (or fix its extension)"
        ) from exc
    with f:
        notes: list[str] = []
        attrs = {k: _attr(v) for k, v in f.attrs.items()}
        units = _units_map(attrs.pop("units", None), src, notes)
        meta = {k: v for k, v in attrs.items() if v is not None}
        fs_file = next(((attrs[k], f"attribute '{k}'") for k in _FS_KEYS if k in attrs), None)
        if str(attrs.get("kind", "")) in _SUMMARY_KINDS or isinstance(f.get("wv"), h5py.Group):
            if opts.scale is not None:
                raise LoadError(
                    f"file '{src}' is a wavelet-variance summary: scale= applies to "
                    "raw samples (counts); load the raw log instead"
                )
            return _read_summary(f, src, channel, opts.fs_user, fs_file, units, meta, notes)
        found: dict[str, tuple[int, Callable[[], np.ndarray], h5py.Dataset]] = {}
        times: list[tuple[str, h5py.Dataset, tuple[float, bool]]] = []
        scalar_fs: list[tuple[Any, str]] = []

        def visit(name: str, obj: Any) -> None:
            if not isinstance(obj, h5py.Dataset) or obj.dtype.kind not in "iufb":
                return
            unit = _unit(obj.attrs.get("units", obj.attrs.get("unit", "")))
            div = _time_div(name.rsplit("/", 1)[-1], unit)
            if obj.ndim == 1 and div is not None:
                times.append((name, obj, div))
            elif obj.ndim == 1 and obj.size > 1:
                found[name] = (obj.shape[0], lambda: obj[...], obj)
                units[name] = unit or units.get(name, "")
            elif obj.ndim == 2 and obj.size > 1:
                rows_first = obj.shape[0] < obj.shape[1]  # (k, N): channels in rows
                for j in range(obj.shape[1 - int(rows_first)]):
                    found[f"{name}[{j}]"] = (
                        obj.shape[int(rows_first)],
                        (lambda j=j: obj[j, :]) if rows_first else (lambda j=j: obj[:, j]),
                        obj,
                    )
                    units[f"{name}[{j}]"] = unit or units.get(f"{name}[{j}]", "")
            elif obj.ndim == 0 and name.lower() in _FS_KEYS:
                scalar_fs.append((_attr(obj[()]), f"dataset '{name}'"))
            elif obj.ndim > 2:
                notes.append(f"dataset '{name}' of shape {obj.shape} skipped (not 1-D or 2-D)")

        f.visititems(visit)
        fs_file = fs_file or (scalar_fs[0] if scalar_fs else None)
        names = _ordered(list(found), units)
        if channel is not None:
            names = [_pick(src, names, channel)]
        elif names:
            n_max = max(found[k][0] for k in names)
            other = [k for k in names if found[k][0] != n_max]
            if other:
                notes.append(
                    f"datasets of another length skipped (select them with channel=): "
                    f"{', '.join(other)}"
                )
            names = [k for k in names if found[k][0] == n_max]
        for k in names if fs_file is None else []:
            ds_attrs = found[k][2].attrs
            key = next((a for a in _FS_KEYS if a in ds_attrs), None)
            if key is not None:
                fs_file = (_attr(ds_attrs[key]), f"attribute '{key}' of dataset '{k}'")
                break
        n = found[names[0]][0] if names else 0
        time = next(((nm, ds[...], div) for nm, ds, div in times if ds.shape[0] == n), None)
        cols: dict[str, Any] = {}
        for k in names:
            try:
                cols[k] = found[k][1]()
            except (OSError, ValueError) as exc:
                raise LoadError(
                    f"file '{src}', dataset '{k}' could not be read ({exc}): the file "
                    "may be truncated or corrupt; re-export it"
                ) from exc
    return _finish(
        src,
        cols,
        units,
        fmt="hdf5",
        channel=None,
        opts=opts,
        fs_file=fs_file,
        time=time,
        meta=meta,
        notes=notes,
    )


def _read_summary(
    f: h5py.File,
    src: str,
    channel: Any,
    fs_user: float | None,
    fs_file: tuple[Any, str] | None,
    units: dict[str, str],
    meta: dict[str, Any],
    notes: list[str],
) -> ImuLog:
    """WV summary (``derived/`` schema): one WaveletVariance per ``/wv/<channel>`` group."""
    import h5py

    g = f.get("wv")
    names = [k for k in g if isinstance(g[k], h5py.Group)] if isinstance(g, h5py.Group) else []
    if not names:
        raise LoadError(
            f"file '{src}' is marked as a wavelet-variance summary but has no "
            "/wv/<channel> group: add them, or set the 'kind' attribute to 'raw'"
        )
    names = _ordered(names, units)
    if channel is not None:
        names = [_pick(src, names, channel)]
    if "n_samples" not in meta:
        raise LoadError(
            f"file '{src}': attribute 'n_samples' (length of the underlying raw log) "
            "is missing: add it to the file attributes"
        )
    n = int(meta["n_samples"])
    if fs_user is not None:
        fs, fs_source = fs_user, "user"
    elif fs_file is not None:
        fix = "fix it in the file, or pass fs= to override it"
        fs, fs_source = _check_fs(fs_file[0], src, fs_file[1], fix), "file"
    else:
        fs, fs_source = 1.0, "default"
        notes.append("no sampling frequency in the file: fs = 1 Hz assumed (pass fs= to set it)")
    wv: dict[str, WaveletVariance] = {}
    for ch in names:
        grp = g[ch]
        if not isinstance(grp.get("variance"), h5py.Dataset):
            raise LoadError(
                f"file '{src}': dataset 'wv/{ch}/variance' is missing: each "
                "/wv/<channel> group needs the wavelet variance at levels 1..J"
            )
        v = np.asarray(grp["variance"][...], dtype=np.float64)
        ci = [
            np.asarray(grp[c][...], dtype=np.float64) if c in grp else None
            for c in ("ci_low", "ci_high")
        ]
        parts = {"ci_low": ci[0], "ci_high": ci[1], "tau_samples": grp.get("tau_samples")}
        for c, a in parts.items():
            if a is not None and a.shape != v.shape:
                raise LoadError(
                    f"file '{src}': dataset 'wv/{ch}/{c}' has shape {a.shape}, but "
                    f"'wv/{ch}/variance' has {v.shape}: they must match level by level"
                )
        if "tau_samples" in grp and not np.array_equal(
            grp["tau_samples"][...], 2 ** np.arange(1, v.size + 1)
        ):
            raise LoadError(
                f"file '{src}': dataset 'wv/{ch}/tau_samples' is not 2, 4, 8, ...: "
                "the variance must start at level 1 (tau = 2 samples), one per level"
            )
        try:
            wv[ch] = WaveletVariance.from_arrays(
                v,
                n=n,
                fs=fs,
                ci_low=ci[0],
                ci_high=ci[1],
                alpha=float(_attr(grp.attrs.get("ci_alpha", 0.05))),
                robust=bool(_attr(grp.attrs.get("robust", False))),
                unit=units.get(ch, ""),
            )
        except ValueError as exc:
            raise LoadError(
                f"file '{src}', dataset 'wv/{ch}/variance': {exc}: fix the stored values"
            ) from exc
    meta = {"format": "hdf5-wv-summary", **meta, **({"notes": notes} if notes else {})}
    return ImuLog(
        channels={},
        fs=fs,
        fs_source=fs_source,
        units={k: units.get(k, "") for k in wv},
        source=src,
        wv=wv,
        meta=meta,
    )


# ----------------------------------------------------------------------------- public API
def load_log(
    path: str | os.PathLike[str],
    *,
    channel: str | int | None = None,
    fs: float | None = None,
    segment: str | tuple[int, int] | None = None,
    scale: float | Mapping[str, float] | None = None,
    units: str | Mapping[str, str] | None = None,
    topic: str | None = None,
) -> ImuLog:
    """Load a static IMU log (or a wavelet-variance summary file).

    Parameters
    ----------
    path : str or path-like
        CSV/TSV/whitespace text (``.csv .tsv .txt .dat`` or any unknown extension), ``.npy``,
        ``.npz``, HDF5 (``.h5 .hdf5``), or a ROS bag with ``sensor_msgs/Imu`` messages: ROS 1
        ``.bag``, ROS 2 bag directory (with ``metadata.yaml``), ``.db3`` or ``.mcap``. The
        content's magic bytes win over the extension.
    channel : str or int, optional
        Keep only this channel (name, or index into :attr:`ImuLog.names`).
    fs : float, optional
        Sampling frequency in Hz; overrides the file (``fs_source == "user"``). The time
        column, if any, is still checked and its report kept (``segment`` then defaults to
        ``"report"``).
    segment : {"stop", "longest", "report"} or (start, stop), optional
        What to do when the time column has gaps, duplicate or backward stamps (see
        :mod:`engine.timecheck`): ``"stop"`` (the default without ``fs``) raises a
        :class:`LoadError` saying what was found, where, and how to choose; ``"longest"``
        keeps the longest clean segment; ``"report"`` keeps every sample as if uniformly
        spaced; ``(start, stop)`` keeps those samples (0-based, stop excluded), which must be
        clean (without a time column it simply selects a sample range). Samples are never
        joined across a break without a note in ``meta["notes"]``.
        The report is in ``meta["time_report"]`` (a dict, see ``TimeReport.to_dict``), the
        kept range in ``meta["segment"]``.
    scale : float or mapping of str to float, optional
        Scale factor (units per count) for raw integer counts or scaled floats, for every
        channel or per channel (``{"gyro_x": 0.05}``): samples become ``float64(x) * scale``
        (exact for integer counts: one correctly rounded product). ``meta["scale"]`` records it.
    units : str or mapping of str to str, optional
        Signal unit of every channel, or per channel; overrides the file (e.g. after scaling
        counts: ``scale=0.05, units="deg/s"``).
    topic : str, optional
        ROS bags: the ``sensor_msgs/Imu`` topic, when the bag has several.

    Returns
    -------
    ImuLog
        Raw channels with ``fs`` and units (float64; float32 files stay float32 unless
        scaled), or ``wv`` for summary files.

    Raises
    ------
    LoadError
        Missing/empty/binary/malformed file, non-numbers, ragged rows, NaN/Inf samples,
        fewer than 4 samples, unknown channel, invalid ``fs`` or ``scale``, a time column
        with gaps under ``segment="stop"``.
    """
    src = str(path)
    p = Path(path)
    fs_user = None if fs is None else _check_fs(fs, src, "fs", "pass fs in Hz, e.g. fs=100")
    opts = _Opts(fs_user=fs_user, segment=segment, scale=scale, units=units, topic=topic)
    if not p.exists():
        raise LoadError(f"no such file: '{src}' (check the path)")
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return _guarded(_read_bag, p, src, channel, opts, "bag")
        raise LoadError(
            f"'{src}' is a directory, not a log file: pass the path of a file "
            "(or of a ROS 2 bag directory with a metadata.yaml)"
        )
    try:
        with open(p, "rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise LoadError(f"cannot read file '{src}' ({exc.strerror}): check permissions") from exc
    if not head:
        raise LoadError(f"file '{src}' is empty (0 bytes): check that the logger wrote data")
    fmt = next((v for k, v in _MAGIC.items() if head.startswith(k)), None)
    ext = p.suffix.lower()
    fmt = fmt or (
        "hdf5"
        if ext in _H5_EXT
        else ext[1:]
        if ext in (".npy", ".npz")
        else "bag"
        if ext in (".bag", ".db3", ".mcap")
        else "text"
    )
    reader = {
        "hdf5": _read_h5,
        "npy": _read_npy,
        "npz": _read_npz,
        "text": _read_text,
        "bag": _read_bag,
    }[fmt]
    return _guarded(reader, p, src, channel, opts, fmt)


_CORRUPT = (
    OSError,
    RuntimeError,
    KeyError,
    IndexError,
    TypeError,
    ValueError,
    AttributeError,
    EOFError,
    OverflowError,
    UnicodeError,
    zipfile.BadZipFile,
    zlib.error,
    struct.error,
)


def _guarded(
    reader: Callable[..., ImuLog], p: Path, src: str, channel: Any, opts: _Opts, fmt: str
) -> ImuLog:
    """Run a reader; a library error on damaged content becomes a LoadError (with its type, so
    that the cause stays visible)."""
    try:
        return reader(p, src, channel, opts)
    except LoadError:
        raise
    except _CORRUPT as exc:
        what = {"text": "text", "npy": ".npy", "npz": ".npz", "hdf5": "HDF5", "bag": "ROS bag"}
        raise LoadError(
            f"file '{src}' could not be read as {what.get(fmt, fmt)} "
            f"({type(exc).__name__}: {' '.join(str(exc).split())[:200]}): it may be "
            "truncated or corrupt; check it or export it again"
        ) from exc


def _read_bag(path: Path, src: str, channel: Any, opts: _Opts) -> ImuLog:
    """ROS 1/2 bag with sensor_msgs/Imu messages (see :mod:`engine.rosbag`)."""
    from .rosbag import read_imu_bag

    bag = read_imu_bag(path, topic=opts.topic, src=src)
    return _finish(
        src,
        bag.channels,
        bag.units,
        fmt=bag.format,
        channel=channel,
        opts=opts,
        time=(bag.stamp_source, bag.stamps_ns, (1e9, True)),
        meta=bag.meta,
        notes=list(bag.notes),
    )


def save_log(
    path: str | os.PathLike[str],
    channels: Mapping[str, np.ndarray],
    fs: float,
    units: Mapping[str, str] | None = None,
    attrs: Mapping[str, Any] | None = None,
) -> Path:
    """Write channels to HDF5 (raw layout of ``shared/data``), ``.npy`` or ``.csv``.

    Parameters
    ----------
    path : str or path-like
        Output file; the extension picks the format: ``.h5``/``.hdf5`` (gzip-compressed root
        datasets, file attributes ``fs_hz``, ``n_samples``, ``duration_s``, ``units`` (JSON),
        ``kind="raw"``, ``schema_version="1"``, per-dataset ``units``), ``.npy`` (1-D for one
        channel, else (N, k); names, fs and units are not stored) or ``.csv`` (header
        ``time,name [unit],...``, time = i / fs, 17 significant digits: exact round trip).
    channels : mapping of str to array_like
        Channel name to 1-D numeric samples, all of the same length.
    fs : float
        Sampling frequency (Hz), > 0.
    units : mapping of str to str, optional
        Channel name to signal unit.
    attrs : mapping, optional
        Extra HDF5 file attributes (``sensor``, ``description``, ...); dicts and lists are
        stored as JSON. Ignored for ``.npy``/``.csv``.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ValueError
        Unknown extension, no channels, non-1-D/non-numeric/unequal channels, invalid fs,
        names unusable in the format, or an extra attribute clashing with a reserved one.
    """
    import h5py  # lazily: 0.1 s to import, not needed for text and NPY logs

    p = Path(path)
    ext = p.suffix.lower()
    fs = _check_fs(fs, str(p), "fs", "pass the sampling frequency in Hz")
    if ext not in _H5_EXT | {".npy", ".csv"}:
        raise ValueError(f"cannot save '{p}': unknown extension {ext!r} (use .h5, .npy or .csv)")
    if not channels:
        raise ValueError(f"cannot save '{p}': no channels given")
    arrs = {str(k): np.asarray(v) for k, v in channels.items()}
    n = next(iter(arrs.values())).size
    for k, a in arrs.items():
        if a.ndim != 1 or a.dtype.kind not in "iuf" or a.size != n or not n or not k:
            raise ValueError(
                f"cannot save '{p}': channel {k!r} must have a non-empty name and be "
                f"1-D numeric with {n} samples (got shape {a.shape}, {a.dtype})"
            )
    unit = {k: _unit((units or {}).get(k, "")) for k in arrs}
    extra = dict(attrs or {})
    if ext != ".npy" and (timelike := [k for k in arrs if _time_div(k.rsplit("/")[-1])]):
        raise ValueError(
            f"cannot save '{p}': channel names {timelike} would be read back as a "
            "time column; rename them"
        )
    if clash := sorted(_RESERVED & set(extra)):
        raise ValueError(f"cannot save '{p}': attrs {clash} are written by save_log itself")
    if ext in _H5_EXT:
        with h5py.File(p, "w") as f:
            for k, a in arrs.items():
                ds = f.create_dataset(k, data=a, compression="gzip", chunks=(min(n, 65536),))
                ds.attrs["units"] = unit[k]
            f.attrs.update(
                {
                    "fs_hz": fs,
                    "n_samples": np.int64(n),
                    "duration_s": n / fs,
                    "units": json.dumps(unit),
                    "kind": "raw",
                    "schema_version": "1",
                }
            )
            for k, v in extra.items():
                ok = isinstance(v, (str, bytes, int, float, bool, np.generic, np.ndarray))
                f.attrs[k] = v if ok else json.dumps(v)
    elif ext == ".npy":
        a = next(iter(arrs.values())) if len(arrs) == 1 else np.column_stack(list(arrs.values()))
        np.save(p, a)
    else:
        if bad := [k for k in arrs if any(c in k for c in ',"#\n\r[(')]:
            raise ValueError(
                f"cannot save '{p}': channel names {bad} contain characters that "
                'CSV headers cannot hold (, " # [ ( or newlines)'
            )
        head = ",".join(["time"] + [f"{k} [{unit[k]}]" if unit[k] else k for k in arrs])
        data = np.column_stack([np.arange(n) / fs] + [a.astype(np.float64) for a in arrs.values()])
        np.savetxt(p, data, fmt="%.17g", delimiter=",", header=head, comments="")
    return p
