"""Loading static IMU logs: text (CSV/TSV/whitespace), NPY/NPZ, HDF5, ROS bags.

:func:`load_log` returns an :class:`ImuLog`: raw channels (1-D arrays) with their sampling
frequency and units, or, for the wavelet-variance summary files of ``shared/data/derived``,
one precomputed :class:`~engine.wv.WaveletVariance` per channel. Every failure raises
:class:`LoadError`, whose message names the file, the column or dataset, what is wrong and
how to fix it (library errors on damaged files are converted too).

Time columns (and ROS message stamps) are checked for gaps, duplicates and jitter
(:mod:`engine.io.timecheck`); ``segment=`` chooses between stopping with a report (default),
the longest clean segment, or keeping every sample with a note. ``scale=`` turns raw integer
counts into units; float32 samples stay float32. ROS 1/2 bags with ``sensor_msgs/Imu`` are
read through :mod:`engine.io.rosbag` (the pure-Python ``rosbags`` package).

:func:`load_log` sniffs the format and calls one reader (:mod:`engine.io.text`,
:mod:`engine.io.npy`, :mod:`engine.io.hdf5`, :mod:`engine.io.rosbag`); the readers share
the column checks of :mod:`engine.io._assemble`. :func:`~engine.io.save_log` is in
:mod:`engine.io.save`.

Sample indices in messages are 0-based; line numbers are 1-based, as in an editor.
"""

from __future__ import annotations

import dataclasses
import io
import operator
import os
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

from .._files import open_regular
from .._limits import load_scope
from ._assemble import LoadOptions, RawLog, check_fs, finish_log
from .dataflash import DATAFLASH_MAGIC, is_dataflash_text, read_dataflash
from .hdf5 import H5_EXT, read_h5
from .log import ImuLog, LoadError, pick_channel
from .npy import read_npy, read_npz
from .qualify import drop_warmup as drop_warmup_of
from .segments import with_segments
from .text import read_text
from .ulog import ULOG_MAGIC, read_ulog

__all__ = ["load_log", "log_of"]

_MAGIC = {
    b"\x89HDF\r\n\x1a\n": "hdf5",
    b"\x93NUMPY": "npy",
    b"PK\x03\x04": "npz",
    b"#ROSBAG V2.0": "bag",
    b"\x89MCAP0\r\n": "bag",
    b"SQLite format 3\x00": "bag",
    ULOG_MAGIC: "ulog",
    DATAFLASH_MAGIC: "dataflash",
}


