"""Writing logs: :func:`save_log` to HDF5 (the raw layout of ``shared/data``), NPY or CSV."""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._files import atomic_output
from .._text import spreadsheet_safe
from ._assemble import check_fs, clean_unit, time_divisor
from .hdf5 import H5_EXT

__all__ = ["save_log"]

_RESERVED = {"fs_hz", "n_samples", "duration_s", "units", "kind", "schema_version"}


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
    fs = check_fs(fs, str(p), "fs", "pass the sampling frequency in Hz")
    if ext not in H5_EXT | {".npy", ".csv"}:
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
    unit = {k: clean_unit((units or {}).get(k, "")) for k in arrs}
    extra = dict(attrs or {})
    if ext != ".npy" and (timelike := [k for k in arrs if time_divisor(k.rsplit("/")[-1])]):
        raise ValueError(
            f"cannot save '{p}': channel names {timelike} would be read back as a "
            "time column; rename them"
        )
    if clash := sorted(_RESERVED & set(extra)):
        raise ValueError(f"cannot save '{p}': attrs {clash} are written by save_log itself")
    if ext not in H5_EXT and ext != ".npy":
        if bad := [k for k in arrs if any(c in k for c in ',"#\n\r[(')]:
            raise ValueError(
                f"cannot save '{p}': channel names {bad} contain characters that "
                'CSV headers cannot hold (, " # [ ( or newlines)'
            )
    with atomic_output(p) as tmp:  # a full disk or an error never leaves half a file
        if ext in H5_EXT:  # built in memory, then written by us: the HDF5 library never
            # meets a full disk (it crashes at exit when it cannot close a file)
            image = io.BytesIO()
            with h5py.File(image, "w") as f:
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
            with open(tmp, "wb") as fh:
                fh.write(image.getbuffer())
        elif ext == ".npy":
            cols = list(arrs.values())
            with open(tmp, "wb") as fh:  # (a file object: np.save adds no suffix)
                np.save(fh, cols[0] if len(cols) == 1 else np.column_stack(cols))
        else:
            cells = [f"{k} [{unit[k]}]" if unit[k] else k for k in arrs]
            head = ",".join(["time", *(spreadsheet_safe(c) for c in cells)])
            floats = [a.astype(np.float64) for a in arrs.values()]
            data = np.column_stack([np.arange(n) / fs, *floats])
            np.savetxt(tmp, data, fmt="%.17g", delimiter=",", header=head, comments="")
    return p
