"""Wavelet variance of logs larger than memory: NPY and HDF5 streamed in blocks.

:func:`wavelet_variance_stream` gives the classical Haar WV of
:func:`engine.wv.wavelet_variance` (same numbers to about 1e-14 relative) while holding only a
few blocks in memory, whatever the length of the log: a mean pass, then a main pass over the
cumulative sum with, for the large levels, lagged streams that re-read the file behind it.
The algorithm, its memory and its measured cost: docs/methods.md, "Streaming the wavelet
variance".

Reference: Percival & Walden (2000), ch. 8 (MODWT Haar WV).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import check_fs
from .._files import open_regular
from ._kernel import sumsq_kernel
from .classical import WaveletVariance, default_levels

__all__ = ["wavelet_variance_stream", "open_series", "SeriesSource"]

DEFAULT_BLOCK = 1 << 19
_SUB = 1 << 15  # cache-sized sub-block for the small levels (as in engine.wv._kernel)
_FS_KEYS = ("fs_hz", "fs", "sample_rate", "sampling_rate")


class SeriesSource:
    """One channel of a long log, read by ranges into caller buffers.

    Build with :func:`open_series`. Each instance owns its own file handle (so several
    streams can read one file at different offsets). ``n``, ``fs`` (None when unknown),
    ``unit``, ``name`` and ``dtype`` describe the channel.
    """

    n: int
    fs: float | None
    unit: str
    name: str
    dtype: np.dtype

    def read(self, start: int, stop: int, out: np.ndarray) -> np.ndarray:
        """Samples ``[start, stop)`` converted into ``out[:stop - start]`` (float64)."""
        raise NotImplementedError

    def clone(self) -> SeriesSource:
        """An independent reader of the same channel."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the file handle."""


