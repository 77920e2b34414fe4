"""HDF5 logs: every numeric 1-D or 2-D dataset is a channel.

File attributes (``fs_hz``, ``units`` as JSON, ...) or dataset attributes give the sampling
frequency and units; a time-named 1-D dataset is the time column. Files marked as
wavelet-variance summaries are read by :mod:`engine.io.summary`.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._assemble import (
    FS_KEYS,
    LoadOptions,
    RawLog,
    array_memory_need,
    attr_value,
    check_array_memory,
    check_channel_count,
    clean_unit,
    finish_log,
    ordered_names,
    time_divisor,
    units_map,
)
from .log import ImuLog, LoadError, pick_channel
from .summary import read_wv_summary

if TYPE_CHECKING:  # pragma: no cover
    import h5py

__all__ = ["read_h5", "H5_EXT"]

H5_EXT = {".h5", ".hdf5", ".hdf", ".he5"}
#: Bytes the HDF5 library allocates per chunk that one read touches (its map of the chunks),
#: measured: reading 1e5 one-sample chunks at once peaked at 423 MB (about 3.8 KB a chunk).
H5_BYTES_PER_CHUNK = 4096
#: Chunks one read may touch: a dataset of tiny chunks is read in slices of at most this many
#: chunks (the library's chunk map then stays under 5 MB; measured on 1e5 one-sample chunks,
#: slices of 1024 chunks were also the fastest), and of at most :data:`H5_SLICE_SAMPLES`
#: samples when the chunks are small.
H5_CHUNKS_PER_READ = 1024
#: Most chunks a channel may be stored in (about 15 us each to read): a dataset of 1e6
#: one-sample chunks is refused, not read for tens of seconds. The logs of shared/data have 16.
H5_MAX_CHUNKS = 1 << 18
H5_SLICE_SAMPLES = 1 << 20
_SUMMARY_KINDS = {"wavelet_and_allan_variance", "wavelet_variance"}


def read_h5(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
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
        attrs = {k: attr_value(v) for k, v in f.attrs.items()}
        units = units_map(attrs.pop("units", None), src, notes)
        meta = {k: v for k, v in attrs.items() if v is not None}
        fs_file = next(((attrs[k], f"attribute '{k}'") for k in FS_KEYS if k in attrs), None)
        if str(attrs.get("kind", "")) in _SUMMARY_KINDS or isinstance(f.get("wv"), h5py.Group):
            if opts.scale is not None:
                raise LoadError(
                    f"file '{src}' is a wavelet-variance summary: scale= applies to "
                    "raw samples (counts); load the raw log instead"
                )
            return read_wv_summary(f, src, channel, opts.fs_user, fs_file, units, meta, notes)
        found: dict[str, tuple[int, Callable[[], np.ndarray], h5py.Dataset]] = {}
        times: list[tuple[str, h5py.Dataset, tuple[float, bool]]] = []
        scalar_fs: list[tuple[Any, str]] = []

        def visit(name: str, obj: Any) -> None:
            if not isinstance(obj, h5py.Dataset) or obj.dtype.kind not in "iufb":
                return
            unit = clean_unit(obj.attrs.get("units", obj.attrs.get("unit", "")))
            div = time_divisor(name.rsplit("/", 1)[-1], unit)
            if obj.ndim == 1 and div is not None:
                times.append((name, obj, div))
            elif obj.ndim == 1 and obj.size > 1:
                found[name] = (obj.shape[0], _reader(obj), obj)
                units[name] = unit or units.get(name, "")
            elif obj.ndim == 2 and obj.size > 1:
                rows_first = obj.shape[0] < obj.shape[1]  # (k, N): channels in rows
                k = obj.shape[1 - int(rows_first)]
                check_channel_count(src, len(found) + k, f"channels (dataset '{name}': {k})")
                for j in range(k):
                    found[f"{name}[{j}]"] = (obj.shape[int(rows_first)], _reader(obj, j), obj)
                    units[f"{name}[{j}]"] = unit or units.get(f"{name}[{j}]", "")
            elif obj.ndim == 0 and name.lower() in FS_KEYS:
                scalar_fs.append((attr_value(obj[()]), f"dataset '{name}'"))
            elif obj.ndim > 2:
                notes.append(f"dataset '{name}' of shape {obj.shape} skipped (not 1-D or 2-D)")

        f.visititems(visit)
        fs_file = fs_file or (scalar_fs[0] if scalar_fs else None)
        names = ordered_names(list(found), units)
        if channel is not None:
            names = [pick_channel(src, names, channel)]
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
            key = next((a for a in FS_KEYS if a in ds_attrs), None)
            if key is not None:
                fs_file = (attr_value(ds_attrs[key]), f"attribute '{key}' of dataset '{k}'")
                break
        n = found[names[0]][0] if names else 0
        reads = [found[k][2] for k in names] + [ds for _, ds, _ in times if ds.shape[0] == n][:1]
        for ds in reads:
            _check_chunks(src, ds)
        need = sum(_read_need(ds) for ds in reads)
        stored = sum({id(ds): ds.id.get_storage_size() for ds in reads}.values())
        what = f"{len(names)} dataset column(s) of {n} samples"
        check_array_memory(need, src, what, stored=stored)
        time = next(((nm, _reader(ds)(), div) for nm, ds, div in times if ds.shape[0] == n), None)
        cols: dict[str, Any] = {}
        for k in names:
            try:
                cols[k] = found[k][1]()
            except (OSError, ValueError) as exc:
                raise LoadError(
                    f"file '{src}', dataset '{k}' could not be read ({exc}): the file "
                    "may be truncated or corrupt; re-export it"
                ) from exc
    raw = RawLog(cols, units, fs_file=fs_file, time=time, meta=meta, notes=notes)
    return finish_log(src, raw, fmt="hdf5", channel=None, opts=opts)


def _slicing(ds: h5py.Dataset, axis: int) -> tuple[int, int]:
    """(samples per read, chunks along the samples axis) of reading a channel of ``ds``."""
    n = int(ds.shape[axis])
    if ds.chunks is None:
        return n, 1
    c = max(1, int(ds.chunks[axis]))
    step = c * max(1, min(H5_CHUNKS_PER_READ, H5_SLICE_SAMPLES // c))
    return min(step, n), -(-n // c)


def _sample_axis(ds: h5py.Dataset) -> int:
    return 0 if ds.ndim == 1 or ds.shape[0] >= ds.shape[1] else 1


def _check_chunks(src: str, ds: h5py.Dataset) -> None:
    """LoadError when a channel of ``ds`` is stored in more than :data:`H5_MAX_CHUNKS`
    chunks."""
    axis = _sample_axis(ds)
    _, chunks = _slicing(ds, axis)
    if chunks > H5_MAX_CHUNKS:
        c = ds.chunks[axis]
        raise LoadError(
            f"file '{src}', dataset '{ds.name.lstrip('/')}': {ds.shape[axis]} samples stored in "
            f"{chunks} chunks of {c} sample(s), more than {H5_MAX_CHUNKS} chunks: re-save it "
            "with larger chunks (e.g. h5repack -l CHUNK=65536, or chunks=True in h5py)"
        )


def _read_need(ds: h5py.Dataset) -> int:
    """Peak memory (bytes) of reading one channel of ``ds`` with :func:`_reader` and making it
    a channel: the samples (:func:`array_memory_need`), the library's map of the chunks one
    read touches, and the slice copied at a time when the read is sliced."""
    axis = _sample_axis(ds)
    n = int(ds.shape[axis])
    step, chunks = _slicing(ds, axis)
    per_read = 0 if ds.chunks is None else min(chunks, H5_CHUNKS_PER_READ) * H5_BYTES_PER_CHUNK
    return (
        array_memory_need((n,), ds.dtype) + per_read + (step * ds.dtype.itemsize if step < n else 0)
    )


def _reader(ds: h5py.Dataset, j: int | None = None) -> Callable[[], np.ndarray]:
    """A zero-argument reader of the channel of ``ds`` (the dataset, or its column or row
    ``j``), in slices of chunks (:data:`H5_CHUNKS_PER_READ`) so that a dataset of one-sample
    chunks cannot make the library map a million chunks at once."""
    axis = _sample_axis(ds)

    def sel(a: int, b: int) -> Any:
        if ds.ndim == 1:
            return np.s_[a:b]
        return np.s_[j, a:b] if axis == 1 else np.s_[a:b, j]

    def read() -> np.ndarray:
        n = int(ds.shape[axis])
        step, _ = _slicing(ds, axis)
        if step >= n:
            return np.asarray(ds[sel(0, n)])
        out = np.empty(n, dtype=ds.dtype)
        for a in range(0, n, step):
            out[a : a + step] = ds[sel(a, min(a + step, n))]
        return out

    return read
