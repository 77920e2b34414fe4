"""Still segments of a flight log, and a log analysed on them.

:func:`still_segments` finds where the vehicle stood still (before take-off, after landing,
on the bench): the standard deviation of every channel over sliding windows (``window_s``
long, half a window apart) is compared with that channel's still floor (the 10th percentile
of its window deviations, the quietest tenth of the log). A window is moving when, for the
gyroscopes or for the accelerometers (channels named ``gyr*``/``acc*``; every channel when
the names say neither), the mean ratio exceeds ``threshold``. Every sample of a moving window
is moving; the still runs at least ``min_s`` long are the segments.

:func:`with_segments` gives the log whose :meth:`~engine.io.log.ImuLog.wavelet_variance` is
the pooled WV of the segments (:func:`engine.wv.pooled.pooled_wavelet_variance`): every
command that takes ``--segments auto|LIST`` analyses the still parts only.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from .log import ImuLog, LoadError

__all__ = ["still_segments", "with_segments", "parse_segments"]


def _window_std(x: np.ndarray, w: int, hop: int) -> np.ndarray:
    """Standard deviation of ``x[k hop : k hop + w]`` for every whole window k."""
    x = np.asarray(x, dtype=np.float64) - float(np.mean(x))
    c1 = np.concatenate([[0.0], np.cumsum(x)])
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    starts = np.arange(0, x.size - w + 1, hop)
    s1 = c1[starts + w] - c1[starts]
    s2 = c2[starts + w] - c2[starts]
    return np.sqrt(np.maximum(s2 / w - (s1 / w) ** 2, 0.0))


def still_segments(
    log: ImuLog,
    *,
    window_s: float = 1.0,
    threshold: float = 3.0,
    min_s: float = 5.0,
) -> list[tuple[int, int]]:
    """The still segments of a log, as ``(start, stop)`` sample ranges (stop excluded).

    Parameters
    ----------
    log : ImuLog
        A log with raw channels (gyroscopes and/or accelerometers).
    window_s : float
        Window length (s) of the moving standard deviation; windows are half a window apart.
    threshold : float
        A window is moving when its deviation exceeds ``threshold`` times the still floor
        (mean over the gyroscope channels, or over the accelerometer channels).
    min_s : float
        Shortest segment kept (s).

    Returns
    -------
    list of (int, int)
        In time order; empty when nothing is still for ``min_s``.

    Raises
    ------
    LoadError
        A summary file (no samples), a log shorter than two windows, bad settings.
    """
    if log.is_summary:
        raise LoadError(f"file '{log.source}' is a WV summary: still segments need raw samples")
    if not (window_s > 0 and threshold > 1 and min_s >= 0):
        raise LoadError(
            f"still segments: window_s={window_s!r} must be > 0, threshold={threshold!r} > 1 "
            f"and min_s={min_s!r} >= 0"
        )
    n, fs = log.n, log.fs
    w = max(int(round(window_s * fs)), 4)
    hop = max(w // 2, 1)
    if n < 2 * w:
        raise LoadError(
            f"file '{log.source}' has {n} samples: still segments need at least two windows "
            f"of {w} samples (window_s={window_s:g} s at {fs:g} Hz); pass a shorter window_s"
        )
    names = log.names
    groups = [[k for k in names if "gyr" in k.lower()], [k for k in names if "acc" in k.lower()]]
    groups = [g for g in groups if g] or [names]
    moving_w = np.zeros(len(range(0, n - w + 1, hop)), dtype=bool)
    for group in groups:
        ratio = np.zeros_like(moving_w, dtype=np.float64)
        for k in group:
            s = _window_std(log.channels[k], w, hop)
            floor = float(np.percentile(s, 10))
            ratio += s / (floor if floor > 0 else float(np.max(s)) or 1.0)
        moving_w |= ratio / len(group) > threshold
    moving = np.zeros(n + 1, dtype=np.int64)  # difference array of the moving windows' spans
    starts = np.flatnonzero(moving_w) * hop
    np.add.at(moving, starts, 1)
    np.add.at(moving, starts + w, -1)
    still = np.cumsum(moving[:n]) == 0
    tail = (n - w) % hop  # samples after the last whole window: as the last window
    if tail and moving_w[-1]:
        still[n - tail :] = False
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
    runs = edges.reshape(-1, 2)
    min_n = max(int(round(min_s * fs)), 4)
    return [(int(a), int(b)) for a, b in runs if b - a >= min_n]


def parse_segments(
    spec: str | Sequence[tuple[int, int]], n: int, src: str = ""
) -> str | list[tuple[int, int]]:
    """``"auto"``, or a list of ``(start, stop)`` from ``"0:5000,8000:12000"`` (samples) or
    pairs, checked against ``n`` samples."""
    if isinstance(spec, str) and spec.strip().lower() == "auto":
        return "auto"
    pairs: list[tuple[int, int]] = []
    try:
        if isinstance(spec, str):
            for part in spec.split(","):
                lo, hi = part.split(":")
                pairs.append((int(lo), int(hi)))
        else:
            pairs = [(int(a), int(b)) for a, b in spec]
    except (TypeError, ValueError):
        raise LoadError(
            f"file '{src}': segments={spec!r} is not 'auto' nor START:STOP sample ranges "
            "separated by commas (e.g. 0:5000,8000:12000)"
        ) from None
    for start, stop in pairs:
        if not 0 <= start < stop <= n or stop - start < 4:
            raise LoadError(
                f"file '{src}': segment {start}:{stop} is not inside the log's {n} samples (or has "
                "fewer than 4): give 0 <= START < STOP <= n"
            )
    return sorted(pairs)


def with_segments(
    log: ImuLog,
    segments: str | Sequence[tuple[int, int]],
    *,
    window_s: float = 1.0,
    threshold: float = 3.0,
    min_s: float = 5.0,
) -> ImuLog:
    """The log analysed on ``segments`` (``"auto"``: :func:`still_segments`): its
    :meth:`~engine.io.log.ImuLog.wavelet_variance` pools the segments' WV.

    Raises
    ------
    LoadError
        Bad ranges, or ``"auto"`` finding no still segment (the message says how to relax it).
    """
    parsed = parse_segments(segments, log.n, log.source)
    spec: list[tuple[int, int]]
    if isinstance(parsed, str):  # "auto"
        spec = still_segments(log, window_s=window_s, threshold=threshold, min_s=min_s)
        if not spec:
            raise LoadError(
                f"file '{log.source}': no still segment of {min_s:g} s or more found "
                f"(threshold {threshold:g} x the still floor): raise the threshold, shorten "
                "min_s, or give the segments as START:STOP samples"
            )
    else:
        spec = parsed
    meta = {**log.meta, "segments": [list(p) for p in spec]}
    return dataclasses.replace(log, segments=tuple((a, b) for a, b in spec), meta=meta)
