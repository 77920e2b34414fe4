"""Wavelet-variance summary files (the HDF5 schema of ``shared/data/derived``).

One :class:`~engine.wv.WaveletVariance` per ``/wv/<channel>`` group (``variance`` at levels
1..J, optional ``ci_low``/``ci_high`` and ``tau_samples``), with the file attribute
``n_samples`` (length of the underlying raw log).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..wv.classical import WaveletVariance
from ._assemble import attr_value, check_fs, ordered_names
from .log import ImuLog, LoadError, pick_channel

if TYPE_CHECKING:  # pragma: no cover
    import h5py

__all__ = ["read_wv_summary"]


def read_wv_summary(
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
    names = ordered_names(names, units)
    if channel is not None:
        names = [pick_channel(src, names, channel)]
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
        fs, fs_source = check_fs(fs_file[0], src, fs_file[1], fix), "file"
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
                alpha=float(attr_value(grp.attrs.get("ci_alpha", 0.05))),
                robust=bool(attr_value(grp.attrs.get("robust", False))),
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