class _NpySource(SeriesSource):
    """A ``.npy`` file: header read with ``np.load(mmap_mode="r")``, data with file reads."""

    piece = 1 << 21  # bytes read at once from the rows of a C-order (N, k) array

    def __init__(self, path: Path, column: int | None, fs: float | None) -> None:
        try:
            mm = np.load(path, mmap_mode="r", allow_pickle=False)
        except Exception as exc:
            raise ValueError(f"file '{path}' is not a readable .npy array ({exc})") from exc
        if not isinstance(mm, np.memmap):
            raise ValueError(f"file '{path}' is not a memory-mappable .npy array")
        shape, dtype, offset = mm.shape, mm.dtype, int(mm.offset)
        fortran = bool(mm.ndim == 2 and mm.flags.f_contiguous and not mm.flags.c_contiguous)
        del mm
        if dtype.kind not in "iuf" or dtype.names:
            raise ValueError(f"file '{path}': dtype {dtype} is not real-valued numeric data")
        if len(shape) == 1:
            if column not in (None, 0):
                raise ValueError(f"file '{path}' has one channel: column={column} is out of range")
            column, k = 0, 1
        elif len(shape) == 2:
            k = shape[1]
            if column is None:
                if k != 1:
                    raise ValueError(
                        f"file '{path}' has shape {shape}: choose a column "
                        f"(0..{k - 1}) with column="
                    )
                column = 0
            if not -k <= column < k:
                raise ValueError(f"file '{path}': column {column} is out of range 0..{k - 1}")
            column %= k
        else:
            raise ValueError(f"file '{path}': array of shape {shape} is not 1-D or 2-D (N, k)")
        self.path, self.column, self.k, self.fortran = path, column, k, fortran
        self.n, self.dtype, self.offset = int(shape[0]), dtype, offset
        self.fs, self.unit, self.name = fs, "", f"{path.name}[{column}]" if k > 1 else path.name
        self._fh: Any = None
        self._raw = np.empty(0, dtype=np.uint8)

    def clone(self) -> _NpySource:
        new = object.__new__(_NpySource)
        new.__dict__.update(self.__dict__)
        new._fh, new._raw = None, np.empty(0, dtype=np.uint8)
        return new

    def read(self, start: int, stop: int, out: np.ndarray) -> np.ndarray:
        if self._fh is None:
            self._fh = open_regular(self.path)  # closed by close()
        isz = self.dtype.itemsize
        contiguous = self.k == 1 or self.fortran
        per = 1 if contiguous else self.k
        # rows of a C-order (N, k) array are read in pieces of at most 2 MB
        step = stop - start if contiguous else max(1, self.piece // (self.k * isz))
        for a in range(start, stop, max(step, 1)):
            b = min(a + step, stop)
            cnt = b - a
            nbytes = cnt * per * isz
            if self._raw.size < nbytes:
                self._raw = np.empty(nbytes, dtype=np.uint8)
            if contiguous:
                pos = self.offset + (self.column * self.n + a) * isz
            else:
                pos = self.offset + a * self.k * isz
            self._fh.seek(pos)
            view = self._raw.data[:nbytes]
            got = 0
            while got < nbytes:
                r = self._fh.readinto(view[got:])
                if not r:
                    raise ValueError(f"file '{self.path}' is truncated: expected {self.n} samples")
                got += r
            vals = self._raw[:nbytes].view(self.dtype)
            if not contiguous:
                vals = vals.reshape(cnt, self.k)[:, self.column]
            out[a - start : b - start] = vals
        return out[: stop - start]

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


class _ArraySource(SeriesSource):
    """Any sliceable array: ndarray, np.memmap, h5py.Dataset (1-D, or 2-D with a column)."""

    def __init__(
        self,
        arr: Any,
        column: int | None,
        fs: float | None,
        unit: str = "",
        name: str = "x",
        owner: Any = None,
    ) -> None:
        shape = tuple(getattr(arr, "shape", ()))
        dtype = np.dtype(getattr(arr, "dtype", np.float64))
        if dtype.kind not in "iuf" or dtype.names:
            raise ValueError(f"'{name}': dtype {dtype} is not real-valued numeric data")
        if len(shape) == 2 and column is None and shape[1] == 1:
            column = 0
        if len(shape) == 2:
            if column is None or not -shape[1] <= column < shape[1]:
                raise ValueError(
                    f"'{name}' has shape {shape}: choose a column (0..{shape[1] - 1}) with column="
                )
            column %= shape[1]
        elif len(shape) != 1:
            raise ValueError(f"'{name}' of shape {shape} is not 1-D or 2-D (N, k)")
        self.arr, self.column, self.n, self.dtype = arr, column, int(shape[0]), dtype
        self.fs, self.unit, self.name, self._owner = fs, unit, name, owner
        # buffer of the stored type when it differs from the output's (h5py's read_direct)
        self._raw: np.ndarray | None = None

    def clone(self) -> _ArraySource:
        new = object.__new__(_ArraySource)
        new.__dict__.update(self.__dict__)
        new._owner = None  # the original closes the file
        new._raw = None
        return new

    def read(self, start: int, stop: int, out: np.ndarray) -> np.ndarray:
        sel = np.s_[start:stop] if self.column is None else np.s_[start:stop, self.column]
        cnt = stop - start
        read_direct = getattr(self.arr, "read_direct", None)
        if read_direct is not None and cnt:  # h5py: into a reused buffer, no temporary
            if self.dtype == out.dtype:
                read_direct(out, source_sel=sel, dest_sel=np.s_[0:cnt])
            else:  # read the stored type, convert with NumPy (HDF5's conversion is slower)
                raw = self._raw
                if raw is None or raw.size < cnt:
                    raw = self._raw = np.empty(cnt, dtype=self.dtype.newbyteorder("="))
                read_direct(raw, source_sel=sel, dest_sel=np.s_[0:cnt])
                out[:cnt] = raw[:cnt]
        else:
            out[:cnt] = self.arr[sel]
        return out[:cnt]

    def close(self) -> None:
        if self._owner is not None and getattr(self._owner, "id", None) is not None:
            try:
                self._owner.close()
            except Exception:  # pragma: no cover - closing twice is harmless
                pass


def _h5_attr(v: Any) -> Any:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.generic):
        return v.item()
    return v


