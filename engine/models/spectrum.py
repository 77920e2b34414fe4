"""A process in the frequency domain and as a navigation filter sees it.

:class:`Spectral` is the part of the :class:`~engine.models.Process` interface that speaks of
spectra: its pieces (:class:`PsdTerms`, what the closed-form WV covariance works on), the
density they add up to, the white-noise equivalent at f = 0, and what the process contributes
to a filter's WN+RW / WN+GM noise model (:class:`FilterTerms`). Each concrete process gives
``psd_terms`` and ``filter_terms``; the rest follows here, once for all processes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["PsdTerms", "FilterTerms", "Spectral"]


class PsdTerms(NamedTuple):
    """A process's two-sided spectral density, in cycles/sample, as pieces of
    ``x = |1 - e^(2 pi i f)|^2 = 4 sin^2(pi f)``:

    ``S(f) = sum_p poly[p] x^p + s / ((1 - phi)^2 + phi x)`` with ``(phi, s) = ar``.

    QN is ``q2 x``, WN ``sigma2``, RW (generalised) ``gamma2 / x``, an AR1 (phi, s) the last
    term (``|1 - phi z|^2 = (1 - phi)^2 + phi x``, stable near phi = 1); a drift has none.
    The closed-form WV covariance (``engine.fit._closed_form``) works on these pieces.
    """

    poly: dict[int, float]
    ar: tuple[float, float] | None = None


class FilterTerms(NamedTuple):
    """What one fitted process contributes to a filter's WN+RW / WN+GM model (the rule of
    ``engine.formats.bound.split_terms``).

    ``white``: white-noise variance per log sample (a term white at the filter step);
    ``rw_k2``: continuous random-walk density ``K^2`` [u^2/s]; ``gamma2``: RW per sample;
    ``omega``: the drift per sample (None for other processes); ``slow``: ``(beta, sigma2_gm)``
    of a bias GM (None otherwise); ``fast``: the term goes to the white part;
    ``assignment``: what the rule did, in words.
    """

    white: float = 0.0
    rw_k2: float = 0.0
    gamma2: float = 0.0
    omega: float | None = None
    slow: tuple[float, float] | None = None
    fast: bool = False
    assignment: str = ""


class Spectral:
    """The spectral side of a process (mixed into :class:`~engine.models.Process`)."""

    # ---- spectrum ----------------------------------------------------------------------------
    def psd_terms(self, fs: float) -> PsdTerms:
        """The spectral density in pieces (:class:`PsdTerms`); every value must be set."""
        raise NotImplementedError

    def psd(self, f: np.ndarray, fs: float) -> np.ndarray:
        """Two-sided spectral density on ``f`` in cycles/sample (``0 < f <= 1/2``) [u^2 per
        cycle/sample]; a random walk's is the generalised ``gamma2 / (4 sin^2(pi f))``, a
        drift's is 0 (deterministic).

        ``S(f) = sum_p c_p x^p + s / ((1 - phi)^2 + phi x)``, ``x = 4 sin^2(pi f)``
        (:meth:`psd_terms`). The one-sided density in u^2/Hz is ``2 S(f / fs) / fs``.
        """
        f = np.asarray(f, dtype=float)
        terms = self.psd_terms(fs)
        x = 4.0 * np.sin(np.pi * f) ** 2
        out = np.zeros_like(f)
        for p, c in terms.poly.items():
            out = out + (c * x**p if p >= 0 else c / x ** (-p))
        if terms.ar is not None:
            phi, s = terms.ar
            out = out + s / ((1.0 - phi) ** 2 + phi * x)
        return out

    def white_equivalent(self, fs: float) -> float:
        """Variance per sample of the white noise with the process's density at f = 0,
        ``S(0)`` (an AR1 ``sigma2 / (1 - phi)^2``; inf for a random walk, 0 for QN)."""
        terms = self.psd_terms(fs)
        if any(p < 0 and c > 0 for p, c in terms.poly.items()):
            return math.inf
        out = float(terms.poly.get(0, 0.0))
        if terms.ar is not None:
            phi, s = terms.ar
            out += s / (1.0 - phi) ** 2
        return out

    # ---- projection onto a filter's model ------------------------------------------------------
    def filter_terms(self, fs: float, fs_filter: float, horizon: float) -> FilterTerms:
        """What the process adds to a filter's WN+RW / WN+GM model (:class:`FilterTerms`).

        Parameters
        ----------
        fs : float
            Sampling frequency of the log (Hz).
        fs_filter : float
            The filter's rate (Hz); a term whose correlation time is below its step is white.
        horizon : float
            Horizon in log samples at which a drift's WV is matched by a random walk.
        """
        raise NotImplementedError
