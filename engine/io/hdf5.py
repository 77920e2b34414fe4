"""HDF5 logs: every numeric 1-D or 2-D dataset is a channel.

File attributes (``fs_hz``, ``units`` as JSON, ...) or dataset attributes give the sampling
frequency and units; a time-named 1-D dataset is the time column. Files marked as
wavelet-variance summaries are read by :mod:`engine.io.summary`.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from functools import partial
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
                found[name] = (obj.shape[0], lambda: obj[...], obj)
                units[name] = unit or units.get(name, "")
            elif obj.ndim == 2 and obj.size > 1:
                rows_first = obj.shape[0] < obj.shape[1]  # (k, N): channels in rows
                for j in range(obj.shape[1 - int(rows_first)]):
                    found[f"{name}[{j}]"] = (
                        obj.shape[int(rows_first)],
                        partial(obj.__getitem__, np.s_[j, :] if rows_first else np.s_[:, j]),
                        obj,
                    )
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
        need = sum(array_memory_need((found[k][0],), found[k][2].dtype) for k in names)
        need += next((array_memory_need((n,), ds.dtype) for _, ds, _ in times), 0)
        check_array_memory(need, src, f"{len(names)} dataset column(s) of {n} samples")
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
    raw = RawLog(cols, units, fs_file=fs_file, time=time, meta=meta, notes=notes)
    return finish_log(src, raw, fmt="hdf5", channel=None, opts=opts)