def _h5_source(
    path: Path, dataset: str | None, column: int | None, fs: float | None
) -> SeriesSource:
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"file '{path}' is not a readable HDF5 file ({exc})") from exc
    try:
        if dataset is None:
            cands: list[tuple[str, Any]] = []
            f.visititems(
                lambda nm, ob: (
                    cands.append((nm, ob))
                    if isinstance(ob, h5py.Dataset)
                    and ob.dtype.kind in "iuf"
                    and ob.ndim in (1, 2)
                    and ob.size > 1
                    else None
                )
            )
            if not cands:
                raise ValueError(f"file '{path}' has no numeric dataset")
            longest = max(c[1].shape[0] for c in cands)
            names = [nm for nm, ob in cands if ob.shape[0] == longest]
            if len(names) > 1:
                raise ValueError(
                    f"file '{path}' has several datasets ({', '.join(names[:20])}): "
                    "choose one with dataset="
                )
            dataset = names[0]
        ds = f.get(dataset)
        if not isinstance(ds, h5py.Dataset):
            names = []
            f.visititems(lambda nm, ob: names.append(nm) if isinstance(ob, h5py.Dataset) else None)
            raise ValueError(
                f"file '{path}' has no dataset {dataset!r}; datasets: {', '.join(names[:50])}"
            )
        if fs is None:
            for attrs in (ds.attrs, f.attrs):
                key = next((k for k in _FS_KEYS if k in attrs), None)
                if key is not None:
                    fs = float(_h5_attr(attrs[key]))
                    break
        unit = _h5_attr(ds.attrs.get("units", ds.attrs.get("unit", "")))
        if not unit and "units" in f.attrs:
            try:
                unit = json.loads(_h5_attr(f.attrs["units"])).get(dataset, "")
            except (ValueError, AttributeError, TypeError):
                unit = ""
        return _ArraySource(ds, column, fs, str(unit or ""), dataset, owner=f)
    except BaseException:
        f.close()
        raise


def open_series(
    source: Any,
    *,
    dataset: str | None = None,
    column: int | None = None,
    fs: float | None = None,
) -> SeriesSource:
    """A :class:`SeriesSource` for a path (``.npy`` or HDF5) or an array-like.

    Parameters
    ----------
    source : str, path-like, ndarray, np.memmap or h5py.Dataset
        The log. HDF5 files are recognised by their magic bytes.
    dataset : str, optional
        HDF5 dataset path (default: the only longest numeric dataset).
    column : int, optional
        Column of a 2-D ``(N, k)`` array.
    fs : float, optional
        Sampling frequency (Hz); default: the file's ``fs_hz`` (HDF5), else unknown.
    """
    if isinstance(source, SeriesSource):
        return source
    if isinstance(source, (str, os.PathLike)):
        p = Path(source)
        with open_regular(p) as fh:  # no FIFO, device or directory: see engine._files
            head = fh.read(8)
        if head.startswith(b"\x89HDF\r\n\x1a\n"):
            return _h5_source(p, dataset, column, fs)
        if head.startswith(b"\x93NUMPY"):
            if dataset is not None:
                raise ValueError(f"file '{p}' is a .npy array: dataset= applies to HDF5 files")
            return _NpySource(p, column, fs)
        raise ValueError(
            f"file '{p}': streaming reads .npy and HDF5 files only; load other "
            "formats with load_log and use wavelet_variance"
        )
    return _ArraySource(source, column, fs)


