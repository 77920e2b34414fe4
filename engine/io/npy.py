"""NumPy logs: ``.npy`` arrays (1-D, (N, k) or structured) and ``.npz`` archives.

A structured array gives one channel per field (a time-named field is the time column); an
``.npz`` archive one channel per numeric key, with optional ``fs`` and ``units`` keys.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from .._files import open_regular, write_atomic
from ._assemble import (
    LoadOptions,
    RawLog,
    array_memory_need,
    attr_value,
    check_array_memory,
    finish_log,
    stored_size,
    time_divisor,
    units_map,
)
from .log import ImuLog, LoadError

__all__ = ["read_npy", "read_npz", "npy_sidecar_path", "read_npy_sidecar", "write_npy_sidecar"]


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


def _np_load(fh: IO[bytes], src: str, what: str, save_with: str) -> Any:
    """``np.load`` without pickles; a file it cannot read is a LoadError saying how to
    re-save it."""
    try:
        return np.load(fh, allow_pickle=False)
    except Exception as exc:
        raise LoadError(
            f"file '{src}' is not a readable {what} ({exc}): re-save it with {save_with}"
        ) from exc


def _open(path: Path | io.BytesIO, src: str) -> IO[bytes]:
    """The file (a regular one: see :func:`engine._files.open_regular`) or the content."""
    return path if isinstance(path, io.BytesIO) else open_regular(path, src, error=LoadError)


def _npy_header(fh: IO[bytes]) -> tuple[tuple[int, ...], np.dtype] | None:
    """``(shape, dtype)`` from the header of the ``.npy`` data at ``fh``'s position, or None
    when it cannot be read (``np.load`` then says why)."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        read = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}[version]
        shape, _, dtype = read(fh)
    except Exception:  # noqa: BLE001 - a damaged header: np.load reports it
        return None
    return tuple(shape), dtype


def read_npy(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    with _open(path, src) as fh:
        head = _npy_header(fh)
        if head is not None:
            shape, dtype = head
            what = f"an array of shape {shape} and dtype {dtype}"
            need = array_memory_need(shape, dtype)
            check_array_memory(need, src, what, stored=stored_size(path))
        fh.seek(0)
        a = _np_load(fh, src, ".npy array of numbers", "numpy.save(path, array)")
    raw = RawLog()
    if a.dtype.names and a.ndim == 1:  # structured array: one channel per field
        for name in a.dtype.names:
            div = time_divisor(name)
            if div is not None and a[name].ndim == 1:
                raw.time = raw.time or (name, a[name], div)
            else:
                raw.cols.update(_columns(name, a[name], raw.notes))
    elif a.ndim in (1, 2) and not a.dtype.names:
        raw.cols = {"x": a} if a.ndim == 1 else _columns("array", a, raw.notes, "col{j}")
    else:
        raise LoadError(
            f"file '{src}': array of shape {a.shape} is not 1-D (N,) or 2-D (N, k): "
            "save one column per channel"
        )
    side = None if isinstance(path, io.BytesIO) else read_npy_sidecar(path)
    if side is not None:  # written by `gmwm simulate -o x.npy`: fs, channel names, units
        names = side.get("channels")
        cols = raw.cols
        if isinstance(names, list) and len(names) == len(cols) and len(set(names)) == len(names):
            raw.cols = dict(zip(map(str, names), cols.values(), strict=True))
        if isinstance(side.get("units"), dict):
            raw.units = {str(k): str(v) for k, v in side["units"].items()}
        if "fs_hz" in side:
            raw.fs_file = (side["fs_hz"], f"sidecar '{npy_sidecar_path(src).name}'")
        raw.meta = {k: v for k, v in side.items() if k not in ("channels", "units", "fs_hz")}
    return finish_log(src, raw, fmt="npy", channel=channel, opts=opts)


def npy_sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The JSON sidecar of a ``.npy`` log: ``x.npy`` -> ``x.npy.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def read_npy_sidecar(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The sidecar of a ``.npy`` log as a dict (None when there is none).

    A ``.npy`` array holds samples only; its sidecar ``x.npy.json`` keeps what the array cannot:
    ``{"fs_hz": 200.0, "channels": ["x"], "units": {"x": "deg/s"}, ...}`` (other keys, e.g.
    ``model`` and ``seed``, end up in ``ImuLog.meta``). Raises LoadError when the sidecar exists
    but is not such an object.
    """
    side = npy_sidecar_path(path)
    if not side.is_file():
        return None
    try:
        d = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, UnicodeError, ValueError) as exc:
        raise LoadError(
            f"sidecar '{side}' of '{path}' is not readable JSON ({exc}): fix or delete it"
        ) from exc
    if not isinstance(d, dict):
        raise LoadError(f"sidecar '{side}' of '{path}' is not a JSON object: fix or delete it")
    return d


def write_npy_sidecar(
    path: str | os.PathLike[str],
    fs: float,
    channels: list[str],
    units: Mapping[str, str] | None = None,
    **extra: Any,
) -> Path:
    """Write the sidecar of a ``.npy`` log (see :func:`read_npy_sidecar`); returns its path."""
    d = {"fs_hz": float(fs), "channels": list(channels), "units": dict(units or {}), **extra}
    side = npy_sidecar_path(path)
    write_atomic(side, json.dumps(d, indent=2) + "\n")
    return side


def _npz_memory_need(z: Any) -> int:
    """Peak memory (bytes) of reading every array of an open ``.npz`` archive."""
    need = 0
    for info in z.zip.infolist():
        with z.zip.open(info) as m:
            head = _npy_header(m)
        need += info.file_size if head is None else array_memory_need(*head)
    return need


def read_npz(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    raw = RawLog()
    with _open(path, src) as fh:
        z = _np_load(fh, src, ".npz archive", "numpy.savez(path, gyro_x=..., fs=100.0)")
        with z:
            need, what = _npz_memory_need(z), f"{len(z.files)} array(s)"
            check_array_memory(need, src, what, stored=stored_size(path))
            for key in z.files:
                try:
                    a = z[key]
                except ValueError:
                    raw.notes.append(f"key '{key}' holds Python objects and was skipped")
                    continue
                divisor = time_divisor(key)
                if key.lower() in ("fs", "fs_hz", "sample_rate") and a.size == 1:
                    raw.fs_file = (a.item(), f"key '{key}'")
                elif key == "units" and a.dtype.kind in "US" and a.size == 1:
                    raw.units = units_map(str(a.item()), src, raw.notes)
                elif a.dtype.kind in "iufb" and a.ndim == 1 and divisor is not None:
                    raw.time = raw.time or (key, a, divisor)
                elif a.dtype.kind in "iufb" and a.ndim in (1, 2) and a.size > 1:
                    raw.cols.update(_columns(key, a, raw.notes))
                elif a.ndim == 0:
                    raw.meta[key] = attr_value(a.item())
                else:
                    shape = f"shape {a.shape}, dtype {a.dtype}"
                    raw.notes.append(f"key '{key}' ({shape}) was skipped")
    return finish_log(src, raw, fmt="npz", channel=channel, opts=opts)
