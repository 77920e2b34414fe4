"""Limits on the work a call may ask for: the samples a simulation may hold, the memory a file
may take to load.

A simulation of ``n`` samples holds the result and one process's draw at a time, plus the
temporaries of a cumulative sum or a recursive filter: about :data:`BYTES_PER_SAMPLE` bytes
per sample and channel at its peak. :func:`check_sample_count` refuses an ``n`` whose peak
would exceed :data:`MEMORY_FRACTION` of the memory available now (``MemAvailable`` of
``/proc/meminfo``; elsewhere the physical memory), and any ``n`` above :data:`MAX_SAMPLES`
whatever the memory, so that a typo such as ``1e14`` is a one-line error, not minutes of
swapping or a MemoryError.

Loading a file is bounded the same way, before anything is parsed (:func:`check_memory`, called
by every reader with its estimate of the load's peak):

* the estimate must fit in the memory available now, less what the loads running in this
  process have reserved (:func:`load_scope`: one budget shared by every load, so that two app
  sessions cannot each count on all of ``MemAvailable``), and within the process's load budget
  (:func:`set_load_budget`, e.g. a fraction of the machine for a class server);
* a file may not expand by more than :data:`MAX_EXPANSION` times its size on disk once the
  estimate passes :data:`EXPANSION_FLOOR` bytes: a decompression bomb (a 1.24 MB ``.npz`` that
  inflates to 1.26 GB) or a declared-size bomb (an HDF5 dataset of 16 GB of fill values in a
  1.5 KB file) is refused from its declared sizes, not after its memory is taken.
"""

from __future__ import annotations

import math
import operator
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import SupportsIndex

