"""Checks of a log's time column: sampling frequency, gaps, duplicates, reversals and jitter.

A static IMU log is analysed as a uniformly sampled series, so the time stamps must be close
to ``t_0 + i / fs``. :func:`check_time` finds every place where they are not and splits the
log into *clean segments* (runs of samples whose steps are all regular). The loader then lets
the user choose (``load_log(..., segment=...)``): stop with a message saying what was found
(the default), analyse the longest clean segment, or keep everything with the report attached.
Samples on both sides of a gap are never joined silently.

Definitions, with ``d_i = t_{i+1} - t_i`` the steps and ``med`` the median of the positive
steps:

* **gap**: ``d_i > gap_factor * med`` (1.5 by default); about ``round(d_i / med) - 1`` samples
  are missing;
* **duplicate**: ``d_i == 0`` (the same stamp twice);
* **backward**: ``d_i < 0`` (stamps going back in time, e.g. rows out of order or a clock
  reset);
* **invalid**: a NaN/Inf stamp (the sample is dropped from every segment);
* **jitter**: relative standard deviation ``std(d) / med`` of the regular steps, reported
  (a jittery clock does not break the log; the samples are still treated as uniform).

``fs`` of a clean segment is ``(n - 1) / (t_last - t_first)`` when every step is within 1 %
of the median step (exact for printed, rounded stamps), else ``1 / med``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["TimeEvent", "TimeReport", "check_time", "segment_fs", "GAP_FACTOR"]

GAP_FACTOR = 1.5
_KINDS = ("gap", "duplicate", "backward", "invalid")
_SHOW = 5  # events listed in a message, per kind


@dataclass(frozen=True)
class TimeEvent:
    """One irregular step between samples ``index - 1`` and ``index``.

    Attributes
    ----------
    kind : {"gap", "duplicate", "backward", "invalid"}
        What happened (see the module docstring).
    index : int
        0-based index of the first sample after the break.
    time : float
        Time of the sample before the break, in seconds from the first stamp (NaN if invalid).
    step : float
        The step ``t[index] - t[index - 1]`` in seconds (NaN for an invalid stamp).
    missing : int
        Estimated number of missing samples (gaps only: ``round(step / median) - 1``).
    line : int or None
        1-based line of the sample in a text file, when known.
    """

    kind: str
    index: int
    time: float
    step: float
    missing: int = 0
    line: int | None = None

    def where(self) -> str:
        """``line 120 (sample 118, t = 1.17 s)`` or ``sample 118 (t = 1.17 s)``."""
        t = "" if not math.isfinite(self.time) else f", t = {self.time:.6g} s"
        if self.line is not None:
            return f"line {self.line} (sample {self.index}{t})"
        return f"sample {self.index}" + (f" ({t[2:]})" if t else "")

    def describe(self) -> str:
        """One phrase, e.g. ``gap of 0.25 s (24 missing samples) at sample 118 (t = 1.17 s)``."""
        if self.kind == "gap":
            return (
                f"gap of {self.step:.6g} s (about {self.missing} missing sample(s)) "
                f"at {self.where()}"
            )
        if self.kind == "duplicate":
            return f"duplicate stamp at {self.where()}"
        if self.kind == "backward":
            return f"stamp going back by {-self.step:.6g} s at {self.where()}"
        return f"NaN/Inf stamp at {self.where()}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN as None)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "kind": self.kind,
            "index": int(self.index),
            "time_s": num(self.time),
            "step_s": num(self.step),
            "missing": int(self.missing),
            "line": self.line,
        }


@dataclass(frozen=True, eq=False)
class TimeReport:
    """What :func:`check_time` found in a time column.

    Attributes
    ----------
    n : int
        Number of stamps.
    median_step : float
        Median of the positive steps (s); NaN when there is none.
    fs : float
        Sampling frequency of the longest clean segment (Hz); NaN if it has < 2 samples.
    jitter : float
        Relative standard deviation of the regular steps (``std / median``), 0 for a perfect
        clock.
    events : tuple of TimeEvent
        The irregular steps, in sample order (at most ``max_events`` per kind, see
        :func:`check_time`; ``counts`` has the totals).
    segments : ndarray of int, shape (k, 2)
        Clean segments ``[start, stop)`` (0-based sample indices), in sample order.
    counts : dict of str to int
        Number of events of each kind.
    column : str
        Name of the time column (for messages).
    """

    n: int
    median_step: float
    fs: float
    jitter: float
    events: tuple[TimeEvent, ...]
    segments: np.ndarray
    counts: dict[str, int] = field(default_factory=dict)
    column: str = "time"

    @property
    def ok(self) -> bool:
        """True when the stamps have no gap, duplicate, reversal or invalid value."""
        return not self.events

    @property
    def longest(self) -> tuple[int, int]:
        """The longest clean segment ``(start, stop)`` (the first one on ties)."""
        if self.segments.size == 0:
            return (0, 0)
        lengths = self.segments[:, 1] - self.segments[:, 0]
        k = int(np.argmax(lengths))
        return int(self.segments[k, 0]), int(self.segments[k, 1])

    def events_of(self, kind: str) -> list[TimeEvent]:
        """Events of one kind."""
        return [e for e in self.events if e.kind == kind]

    def summary(self, *, max_events: int = _SHOW) -> str:
        """Several readable lines: fs, jitter, the events found (at most ``max_events`` per
        kind, gaps by decreasing length) and the clean segments."""
        lines = [
            f"time column '{self.column}': {self.n} stamps, median step "
            f"{self.median_step:.6g} s ({_hz(self.median_step)}), jitter "
            f"{100 * self.jitter:.3g} % (std of the regular steps / median step)"
        ]
        if self.ok:
            lines.append("no gap, duplicate or reversal: one clean segment")
            return "\n".join(lines)
        lines.append(self._found())
        for kind in _KINDS:
            ev = self.events_of(kind)
            if kind == "gap":
                ev = sorted(ev, key=lambda e: -e.step)
            for e in ev[:max_events]:
                lines.append(f"  - {e.describe()}")
            more = self.counts.get(kind, 0) - min(len(ev), max_events)
            if more > 0:
                lines.append(f"  - ... and {more} more {kind}(s)")
        a, b = self.longest
        lines.append(
            f"{len(self.segments)} clean segment(s); the longest is samples {a} to "
            f"{b - 1} ({b - a} samples, {100 * (b - a) / max(self.n, 1):.3g} % of the "
            f"log, {self.fs:.6g} Hz)"
        )
        return "\n".join(lines)

    def _found(self) -> str:
        parts = []
        for kind in _KINDS:
            k = self.counts.get(kind, 0)
            if k:
                what = {
                    "gap": "gap(s)",
                    "duplicate": "duplicate stamp(s)",
                    "backward": "backward step(s)",
                    "invalid": "NaN/Inf stamp(s)",
                }[kind]
                parts.append(f"{k} {what}")
        return "found " + ", ".join(parts)

    def message(self) -> str:
        """One paragraph for an error: what was found, where, and how to choose."""
        where = []
        for kind in _KINDS:  # the first event of each kind, and the largest gap
            ev = self.events_of(kind)
            if ev:
                where.append(f"first {ev[0].describe()}")
            if kind == "gap" and len(ev) > 1:
                big = max(ev, key=lambda e: e.step)
                if big is not ev[0]:
                    where.append(f"largest {big.describe()}")
        a, b = self.longest
        return (
            f"time column '{self.column}' is not uniformly sampled: {self._found()} "
            f"({'; '.join(where)}). The longest clean segment is samples {a} to {b - 1} "
            f"({b - a} of {self.n} samples, {self.fs:.6g} Hz)"
        )

    def to_dict(self, *, max_events: int = 100) -> dict[str, Any]:
        """JSON-ready dictionary; lists at most ``max_events`` events (``events_truncated``)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        a, b = self.longest
        return {
            "column": self.column,
            "n": int(self.n),
            "ok": self.ok,
            "median_step_s": num(self.median_step),
            "fs": num(self.fs),
            "jitter": num(self.jitter),
            "counts": dict(self.counts),
            "events": [e.to_dict() for e in self.events[:max_events]],
            "events_truncated": sum(self.counts.values()) > min(len(self.events), max_events),
            "n_segments": int(len(self.segments)),
            "segments": [[int(s), int(e)] for s, e in self.segments[:max_events]],
            "longest": [a, b],
        }