def load_log(
    path: str | os.PathLike[str] | bytes | bytearray | memoryview | IO[bytes],
    *,
    name: str | None = None,
    channel: str | int | None = None,
    fs: float | None = None,
    segment: str | tuple[int, int] | None = None,
    scale: float | Mapping[str, float] | None = None,
    units: str | Mapping[str, str] | None = None,
    topic: str | None = None,
    segments: str | Sequence[tuple[int, int]] | None = None,
    drop_warmup: int = 0,
) -> ImuLog:
    """Load a static IMU log (or a wavelet-variance summary file).

    Parameters
    ----------
    path : str, path-like, bytes or binary file object
        CSV/TSV/whitespace text (``.csv .tsv .txt .dat`` or any unknown extension), ``.npy``,
        ``.npz``, HDF5 (``.h5 .hdf5``), or a ROS bag with ``sensor_msgs/Imu`` messages: ROS 1
        ``.bag``, ROS 2 bag directory (with ``metadata.yaml``), ``.db3`` or ``.mcap``; a PX4
        ULog ``.ulg`` (extra ``px4``) or an ArduPilot DataFlash ``.bin``/``.log`` (extra
        ``ardupilot``), see :mod:`engine.io.ulog` and :mod:`engine.io.dataflash`. The
        content's magic bytes win over the extension. The file's content may be given instead
        of its path (an upload): ``bytes`` or a binary file object (read to its end); ``name``
        then gives its extension and its name in messages. (A ROS bag given as content goes
        through a temporary file: the bag library reads paths only.)
    name : str, optional
        For content: the file's name (e.g. ``"run1.h5"``), whose extension hints at the format
        and which error messages name (default ``"<upload>"``). For a path: how messages and
        :attr:`ImuLog.source` name the file (default: the path as given; a server names the
        path as its user typed it).
    channel : str or int, optional
        Keep only this channel (name, or index into :attr:`ImuLog.names`).
    fs : float, optional
        Sampling frequency in Hz; overrides the file (``fs_source == "user"``). The time
        column, if any, is still checked and its report kept (``segment`` then defaults to
        ``"report"``).
    segment : {"stop", "longest", "report"} or (start, stop), optional
        What to do when the time column has gaps, duplicate or backward stamps (see
        :mod:`engine.io.timecheck`): ``"stop"`` (the default without ``fs``) raises a
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
        ROS bags: the ``sensor_msgs/Imu`` topic, when the bag has several; PX4 ULogs: the
        IMU topic (``sensor_combined``, ``sensor_gyro``, ``sensor_accel``, ``vehicle_imu``).
    segments : "auto" or sequence of (start, stop), optional
        Analyse only these sample ranges of a flight log (``"auto"``: its still segments,
        :func:`engine.io.segments.still_segments`, found on every channel before ``channel``
        selects one): the log's :meth:`~ImuLog.wavelet_variance` pools their WVs.
    drop_warmup : int, optional
        Samples dropped from the start as a warm-up, after ``segment`` and ``segments``
        (:func:`engine.io.qualify.drop_warmup`; the log check's
        :attr:`~engine.io.qualify.Qualification.suggested_start`); 0 keeps every sample.

    Returns
    -------
    ImuLog
        Raw channels with ``fs`` and units (float64; float32 files stay float32 unless
        scaled), or ``wv`` for summary files.

    Raises
    ------
    LoadError
        Missing file, not a regular file (a FIFO, device, socket: refused before any read),
        a file whose loading needs more memory than is available (estimated before parsing),
        empty/binary/malformed file, non-numbers, ragged rows, NaN/Inf samples,
        fewer than 4 samples, unknown channel, invalid ``fs`` or ``scale``, a time column
        with gaps under ``segment="stop"``.

    Examples
    --------
    >>> import engine as eg
    >>> log = eg.load_log(eg.demo_path())
    >>> log.fs, log.n, list(log.channels)[:3]
    (100.0, 200000, ['gyro_x', 'gyro_y', 'gyro_z'])
    """
    if drop_warmup:
        try:
            start = -1 if isinstance(drop_warmup, bool) else operator.index(drop_warmup)
        except TypeError:
            start = -1
        if start < 0:
            raise LoadError(
                f"drop_warmup must be a number of samples (0 or more), got {drop_warmup!r}"
            )
        whole = load_log(
            path,
            name=name,
            channel=channel,
            fs=fs,
            segment=segment,
            scale=scale,
            units=units,
            topic=topic,
            segments=segments,
        )
        try:
            return drop_warmup_of(whole, start)
        except ValueError as e:
            raise LoadError(f"'{whole.source}': drop_warmup: {e}") from None
    if segments is not None:
        whole = load_log(
            path, name=name, fs=fs, segment=segment, scale=scale, units=units, topic=topic
        )
        return _select(with_segments(whole, segments), channel)
    if isinstance(path, (bytes, bytearray, memoryview)) or hasattr(path, "read"):
        return _load_content(path, name, channel, fs, segment, scale, units, topic)
    src = str(path) if name is None else str(name)
    p = Path(path)
    fs_user = None if fs is None else check_fs(fs, src, "fs", "pass fs in Hz, e.g. fs=100")
    opts = LoadOptions(fs_user=fs_user, segment=segment, scale=scale, units=units, topic=topic)
    if p.is_dir():
        if (p / "metadata.yaml").exists():  # its files are checked by the bag reader
            return _guarded(_read_bag, p, src, channel, opts, "bag")
        raise LoadError(
            f"'{src}' is a directory, not a log file: pass the path of a file "
            "(or of a ROS 2 bag folder: the directory holding metadata.yaml)"
        )
    with open_regular(p, src, error=LoadError) as fh:  # no FIFO, device, socket: see _files
        head = fh.read(16)
    fmt = _sniff(head, p.suffix, src)
    return _guarded(_READERS[fmt], p, src, channel, opts, fmt)


def _select(log: ImuLog, channel: str | int | None) -> ImuLog:
    """The log with one channel (and every auxiliary one), or as it is."""
    if channel is None:
        return log
    name = pick_channel(log.source, log.names, channel)
    units = {k: v for k, v in log.units.items() if k == name or k in log.aux}
    return dataclasses.replace(log, channels={name: log.channels[name]}, units=units)


def log_of(
    source: str | os.PathLike[str] | ImuLog,
    *,
    fs: float | None,
    load_options: Mapping[str, Any] | None,
    caller: str,
) -> ImuLog:
    """A log given as a path (loaded by :func:`load_log` with ``fs`` and ``load_options``)
    or already loaded (returned as it is: ``fs`` and ``load_options`` must then be left out,
    they were the loader's; else TypeError naming ``caller``)."""
    if isinstance(source, ImuLog):
        if fs is not None or load_options:
            raise TypeError(f"{caller}(): fs and load_options apply to a path, not to a loaded log")
        return source
    return load_log(str(source), fs=fs, **dict(load_options or {}))


