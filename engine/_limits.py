"""Limits on the work a call may ask for: the samples a simulation may hold, the memory a file
may take to load.

A simulation of ``n`` samples holds the result and one process's draw at a time, plus the
temporaries of a cumulative sum or a recursive filter: about :data:`BYTES_PER_SAMPLE` bytes
per sample and channel at its peak. :func:`check_sample_count` refuses an ``n`` whose peak
would exceed :data:`MEMORY_FRACTION` of the memory available now (``MemAvailable`` of
``/proc/meminfo``; elsewhere the physical memory), and any ``n`` above :data:`MAX_SAMPLES`
whatever the memory, so that a typo such as ``1e14`` is a one-line error, not minutes of
swapping or a MemoryError.
"""

from __future__ import annotations

import math
import operator
import os
from typing import SupportsIndex

__all__ = [
    "BYTES_PER_SAMPLE",
    "MEMORY_FRACTION",
    "MAX_SAMPLES",
    "available_memory",
    "check_memory",
    "max_samples",
    "check_sample_count",
]

#: Peak bytes per simulated sample and channel: the float64 result, one process's float64
#: draw, and the float64 temporaries of a cumulative sum or ``lfilter`` (4 x 8 bytes).
BYTES_PER_SAMPLE = 32
#: Share of the available memory a simulation may use (the rest is left to the system, to
#: writing the output and to the other processes of a shared machine).
MEMORY_FRACTION = 0.5
#: Absolute ceiling on a sample count (2^40, about 1.1e12 samples: 8.8 TB of float64).
MAX_SAMPLES = 2**40


def available_memory() -> int | None:
    """Memory (bytes) the system can give this process without swapping, or None if unknown.

    ``MemAvailable`` of ``/proc/meminfo`` (Linux: free memory plus reclaimable caches), else
    ``sysconf("SC_AVPHYS_PAGES") * sysconf("SC_PAGE_SIZE")`` (free pages only).
    """
    try:
        with open("/proc/meminfo", "rb") as f:
            for line in f:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def max_samples(channels: int = 1, copies: int = 1) -> int:
    """The largest sample count :func:`check_sample_count` accepts now.

    Parameters
    ----------
    channels : int
        Channels simulated together (each costs :data:`BYTES_PER_SAMPLE` per sample).
    copies : int
        Simulations running at once (e.g. worker processes).

    Returns
    -------
    int
        ``min(MAX_SAMPLES, MEMORY_FRACTION * available / (BYTES_PER_SAMPLE channels copies))``.
    """
    mem = available_memory()
    if mem is None:
        return MAX_SAMPLES
    per = BYTES_PER_SAMPLE * max(1, channels) * max(1, copies)
    return max(1, min(MAX_SAMPLES, int(MEMORY_FRACTION * mem // per)))


def _gb(nbytes: float) -> str:
    return f"{nbytes / 1e9:.3g} GB"


def check_sample_count(n: object, *, name: str = "n", channels: int = 1, copies: int = 1) -> int:
    """Validate a number of samples to simulate; returns it as an int.

    Parameters
    ----------
    n : int
        The sample count (a Python or NumPy integer; not a bool, not a float).
    name : str
        How the caller names it in messages: the argument ``n`` in the engine, ``-n`` on the
        command line.
    channels, copies : int
        As in :func:`max_samples`.

    Raises
    ------
    ValueError
        ``n`` is not an integer, is below 1, is above :data:`MAX_SAMPLES`, or would need more
        than :data:`MEMORY_FRACTION` of the available memory; the message gives the largest
        accepted count.
    """
    if isinstance(n, bool) or not isinstance(n, SupportsIndex):
        raise ValueError(f"{name} must be a whole number of samples, got {n!r}")
    try:
        k = operator.index(n)
    except TypeError:
        raise ValueError(f"{name} must be a whole number of samples, got {n!r}") from None
    if k < 1:
        raise ValueError(f"{name} must be at least 1 sample, got {k}")
    if k > MAX_SAMPLES:
        raise ValueError(
            f"{name} = {k:.3g} samples is beyond any simulation (at most 2^40 = {MAX_SAMPLES:.3g})"
        )
    limit = max_samples(channels, copies)
    if k > limit:
        need = float(k) * BYTES_PER_SAMPLE * max(1, channels) * max(1, copies)
        mem = available_memory() or 0
        raise ValueError(
            f"{name} = {k} samples would need about {_gb(need)} of memory "
            f"({BYTES_PER_SAMPLE} bytes per sample"
            + (f" x {channels} channels" if channels > 1 else "")
            + (f" x {copies} at once" if copies > 1 else "")
            + f"), more than {math.floor(MEMORY_FRACTION * 100)}% of the {_gb(mem)} available: "
            f"use {name} <= {limit}"
        )
    return k


def check_memory(
    need: int,
    src: str,
    *,
    what: str = "",
    fix: str = "",
    error: type[Exception] = ValueError,
) -> None:
    """Refuse, before parsing, a file whose loading needs more memory than is available.

    Parameters
    ----------
    need : int
        The reader's estimate of the memory (bytes) that loading the file takes at its peak.
    src : str
        The file as the user gave it, for the message.
    what : str, optional
        What the estimate counts, for the message (e.g. ``"3 channels x 2e9 samples"``).
    fix : str, optional
        What else the user can do, appended to "free memory or use a machine with more"
        (e.g. ``"load one channel (channel=)"``).
    error : exception type
        Raised with the message.

    Raises
    ------
    error
        ``need`` is larger than :func:`available_memory` (nothing is checked when that is
        unknown).
    """
    avail = available_memory()
    if avail is None or need <= avail:
        return
    detail = f" ({what})" if what else ""
    raise error(
        f"'{src}' is too large to load: it needs about {_mb(need)} of memory{detail}, and "
        f"{_mb(avail)} are available: free memory or use a machine with more"
        + (f", or {fix}" if fix else "")
    )


def _mb(n: float) -> str:
    return f"{n / 1e9:.3g} GB" if n >= 1e9 else f"{n / 1e6:.3g} MB"