def _hz(step: float) -> str:
    return f"{1 / step:.6g} Hz" if step > 0 and math.isfinite(step) else "no rate"


def segment_fs(t: np.ndarray, start: int = 0, stop: int | None = None) -> float:
    """Sampling frequency (Hz) of the stamps ``t[start:stop]`` (seconds), assumed clean.

    ``(n - 1) / span`` when every step is within 1 % of the median step, else
    ``1 / median step``; rounded to 12 significant digits (printed stamps carry last-digit
    noise). NaN for fewer than 2 samples and when the steps are too small to give a finite
    rate.
    """
    seg = np.asarray(t[start:stop], dtype=np.float64)
    if seg.size < 2:
        return math.nan
    d = np.diff(seg)
    med = float(np.median(d))
    if not med > 0:
        return math.nan
    uniform = bool(np.all(np.abs(d - med) <= 0.01 * med))
    with np.errstate(over="ignore", divide="ignore"):  # steps of ~1e-308 s: no usable rate
        fs = (seg.size - 1) / (seg[-1] - seg[0]) if uniform else 1.0 / med
    return float(f"{fs:.12g}") if math.isfinite(fs) else math.nan


def as_seconds(t: Any, scale: float = 1.0) -> np.ndarray:
    """Stamps as float64 seconds relative to the first finite stamp.

    Integer stamps (e.g. nanoseconds since 1970) are shifted in integer arithmetic before
    the conversion, so no resolution is lost; ``scale`` divides (1e9 for ns).
    """
    a = np.asarray(t)
    if a.ndim != 1:
        raise ValueError(f"time stamps must be one-dimensional, got shape {a.shape}")
    if a.size == 0:
        return np.zeros(0)
    if a.dtype.kind in "iu":
        return (a.astype(np.int64) - np.int64(a[0])).astype(np.float64) / scale
    if a.dtype.kind not in "fb":
        raise ValueError(f"time stamps must be numbers, got dtype {a.dtype}")
    a = a.astype(np.float64, copy=False)
    fin = np.isfinite(a)
    t0 = a[int(fin.argmax())] if fin.any() else 0.0  # the first finite stamp
    del fin
    out = a - t0  # in place below: one N-sized array (a long log's stamps are 100s of MB)
    if scale != 1:
        out /= scale
    return out


