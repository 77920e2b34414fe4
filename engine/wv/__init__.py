"""Wavelet variances: classical and robust Haar WV, streamed WV, cross-covariance (WCCV).

* :mod:`engine.wv.classical`: :class:`WaveletVariance`, :func:`wavelet_variance` (classical,
  or robust through :mod:`engine.wv.robust`), intervals, the :class:`LevelScales` mixin.
* :mod:`engine.wv._kernel`: the shared kernel (series checks, de-meaned cumulative sum, the
  Haar coefficients, blocked sums of squared second differences), also used by the Allan
  variance.
* :mod:`engine.wv.stream`: the WV of logs larger than memory, read in blocks.
* :mod:`engine.wv.wccv`: the WCCV of two channels and the k x k WV/WCCV matrix.
* :mod:`engine.wv.pooled`: the WV of several segments of one log, pooled.

The streamed WV and the WCCV are imported on first use (PEP 562): the WCCV needs
``scipy.special`` (about 0.1 s), which ``import engine`` does not pay for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._blas import set_blas_threads
from .._checks import check_fs
from .._lazy import lazy_attributes
from ._kernel import as_series
from .classical import (
    LevelScales,
    WaveletVariance,
    default_levels,
    eta3_interval,
    haar_coefficients,
    iter_sampled_haar_coefficients,
    max_levels,
    sampled_haar_coefficients,
    wavelet_variance,
)
from .robust import biweight_constant, robust_scale_biweight, robust_wv

_LAZY: dict[str, tuple[str, ...]] = {
    "stream": ("SeriesSource", "open_series", "wavelet_variance_stream"),
    "wccv": ("WaveletCrossCovariance", "WVMatrix", "wavelet_cross_covariance", "wv_matrix"),
    "allan": ("AllanVariance", "allan_variance"),
    "pooled": ("pooled_wavelet_variance",),
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs (the names of _LAZY)
    from .allan import AllanVariance, allan_variance  # noqa: F401
    from .pooled import pooled_wavelet_variance  # noqa: F401
    from .stream import SeriesSource, open_series, wavelet_variance_stream  # noqa: F401
    from .wccv import WaveletCrossCovariance, WVMatrix, wavelet_cross_covariance, wv_matrix  # noqa: F401

__getattr__, __dir__, _lazy_names = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "WaveletVariance",
    "wavelet_variance",
    "default_levels",
    "haar_coefficients",
    "sampled_haar_coefficients",
    "iter_sampled_haar_coefficients",
    "eta3_interval",
    "LevelScales",
    "biweight_constant",
    "robust_scale_biweight",
    "robust_wv",
    "max_levels",
    "as_series",
    # the sampling-frequency check of every WV (and of the loaders), and the BLAS thread limit
    # under which the WV kernel runs fastest (one thread: the gmwm command and the app set it)
    "check_fs",
    "set_blas_threads",
    *_lazy_names,
]