__all__ = [
    "BYTES_PER_SAMPLE",
    "MEMORY_FRACTION",
    "MAX_SAMPLES",
    "available_memory",
    "check_memory",
    "max_samples",
    "check_sample_count",
    "MAX_EXPANSION",
    "EXPANSION_FLOOR",
    "set_load_budget",
    "load_budget",
    "reserved_memory",
    "load_scope",
    "MAX_REPLICATES",
    "check_replicates",
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


#: Largest ratio of a load's estimated peak memory to the size of the file on disk. Real
#: logs stay far below it (the gzip-compressed float64 logs of shared/data: about 10; integer
#: counts converted to float64 from a well-compressed file: tens); DEFLATE cannot exceed
#: about 1032, and an HDF5 dataset of unwritten chunks (fill values) has no bound at all.
MAX_EXPANSION = 256
#: Estimates below this many bytes are never refused for their expansion (a small demo file
#: of constant values is no threat).
EXPANSION_FLOOR = 64_000_000

_LOCK = threading.Lock()
_BUDGET: dict[str, int | None] = {"limit": None, "reserved": 0}
_SCOPE = threading.local()


def set_load_budget(nbytes: int | None) -> None:
    """Cap the memory (bytes) that the loads running at once in this process may reserve
    together (None: no cap besides the available memory). A server of many sessions sets it
    (e.g. to half the machine) so that concurrent uploads share one budget."""
    if nbytes is not None and (isinstance(nbytes, bool) or int(nbytes) < 1):
        raise ValueError(f"the load budget must be a positive number of bytes, got {nbytes!r}")
    with _LOCK:
        _BUDGET["limit"] = None if nbytes is None else int(nbytes)


def load_budget() -> int | None:
    """The cap set by :func:`set_load_budget` (bytes), or None."""
    return _BUDGET["limit"]


def reserved_memory() -> int:
    """Bytes reserved now by the loads running in this process (see :func:`load_scope`)."""
    return int(_BUDGET["reserved"] or 0)


@contextmanager
def load_scope() -> Iterator[None]:
    """Run one load: every :func:`check_memory` accepted inside (in this thread) reserves its
    estimate in the process's shared budget until the scope ends. Scopes nest (the inner one
    adds to the outer)."""
    outer = getattr(_SCOPE, "held", None)
    _SCOPE.held = [0] if outer is None else outer
    try:
        yield
    finally:
        if outer is None:
            held = _SCOPE.held[0]
            _SCOPE.held = None
            with _LOCK:
                _BUDGET["reserved"] = max(0, int(_BUDGET["reserved"] or 0) - held)


def check_memory(
    need: int,
    src: str,
    *,
    what: str = "",
    fix: str = "",
    error: type[Exception] = ValueError,
    stored: int | None = None,
) -> None:
    """Refuse, before parsing, a file whose loading needs more memory than is available.

    Three bounds: ``need`` within the available memory less the loads already reserved in
    this process (:func:`load_scope`); within the process's budget (:func:`set_load_budget`);
    and, when ``stored`` is given and ``need`` passes :data:`EXPANSION_FLOOR`, at most
    :data:`MAX_EXPANSION` times ``stored``. Inside a :func:`load_scope`, an accepted ``need``
    is reserved until the scope ends.

    Parameters
    ----------
    need : int
        The reader's estimate of the memory (bytes) that loading the file takes at its peak.
    stored : int, optional
        The size (bytes) of the file (or of the stored data) the estimate comes from.
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
        ``need`` is larger than :func:`available_memory` less the reserved loads (not
        checked when unknown), than the free part of the load budget, or than
        :data:`MAX_EXPANSION` times ``stored``.
    """
    need = max(0, int(need))
    detail = f" ({what})" if what else ""
    if stored is not None and need > EXPANSION_FLOOR and need > MAX_EXPANSION * max(stored, 1):
        raise error(
            f"'{src}' declares far more data than it holds: loading it needs about "
            f"{_mb(need)}{detail} from {_bytes(stored)} on disk (over {MAX_EXPANSION} times): "
            "a decompression bomb or a damaged file; re-export the log without unwritten "
            "or constant data"
        )
    with _LOCK:
        reserved = int(_BUDGET["reserved"] or 0)
        limit = _BUDGET["limit"]
        avail = available_memory()
        free = None if avail is None else avail - reserved
        if limit is not None:
            free = limit - reserved if free is None else min(free, limit - reserved)
        if free is None or need <= free:
            held = getattr(_SCOPE, "held", None)
            if held is not None:
                held[0] += need
                _BUDGET["reserved"] = reserved + need
            return
    if limit is not None and (avail is None or limit - reserved < avail - reserved):
        where = f"the {_mb(limit)} load budget of this process has {_mb(max(free, 0))} free"
        if reserved:
            where += f" ({_mb(reserved)} held by loads in progress)"
        todo = "try again when the other loads end, or raise the budget"
    else:
        where = f"{_mb(max(free, 0))} are available"
        if reserved:
            where += f" besides the {_mb(reserved)} held by loads in progress"
        todo = "free memory or use a machine with more"
    raise error(
        f"'{src}' is too large to load: it needs about {_mb(need)} of memory{detail}, and "
        f"{where}: {todo}" + (f", or {fix}" if fix else "")
    )


#: Most bootstrap replicates (each one a simulation and a refit: 1e5 take hours already);
#: ``B = 1e11`` would first try to create 1e11 seeds.
MAX_REPLICATES = 100_000


def check_replicates(B: object) -> int:
    """``B`` as a number of bootstrap replicates: an integer from 2 to :data:`MAX_REPLICATES`;
    ValueError naming ``B`` otherwise."""
    if isinstance(B, bool) or not isinstance(B, SupportsIndex):
        raise ValueError(f"B must be a whole number of bootstrap replicates, got {B!r}")
    if not 2 <= operator.index(B) <= MAX_REPLICATES:
        raise ValueError(
            f"B must be from 2 to {MAX_REPLICATES} bootstrap replicates, got {operator.index(B)}"
        )
    return operator.index(B)


def _bytes(n: int) -> str:
    return _mb(n) if n >= 1e6 else f"{n} bytes"


def _mb(n: float) -> str:
    return f"{n / 1e9:.3g} GB" if n >= 1e9 else f"{n / 1e6:.3g} MB"
