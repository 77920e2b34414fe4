"""The WV cache of a session: wavelet variances and WV/WCCV matrices of its log (no widgets).

Two typed maps with their own keys, and the eviction rule of the matrices:

* :attr:`WVCache.wvs`: ``(channel, fs, robust, compensated) -> WaveletVariance``
  (``compensated``: of the temperature-compensated signal,
  :func:`gmwm_app.data.is_compensated`). Kept for the log's
  life (a session's log has a few channels, and each WV is a few kB); a WV at another fs is
  the same WV re-labelled, and a robust WV carries the classical one (:func:`wv_from_cache`).
* :attr:`WVCache.matrices`: ``(channels, fs, compensate) -> (WVMatrix, notice)`` of the
  multi-channel
  view; the last :data:`N_WV_MATRICES` stored are kept (one per channel choice, and a
  matrix of 6 channels holds 21 WV/WCCV curves).

The cache is not thread-safe by itself: :class:`gmwm_app.state.AppState` keeps it with the
log under one lock (a new log brings a new cache). The plain ``WVKey -> WV``
dicts of a :class:`gmwm_app.data.LoadedData` (filled in a worker thread before the data are
installed) use the same two functions, :func:`wv_from_cache` and :func:`store_wv`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import engine as eg

__all__ = ["N_WV_MATRICES", "WVCache", "WVKey", "MatrixKey", "wv_from_cache", "store_wv"]

#: WV/WCCV matrices kept in a session's WV cache (multi-channel view).
N_WV_MATRICES = 4

#: Key of a WV: ``(channel, fs in Hz, robust, compensated)``.
WVKey = tuple[str, float, bool, bool]
#: Key of a WV/WCCV matrix: ``(channels, fs in Hz, temperature compensation choice)`` (the
#: choice, not whether each channel is compensated: a matrix mixes channels).
MatrixKey = tuple[tuple[str, ...], float, str]


def wv_from_cache(
    cache: Mapping[WVKey, eg.WaveletVariance],
    channel: str,
    fs: float,
    robust: bool,
    compensated: bool,
) -> eg.WaveletVariance | None:
    """A cached WV for ``(channel, fs, robust, compensated)``, derived without recomputation
    when possible.

    Parameters
    ----------
    cache : mapping
        ``(channel, fs, robust, compensated) -> WaveletVariance``.
    channel, fs, robust, compensated
        The WV asked for.

    Returns
    -------
    WaveletVariance or None
        The cached WV; else one of the channel at another fs, re-labelled; else the classical
        WV a robust one carries; else None (it must be computed).
    """
    hit = cache.get((channel, fs, robust, compensated))
    if hit is not None:
        return hit
    for (ch, _fs, rob, comp), wv in list(cache.items()):
        if ch != channel or comp != compensated:
            continue
        if rob == robust:
            return wv.with_fs(fs)
        if not robust and rob and wv.classical is not None:
            return wv.classical.with_fs(fs)
    return None


def store_wv(
    cache: dict[WVKey, eg.WaveletVariance],
    ch: str,
    fs: float,
    robust: bool,
    compensated: bool,
    wv: eg.WaveletVariance,
) -> None:
    """Put ``wv`` in a WV map under ``(ch, fs, robust, compensated)`` (and the classical WV a
    robust one carries under ``(ch, fs, False, compensated)``, unless there is one)."""
    cache[(ch, fs, robust, compensated)] = wv
    if robust and wv.classical is not None:
        cache.setdefault((ch, fs, False, compensated), wv.classical)


class WVCache:
    """The WVs and the WV/WCCV matrices computed of one log (see the module docstring).

    Parameters
    ----------
    wvs : mapping, optional
        WVs to start with, ``(channel, fs, robust, compensated) -> WaveletVariance`` (copied).
    n_matrices : int
        How many WV/WCCV matrices are kept (the latest stored).
    """

    def __init__(
        self,
        wvs: Mapping[WVKey, eg.WaveletVariance] | None = None,
        n_matrices: int = N_WV_MATRICES,
    ) -> None:
        self.wvs: dict[WVKey, eg.WaveletVariance] = dict(wvs or {})
        self.matrices: dict[MatrixKey, tuple[eg.wv.WVMatrix, str]] = {}
        self.n_matrices = int(n_matrices)

    def find(
        self, channel: str, fs: float, robust: bool, compensated: bool
    ) -> eg.WaveletVariance | None:
        """The WV of ``(channel, fs, robust, compensated)`` if it is cached or derived from a
        cached one (:func:`wv_from_cache`; a derived WV is kept under its own key), else None."""
        wv = wv_from_cache(self.wvs, channel, fs, robust, compensated)
        if wv is not None:
            self.wvs[(channel, fs, robust, compensated)] = wv
        return wv

    def store(
        self, channel: str, fs: float, robust: bool, compensated: bool, wv: eg.WaveletVariance
    ) -> None:
        """Keep a computed WV (:func:`store_wv`)."""
        store_wv(self.wvs, channel, fs, robust, compensated, wv)

    def matrix(
        self, channels: Sequence[str], fs: float, compensate: str = "off"
    ) -> tuple[eg.wv.WVMatrix, str] | None:
        """The cached WV/WCCV matrix of ``channels`` at ``fs`` (of the signals the
        temperature compensation choice ``compensate`` compensates) and its notice, or None."""
        return self.matrices.get((tuple(channels), float(fs), str(compensate)))

    def store_matrix(
        self,
        channels: Sequence[str],
        fs: float,
        out: tuple[eg.wv.WVMatrix, str],
        compensate: str = "off",
    ) -> None:
        """Keep a WV/WCCV matrix and its notice; the oldest beyond :attr:`n_matrices` go."""
        self.matrices[(tuple(channels), float(fs), str(compensate))] = out
        for key in list(self.matrices)[: -self.n_matrices]:
            del self.matrices[key]