def _sniff(head: bytes, suffix: str, src: str) -> str:
    """The format of a file from its first bytes (magic numbers), else its extension."""
    if not head:
        raise LoadError(f"file '{src}' is empty (0 bytes): check that the logger wrote data")
    fmt = next((v for k, v in _MAGIC.items() if head.startswith(k)), None)
    ext = suffix.lower()
    if fmt is None and ext == ".log" and is_dataflash_text(head):
        fmt = "dataflash"
    return fmt or (
        "hdf5"
        if ext in H5_EXT
        else ext[1:]
        if ext in (".npy", ".npz")
        else "bag"
        if ext in (".bag", ".db3", ".mcap")
        else "text"
    )


def _load_content(
    content: Any,
    name: str | None,
    channel: Any,
    fs: float | None,
    segment: Any,
    scale: Any,
    units: Any,
    topic: str | None,
) -> ImuLog:
    """:func:`load_log` of a file's content (bytes or a binary file object) named ``name``."""
    src = Path(name).name if name else "<upload>"
    if hasattr(content, "read"):
        try:
            content = content.read()
        except OSError as exc:
            raise LoadError(f"cannot read '{src}' ({exc})") from exc
    if isinstance(content, str):
        raise LoadError(f"'{src}': give the content as bytes (encode the text), not str")
    data = bytes(content)
    fs_user = None if fs is None else check_fs(fs, src, "fs", "pass fs in Hz, e.g. fs=100")
    opts = LoadOptions(fs_user=fs_user, segment=segment, scale=scale, units=units, topic=topic)
    fmt = _sniff(data[:16], Path(src).suffix, src)
    if fmt == "bag":
        return _bag_from_bytes(data, src, channel, opts)
    return _guarded(_READERS[fmt], io.BytesIO(data), src, channel, opts, fmt)


def _bag_from_bytes(data: bytes, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    """A one-file ROS bag given as content: through a temporary file (rosbags reads paths)."""
    suffix = Path(src).suffix if Path(src).suffix in (".bag", ".db3", ".mcap") else ".bag"
    fd, tmp = tempfile.mkstemp(prefix="gmwm_bag_", suffix=suffix)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        return _guarded(_read_bag, Path(tmp), src, channel, opts, "bag")
    finally:
        try:
            os.unlink(tmp)
        except OSError:
            pass


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
    reader: Callable[..., ImuLog],
    p: Path | io.BytesIO,
    src: str,
    channel: Any,
    opts: LoadOptions,
    fmt: str,
) -> ImuLog:
    """Run a reader; a library error on damaged content becomes a LoadError (with its type, so
    that the cause stays visible)."""
    try:
        with load_scope():  # its memory estimates are reserved in the process's budget
            return reader(p, src, channel, opts)
    except LoadError:
        raise
    except _CORRUPT as exc:
        what = {"text": "text", "npy": ".npy", "npz": ".npz", "hdf5": "HDF5", "bag": "ROS bag"}
        what.update(ulog="PX4 ULog", dataflash="ArduPilot DataFlash")
        why = type(exc).__name__
        if fmt in ("npy", "npz", "hdf5"):  # the library speaks of the file's structure
            why += ": " + " ".join(str(exc).split())[:200]
        # (text and bag errors may quote the file's lines or paths: their type only)
        raise LoadError(
            f"file '{src}' could not be read as {what.get(fmt, fmt)} ({why}): it may be "
            "truncated or corrupt; check it or export it again"
        ) from exc


def _read_bag(path: Path, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    """ROS 1/2 bag with sensor_msgs/Imu messages (see :mod:`engine.io.rosbag`)."""
    from .rosbag import read_imu_bag

    bag = read_imu_bag(path, topic=opts.topic, src=src)
    time = (bag.stamp_source, bag.stamps_ns, (1e9, True))
    raw = RawLog(bag.channels, bag.units, time=time, meta=bag.meta, notes=list(bag.notes))
    return finish_log(src, raw, fmt=bag.format, channel=channel, opts=opts)


_READERS: dict[str, Callable[..., ImuLog]] = {
    "hdf5": read_h5,
    "npy": read_npy,
    "npz": read_npz,
    "text": read_text,
    "bag": _read_bag,
    "ulog": read_ulog,
    "dataflash": read_dataflash,
}