def _std_in_place(x: np.ndarray) -> float:
    """``np.std(x)`` (the same operations: mean, deviations, squares, their mean) computed in
    ``x`` itself, which it overwrites: no N-sized temporary."""
    mean = x.mean()
    np.subtract(x, mean, out=x)
    np.multiply(x, x, out=x)
    return math.sqrt(x.sum() / x.size)


def check_time(
    t: Any,
    *,
    scale: float = 1.0,
    gap_factor: float = GAP_FACTOR,
    rows: np.ndarray | None = None,
    column: str = "time",
    max_events: int = 1000,
) -> TimeReport:
    """Check time stamps for gaps, duplicates, reversals and jitter.

    Parameters
    ----------
    t : array_like, shape (N,)
        Stamps, in any unit (``scale`` converts to seconds); integers are handled exactly.
    scale : float
        Divisor to seconds (1 for s, 1e3 for ms, 1e9 for ns).
    gap_factor : float
        A step longer than ``gap_factor`` times the median step is a gap (> 1).
    rows : ndarray of int, optional
        1-based text line of each sample, for messages.
    column : str
        Name of the time column, for messages.
    max_events : int
        Events kept per kind (the first ones, plus the 10 longest gaps); ``counts`` always
        has the totals.

    Returns
    -------
    TimeReport

    Notes
    -----
    O(N) time and a few N-sized temporary arrays. The median step is taken over the positive
    steps only, so a few duplicates or reversals do not bias it.
    """
    if not (gap_factor > 1 and math.isfinite(gap_factor)):
        raise ValueError(f"gap_factor must be a finite number > 1, got {gap_factor}")
    if not (scale > 0 and math.isfinite(scale)):
        raise ValueError(f"scale must be a finite number > 0, got {scale}")
    ts = as_seconds(t, scale)
    n = ts.size
    with np.errstate(invalid="ignore"):
        d = np.diff(ts)
        fin = np.isfinite(ts)
        pos = d[d > 0]
        med = float(np.median(pos, overwrite_input=True)) if pos.size else math.nan  # (a copy)
        del pos
        bad_stamp = ~fin
        # classify every step (between sample i and i + 1)
        invalid = ~(fin[:-1] & fin[1:])
        backward = ~invalid & (d < 0)
        duplicate = ~invalid & (d == 0)
        gap = ~invalid & (d > gap_factor * med) if math.isfinite(med) else np.zeros_like(invalid)
    brk = invalid | backward | duplicate | gap
    regular = d[~brk]
    jitter = float(_std_in_place(regular) / med) if regular.size > 1 and med > 0 else 0.0
    del regular

    events: list[TimeEvent] = []
    counts = {k: 0 for k in _KINDS}

    def line(i: int) -> int | None:
        return int(rows[i]) if rows is not None and 0 <= i < len(rows) else None

    for i in np.flatnonzero(bad_stamp)[:max_events]:
        events.append(TimeEvent("invalid", int(i), math.nan, math.nan, 0, line(int(i))))
    for kind, mask in (("gap", gap), ("duplicate", duplicate), ("backward", backward)):
        idx = np.flatnonzero(mask)
        counts[kind] = int(idx.size)
        if idx.size > max_events:  # keep the first ones, and the longest gaps
            top = idx[np.argsort(-d[idx], kind="stable")[:10]] if kind == "gap" else idx[:0]
            idx = np.union1d(idx[:max_events], top)
        for i in idx:
            step = float(d[i])
            missing = max(int(round(step / med)) - 1, 1) if kind == "gap" else 0
            events.append(
                TimeEvent(kind, int(i) + 1, float(ts[i]), step, missing, line(int(i) + 1))
            )
    counts["invalid"] = int(bad_stamp.sum())
    events.sort(key=lambda e: (e.index, _KINDS.index(e.kind)))
    counts = {k: v for k, v in counts.items() if v}

    # clean segments: cut at every irregular step, then drop single invalid samples
    cuts = np.flatnonzero(brk) + 1
    starts = np.concatenate([[0], cuts])
    stops = np.concatenate([cuts, [n]])
    keep = stops > starts
    segs = (
        np.stack([starts[keep], stops[keep]], axis=1).astype(np.int64)
        if n
        else np.zeros((0, 2), np.int64)
    )
    if bad_stamp.any():
        segs = segs[~((segs[:, 1] - segs[:, 0] == 1) & bad_stamp[segs[:, 0]])]
    rep = TimeReport(
        n=n,
        median_step=med,
        fs=math.nan,
        jitter=jitter,
        events=tuple(events),
        segments=segs,
        counts=counts,
        column=column,
    )
    a, b = rep.longest
    object.__setattr__(rep, "fs", segment_fs(ts, a, b))
    return rep