class _Stream:
    """Blocks of S = cumsum of the de-meaned series, in order, from its own reader."""

    def __init__(
        self,
        src: SeriesSource,
        n: int,
        block: int,
        mean: float,
        scale: float | None,
        buf: np.ndarray | None = None,
    ) -> None:
        self.src, self.n, self.block, self.mean, self.scale = src, n, block, mean, scale
        self.s = np.empty(block + 1) if buf is None else buf
        self.k = -1  # index of the block held in self.s
        self.carry = 0.0

    def advance(self) -> np.ndarray:
        """Next block k: ``S[kB .. kB + cnt]`` (cnt + 1 values, cnt samples read)."""
        self.k += 1
        a = self.k * self.block
        cnt = max(min(self.block, self.n - a), 0)
        s = self.s
        s[0] = self.carry
        if cnt:
            d = s[1 : cnt + 1]
            self.src.read(a, a + cnt, d)
            if self.scale is not None:
                np.multiply(d, self.scale, out=d)
            np.subtract(d, self.mean, out=d)
            np.cumsum(s[: cnt + 1], out=s[: cnt + 1])
        self.carry = float(s[cnt])
        return s[: cnt + 1]

    def get(self, k: int) -> np.ndarray:
        """Block k, advancing as needed (blocks are produced in order only)."""
        while self.k < k:
            self.advance()
        if self.k != k:  # pragma: no cover - the main loop only asks in order
            raise RuntimeError("stream blocks must be requested in order")
        return self.s[: max(min(self.block, self.n - k * self.block), 0) + 1]

    @property
    def samples_read(self) -> int:
        """Samples read so far."""
        return min((self.k + 1) * self.block, self.n)


def _mean(
    src: SeriesSource,
    n: int,
    block: int,
    scale: float | None,
    progress: Callable[[int, int], None] | None,
    total: int,
) -> float:
    buf = np.empty(block)
    parts = []
    for a in range(0, n, block):
        b = min(a + block, n)
        x = src.read(a, b, buf)
        if scale is not None:
            np.multiply(x, scale, out=x)
        with np.errstate(over="ignore", invalid="ignore"):  # checked just below
            s = float(np.sum(x))
        if not math.isfinite(s):
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                raise ValueError(
                    f"the series contains NaN/Inf value(s), first at sample "
                    f"{a + int(bad[0])}; remove or interpolate them first"
                )
            raise ValueError(
                f"the samples near sample {a} are too large: their sum overflows "
                "float64 (check the scale factor and the units)"
            )
        parts.append(s)
        if progress is not None:
            progress(b, total)
    mean = math.fsum(parts) / n
    if not math.isfinite(mean):
        raise ValueError("the mean of the series overflows float64: check the scale and units")
    return mean


def _small_sums(
    h: np.ndarray,
    base: int,
    t_lo: int,
    t_hi: int,
    levels: list[int],
    sums: np.ndarray,
    tmp: np.ndarray,
) -> None:
    """Add sum_t (S_t - 2 S_{t-m} + S_{t-2m})^2 over t in [t_lo, t_hi) for small levels;
    ``h[i]`` holds ``S_{base + i}``."""
    sumsq = sumsq_kernel()
    for a in range(t_lo, t_hi, _SUB):
        b = min(a + _SUB, t_hi)
        for j in levels:
            m = 1 << (j - 1)
            lo = max(a, 2 * m)
            if lo >= b:
                break
            k = b - lo
            d = tmp[:k]
            i0 = lo - base
            np.multiply(h[i0 - m : i0 - m + k], -2.0, out=d)
            d += h[i0 : i0 + k]
            d += h[i0 - 2 * m : i0 - 2 * m + k]
            sums[j - 1] += sumsq(d, d)


def wavelet_variance_stream(
    source: Any,
    *,
    dataset: str | None = None,
    column: int | None = None,
    fs: float | None = None,
    levels: int | None = None,
    block: int = DEFAULT_BLOCK,
    scale: float | None = None,
    alpha: float = 0.05,
    unit: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> WaveletVariance:
    """Classical Haar WV of a long log, streamed in blocks with bounded memory.

    Parameters
    ----------
    source : str, path-like, ndarray, np.memmap or h5py.Dataset
        A ``.npy`` file (1-D, or 2-D ``(N, k)`` with ``column``), an HDF5 file (``dataset``),
        or an array-like with ``shape`` and slicing.
    dataset : str, optional
        HDF5 dataset path, e.g. ``"gyro_x"`` (default: the only longest numeric dataset).
    column : int, optional
        Column of a 2-D array.
    fs : float, optional
        Sampling frequency (Hz); default: the file's ``fs_hz`` attribute, else 1.
    levels : int, optional
        Number of levels J; default ``floor(log2(N - 1))``.
    block : int
        Block length in samples, a power of two >= 1024 (default 2^19). Memory is about
        ``16 B`` bytes per stream for float64 data (see the module notes); larger blocks mean
        fewer streams and re-reads.
    scale : float, optional
        Multiply the samples by this factor first (raw integer counts), as ``load_log(scale=)``.
    alpha : float
        Interval level ``1 - alpha`` (eta3).
    unit : str, optional
        Signal unit (default: the dataset's ``units`` attribute).
    progress : callable, optional
        ``progress(done, total)`` in samples read, called once per block.

    Returns
    -------
    WaveletVariance
        The same numbers as ``wavelet_variance(x, fs=fs, levels=levels)`` (classical).

    Raises
    ------
    ValueError
        Unreadable source, NaN/Inf samples, fewer than 4 samples, bad ``block``/``levels``.
    """
    if not (isinstance(block, (int, np.integer)) and block >= 1024 and block & (block - 1) == 0):
        raise ValueError(f"block must be a power of two >= 1024, got {block!r}")
    block = int(block)
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    if scale is not None and not (math.isfinite(scale) and scale != 0):
        raise ValueError(f"scale must be a finite non-zero number, got {scale!r}")
    src = open_series(source, dataset=dataset, column=column, fs=fs)
    clones: list[SeriesSource] = []
    try:
        n = src.n
        fs_v = check_fs(float(fs if fs is not None else src.fs if src.fs is not None else 1.0))
        if n < 4:
            raise ValueError(f"the series has {n} samples; a wavelet variance needs at least 4")
        jmax = default_levels(n)
        levels = jmax if levels is None else int(levels)
        if not 1 <= levels <= jmax:
            raise ValueError(
                f"levels={levels} is out of range: a series of {n} samples "
                f"supports 1 to {jmax} levels"
            )
        lag_levels = [j for j in range(1, levels + 1) if (1 << (j - 1)) >= block]
        small = [j for j in range(1, levels + 1) if j not in lag_levels]
        offsets = sorted({o for j in lag_levels for o in (1 << (j - 1), 1 << j)})
        nblocks = n // block + 1  # the last one holds the final S_N (and maybe no sample)
        total = n + sum(max(n - o, 0) for o in offsets) + n  # samples read, for progress
        mean = _mean(src, n, block, scale, progress, total)

        sums = np.zeros(levels)
        hist = np.zeros(2 * block + 1)
        main = _Stream(src, n, block, mean, scale, buf=hist[block:])
        lags: dict[int, _Stream] = {}
        for o in offsets:
            c = src.clone()
            clones.append(c)
            lags[o // block] = _Stream(c, n, block, mean, scale)
        tmp = np.empty(max(_SUB, block))
        sumsq = sumsq_kernel()
        for k in range(nblocks):
            a = k * block
            s_blk = main.advance()
            used = s_blk.size if k == nblocks - 1 else block  # t positions of this block
            # small levels: S over [a - block, a + used) is hist[0 : block + used]
            _small_sums(hist, a - block, a, a + used, small, sums, tmp)
            for j in lag_levels:
                m = 1 << (j - 1)
                if a < 2 * m:
                    continue
                s1 = lags[m // block].get(k - m // block)[:used]
                s2 = lags[2 * m // block].get(k - 2 * m // block)[:used]
                d = tmp[:used]
                np.multiply(s1, -2.0, out=d)
                d += s_blk[:used]
                d += s2
                sums[j - 1] += sumsq(d, d)
            if k < nblocks - 1:
                hist[:block] = hist[block : 2 * block]
            if progress is not None:
                done = n + main.samples_read + sum(st.samples_read for st in lags.values())
                progress(min(done, total), total)
    finally:
        for c in clones:
            c.close()
        src.close()
    return WaveletVariance.from_sums(
        sums, n, fs=fs_v, alpha=alpha, unit=src.unit if unit is None else unit
    )
