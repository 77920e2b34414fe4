"""Latent processes of an inertial-sensor error model, with their Haar WV and simulators.

Each process is a small frozen dataclass. Parameters are per sample (discrete time), except
GM, which is continuous time (``beta`` in 1/s). Scales ``tau`` are in samples (``2^j``).
A parameter left as ``None`` is unknown (the fitter estimates it).

For fitting, every process contributes one non-negative *linear* coefficient ``h`` (its
variance-like parameter) times a *basis* WV curve; AR1 and GM also have one non-linear
parameter (phi, beta) that shapes their basis. The fitter solves for ``h`` by non-negative
least squares and searches the non-linear parameters (variable projection).

Each class also owns the rest of its behaviour (spectral density, projection onto a filter's
model, datasheet quantities, names): see :class:`engine.models.Process`.

Reference: Guerrier et al. (2013), "Wavelet variance based estimation for composite
stochastic processes", JASA; ``docs/conventions.md``, "Latent processes and their Haar WV".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .._limits import check_sample_count
from .._quantity import Quantity, per_s, sqrt0, squared, times_s
from .model import Process, coefficient_unit, param, per_sample_unit, rate_unit
from .spectrum import FilterTerms, PsdTerms

__all__ = ["WN", "QN", "RW", "DR", "AR1", "GM", "ar1_wv", "ar1_wv_pos", "TC_MIN", "TC_MAX_FACTOR"]

# Range of the correlation time (in samples) of AR1/GM processes that the fitter explores.
TC_MIN = 1e-2
TC_MAX_FACTOR = 1e4  # times the series length


def _series_coefficients(t: np.ndarray) -> np.ndarray:
    """The (4, J) coefficients ``c_k(t)`` of :func:`ar1_wv_pos`'s series ``sum_k c_k x^k``,
    cached per scale vector (a fit evaluates thousands of ``phi`` on the same scales)."""
    key = t.tobytes()
    coef = _SERIES_CACHE.get(key)
    if coef is None:
        s = t
        coef = np.array(
            [
                s / 12 + 1 / (6 * s),
                -(s**2) / 32 + s / 12 + 1 / (6 * s),
                7 * s**3 / 960 - s**2 / 32 + s / 48 + 1 / (20 * s),
                -(s**4) / 768 + 7 * s**3 / 960 - s**2 / 128 - s / 144 - 1 / (180 * s),
            ]
        )
        if len(_SERIES_CACHE) > 256:
            _SERIES_CACHE.clear()
        _SERIES_CACHE[key] = coef
    return coef


_SERIES_CACHE: dict[bytes, np.ndarray] = {}


def _scale_terms(t: np.ndarray) -> np.ndarray:
    """``-t / 2``, ``1 / t``, ``1 / t^2`` and (every entry) ``min(t)`` as a (4, J) array,
    cached like :func:`_series_coefficients`."""
    key = b"scale" + t.tobytes()
    terms = _SERIES_CACHE.get(key)
    if terms is None:
        terms = np.array([-0.5 * t, 1.0 / t, 1.0 / (t * t), np.full(t.shape, t.min())])
        if len(_SERIES_CACHE) > 256:
            _SERIES_CACHE.clear()
        _SERIES_CACHE[key] = terms
    return terms


def _ar1_rows(ps: list[float], terms: np.ndarray, t: np.ndarray) -> np.ndarray:
    """:func:`ar1_wv_pos` of each ``phi`` of ``ps``, one row each, with ``terms`` the
    :func:`_scale_terms` of ``t`` (a fit's search prepares them once: :meth:`GM.search_kernel`).

    ``phi^t - 4 phi^(t/2) + 3 = B (B - 2)`` with ``B = phi^(t/2) - 1`` (t even): one expm1;
    the row's constants divided by ``e_1^3 (phi + 1)`` once, as Python floats; the series
    where ``x t < 2e-3`` (``x = -ln phi``), in the rows that reach it.
    """
    xs = [-math.log(p) for p in ps]
    co = []
    for x, p in zip(xs, ps, strict=True):
        d = 1.0 / (math.expm1(-x) ** 3 * (p + 1))
        co.append((math.expm1(-2 * x) * d, 2 * p * d))
    coef = np.array(co)
    neg_half_t, inv_t, inv_t2, t_min = terms
    hx = np.multiply.outer(xs, neg_half_t)  # -x t / 2
    half = np.expm1(hx)
    out = coef[:, :1] * inv_t + coef[:, 1:] * (half * (half - 2)) * inv_t2
    if min(xs) * t_min[0] < 2e-3:  # the series where x t < 2e-3, in some row
        c = _series_coefficients(t)
        xc = np.array(xs)[:, None]
        series = ((c[3] * xc + c[2]) * xc + c[1]) * xc + c[0]
        out = np.where(hx > -1e-3, series, out)
    return out


def ar1_wv_pos(t: np.ndarray, phi: float | np.ndarray) -> np.ndarray:
    """:func:`ar1_wv` for ``0 < phi < 1``, unit innovation variance (the fit's hot path).

    Parameters
    ----------
    t : ndarray of float, shape (J,)
        Scales in samples, in any order (a replicate fit stacks several scale vectors).
    phi : float or ndarray, shape (k,)
        Autoregressive coefficient(s), ``0 < phi < 1``.

    Returns
    -------
    ndarray, shape (J,), or (k, J) for an array ``phi``
        The WV per unit innovation variance (a new array).
    """
    if isinstance(phi, np.ndarray):  # several at once, one row each (the search's hot path)
        return _ar1_rows(phi.tolist(), _scale_terms(t), t)
    x = -math.log(phi)
    e_2 = math.expm1(-2 * x)
    e_1 = math.expm1(-x)
    out = (e_2 * t + 2 * phi * (np.expm1(-x * t) - 4 * np.expm1(-0.5 * x * t))) / (
        e_1**3 * (phi + 1) * t * t
    )
    if x * t.min() < 2e-3:  # the series where x t < 2e-3 (cached coefficients, Horner)
        near = x * t < 2e-3
        c = _series_coefficients(t)[:, near]
        out[near] = ((c[3] * x + c[2]) * x + c[1]) * x + c[0]
    return out


def ar1_wv(
    tau: np.ndarray, phi: float | np.ndarray, sigma2: float | np.ndarray = 1.0
) -> np.ndarray:
    """Haar WV of an AR1(phi, sigma2) at scales ``tau`` (samples), numerically stable.

    ``sigma2 [(phi^2-1) tau + 2 phi (phi^tau - 4 phi^(tau/2) + 3)] / [(phi-1)^3 (phi+1) tau^2]``.
    For ``phi = exp(-x)`` close to 1 and ``x tau < 2e-3`` a 4-term series in ``x`` is used
    (the closed form cancels there); its relative truncation error is below ``(x tau)^4``.
    Powers ``phi^k - 1`` use ``expm1`` so no digits are lost for phi near 1.

    Parameters
    ----------
    tau : array_like, shape (J,)
        Scales in samples.
    phi : float or array_like, shape (C,)
        Autoregressive coefficient(s), ``|phi| < 1``. An array gives a (C, J) result.
    sigma2 : float or array_like, shape (C,)
        Innovation variance(s).
    """
    tau = np.asarray(tau, dtype=float)
    ph = np.asarray(phi, dtype=float)
    if np.any(np.abs(ph) >= 1.0):
        raise ValueError(f"AR1 needs |phi| < 1, got phi={phi}")
    scalar = ph.ndim == 0
    if scalar and ph > 0:
        return ar1_wv_pos(tau, float(ph)) * float(sigma2)
    ph = np.atleast_1d(ph)[:, None]
    t = tau[None, :]
    pos = ph > 0
    with np.errstate(all="ignore"):
        x = np.where(pos, -np.log(np.where(pos, ph, 0.5)), 0.0)
        # phi^k - 1 (expm1 for phi > 0; a plain power, sign included, for phi < 0)
        e_t = np.where(pos, np.expm1(-x * t), ph**t - 1)
        e_h = np.where(pos, np.expm1(-x * t / 2), ph ** (t / 2) - 1)
        e_2 = np.where(pos, np.expm1(-2 * x), ph * ph - 1)
        e_1 = np.where(pos, np.expm1(-x), ph - 1)
        closed = (e_2 * t + 2 * ph * (e_t - 4 * e_h)) / (e_1**3 * (ph + 1) * t**2)
        series = (
            t / 12
            + 1 / (6 * t)
            + x * (-(t**2) / 32 + t / 12 + 1 / (6 * t))
            + x**2 * (7 * t**3 / 960 - t**2 / 32 + t / 48 + 1 / (20 * t))
            + x**3 * (-(t**4) / 768 + 7 * t**3 / 960 - t**2 / 128 - t / 144 - 1 / (180 * t))
        )
        out = np.where(pos & (x * t < 2e-3), series, closed)
        out = np.where(ph == 0, 1.0 / t, out)
    out = out * np.atleast_1d(np.asarray(sigma2, dtype=float))[:, None]
    return out[0] if scalar else out


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


# Datasheet quantities of a GM (an AR1 is reported as the GM it samples); conversions in
# engine.units' module docstring and docs/conventions.md, "Units and datasheet conversions".
_GM_QUANTITIES = (
    Quantity(
        "GM",
        "T_c",
        "correlation time",
        "beta",
        lambda p, fs: 1.0 / p["beta"],
        lambda v, fs: 1.0 / v,
        lambda u: "s",
        si=False,
    ),
    Quantity(
        "GM",
        "sigma_gm",
        "stationary std",
        "sigma2_gm",
        lambda p, fs: sqrt0(p["sigma2_gm"]),
        lambda v, fs: v * v,
        lambda u: u,
        si=False,
    ),
    Quantity(
        "GM",
        "q",
        "driving-noise PSD",
        "",
        lambda p, fs: 2.0 * p["beta"] * p["sigma2_gm"],
        None,
        lambda u: f"{squared(u)}/s",
        si=False,
    ),
    Quantity(
        "GM",
        "sqrt(q)",
        "driving-noise density",
        "",
        lambda p, fs: sqrt0(2.0 * p["beta"] * p["sigma2_gm"]),
        None,
        lambda u: f"{per_s(u)}/sqrt(Hz)",
    ),
)


def _ar_filter_terms(phi: float, s2: float, fs: float, fs_filter: float) -> FilterTerms:
    """The filter rule of an AR1/GM with coefficient ``phi`` and stationary variance ``s2``:
    white noise when its correlation time is below the filter step (equivalent variance
    ``s2 (1 + phi) / (1 - phi)``), else a bias GM (beta = 1 / T_c) whose random-walk density
    is ``2 beta s2``."""
    dt_f = 1.0 / fs_filter
    tc = -1.0 / (fs * math.log(phi)) if 0.0 < phi < 1.0 else 0.0
    if tc < dt_f:
        return FilterTerms(
            white=s2 * (1.0 + phi) / (1.0 - phi),
            fast=True,
            assignment=(
                f"WN (T_c {tc:.3g} s < filter step {dt_f:.3g} s: white noise, "
                "equivalent sigma2_gm (1+phi)/(1-phi))"
            ),
        )
    beta = 1.0 / tc
    return FilterTerms(
        rw_k2=2.0 * beta * s2, slow=(beta, s2), assignment=f"bias (T_c {tc:.4g} s >= filter step)"
    )


def _ar_shared(z: np.ndarray, x0: np.ndarray, phi: float, innovation_factor: float) -> np.ndarray:
    """An AR1 per column: innovations ``z * innovation_factor``, start ``x0`` (stationary)."""
    from scipy.signal import lfilter  # lazy: scipy.signal takes 0.3 s to import

    innov = z if innovation_factor == 1.0 else z * innovation_factor
    return lfilter([1.0], [1.0, -phi], innov, axis=0, zi=(phi * x0)[None, :])[0]


@dataclass(frozen=True, repr=False)
class WN(Process, order=3, description="white noise"):
    """White noise: iid, variance ``sigma2`` [u^2]. WV ``sigma2 / tau``.

    Examples
    --------
    Its implied WV at dyadic scales (samples) against the closed form; processes add up to
    a :class:`~engine.models.Model`, whose WV is the sum of theirs:

    >>> import numpy as np
    >>> import engine as eg
    >>> tau = np.array([2.0, 4.0, 8.0, 16.0])
    >>> print(*(f"{v:.4g}" for v in eg.WN(sigma2=2.0).wv(tau)))
    1 0.5 0.25 0.125
    >>> m = eg.WN(2.0) + eg.RW(0.03)
    >>> m.spec(values=True)
    'WN(sigma2=2.0)+RW(gamma2=0.03)'
    >>> bool(np.allclose(m.wv(tau), 2.0 / tau + 0.03 * (tau**2 + 2) / (12 * tau)))
    True
    """

    sigma2: float | None = param()

    display_name = "white noise"
    help = "white noise: WV falls as 1/τ (angle/velocity random walk)"
    color = "#1F77B4"
    allan_slope = -0.5
    unique = True
    read_tau = 1.0
    shareable = True
    quantities = (
        Quantity(
            "WN",
            "N",
            "white noise density",
            "sigma2",
            lambda p, fs: sqrt0(p["sigma2"] / fs),
            lambda v, fs: v * v * fs,
            lambda u: f"{u}/sqrt(Hz)",
        ),
    )

    def psd_terms(self, fs):
        (s2,) = self._require()
        return PsdTerms({0: s2})

    def filter_terms(self, fs, fs_filter, horizon):
        (s2,) = self._require()
        return FilterTerms(white=s2, fast=True, assignment=self.code)

    def simulate_shared(self, z, root, phi, rng):
        return z

    def basis(self, tau, fs, nl=None):
        return 1.0 / tau

    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        (s2,) = self._require()
        return _rng(rng).normal(0.0, math.sqrt(s2), n)

    def autocovariance(self, lags, fs=1.0):
        (s2,) = self._require()
        return np.where(np.asarray(lags) == 0, s2, 0.0)


@dataclass(frozen=True, repr=False)
class QN(Process, order=2, description="quantization noise"):
    """Quantization noise ``sqrt(q2) (U_t - U_{t-1})``, ``Var U = 1``. WV ``6 q2 / tau^2``.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> tau = np.array([2.0, 4.0, 8.0])
    >>> print(*(f"{v:.4g}" for v in eg.QN(q2=2.0).wv(tau)))  # 12 / tau^2
    3 0.75 0.1875
    >>> x = eg.QN(q2=2.0).simulate(2**16, rng=np.random.default_rng(1))
    >>> round(float(np.var(x)), 2)  # 2 q2
    4.0
    """

    q2: float | None = param()

    display_name = "quantization noise"
    help = "quantization noise: WV falls as 1/τ²"
    color = "#9467BD"
    allan_slope = -1.0
    unique = True
    read_tau = math.sqrt(3.0)
    quantities = (
        Quantity(
            "QN",
            "Q",
            "quantization",
            "q2",
            lambda p, fs: sqrt0(p["q2"]) / fs,
            lambda v, fs: (v * fs) ** 2,
            times_s,
        ),
    )

    def psd_terms(self, fs):
        (q2,) = self._require()
        return PsdTerms({1: q2})

    def filter_terms(self, fs, fs_filter, horizon):
        # white equivalent at the filter rate: the filter averages m = fs / fs_f log samples
        (q2,) = self._require()
        m = max(fs / fs_filter, 1.0)
        return FilterTerms(
            white=3.0 * q2 / m,
            fast=True,
            assignment="WN (QN's white equivalent at the filter rate, 3 q2 / m)",
        )

    def basis(self, tau, fs, nl=None):
        return 6.0 / tau**2

    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        (q2,) = self._require()
        u = _rng(rng).uniform(-math.sqrt(3.0), math.sqrt(3.0), n + 1)
        return math.sqrt(q2) * np.diff(u)

    def autocovariance(self, lags, fs=1.0):
        (q2,) = self._require()
        lags = np.abs(np.asarray(lags))
        return np.select([lags == 0, lags == 1], [2 * q2, -q2], 0.0)


@dataclass(frozen=True, repr=False)
class RW(Process, order=4, description="random walk"):
    """Random walk: cumulative sum of iid N(0, gamma2). WV ``gamma2 (tau^2 + 2) / (12 tau)``.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> tau = np.array([2.0, 4.0, 8.0])
    >>> print(*(f"{v:.4g}" for v in eg.RW(gamma2=12.0).wv(tau)))  # (tau^2 + 2) / tau
    3 4.5 8.25
    """

    gamma2: float | None = param()

    display_name = "random walk"
    help = "random walk: WV rises as τ (rate random walk)"
    color = "#2CA02C"
    allan_slope = 0.5
    unique = True
    read_tau = 3.0
    shareable = True
    quantities = (
        Quantity(
            "RW",
            "K",
            "rate random walk",
            "gamma2",
            lambda p, fs: sqrt0(p["gamma2"] * fs),
            lambda v, fs: v * v / fs,
            lambda u: f"{per_s(u)}/sqrt(Hz)",
            accel_name="acceleration random walk",
        ),
    )

    def psd_terms(self, fs):
        (g2,) = self._require()
        return PsdTerms({-1: g2})

    def filter_terms(self, fs, fs_filter, horizon):
        (g2,) = self._require()
        return FilterTerms(rw_k2=g2 * fs, gamma2=g2, assignment="bias")

    def simulate_shared(self, z, root, phi, rng):
        return np.cumsum(z, axis=0)

    def basis(self, tau, fs, nl=None):
        return (tau**2 + 2.0) / (12.0 * tau)

    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        (g2,) = self._require()
        return np.cumsum(_rng(rng).normal(0.0, math.sqrt(g2), n))


@dataclass(frozen=True, repr=False)
class DR(Process, order=5, description="drift (rate ramp)"):
    """Drift ``omega * t`` (omega per sample). WV ``omega^2 tau^2 / 16``.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> tau = np.array([2.0, 4.0, 8.0])
    >>> print(*(f"{v:.4g}" for v in eg.DR(omega=2.0).wv(tau)))  # tau^2 / 4
    1 4 16
    >>> print(*eg.DR(omega=2.0).simulate(4))  # deterministic: the ramp
    2.0 4.0 6.0 8.0
    """

    omega: float | None = param(
        "identity", per_sample_unit, (-math.inf, math.inf), "log10", magnitude=True
    )

    display_name = "drift"
    help = "drift (rate ramp): WV rises as τ²"
    color = "#8C564B"
    allan_slope = 1.0
    unique = True
    read_tau = math.sqrt(2.0)
    deterministic = True
    quantities = (
        Quantity(
            "DR",
            "R",
            "rate ramp",
            "omega",
            lambda p, fs: p["omega"] * fs,
            lambda v, fs: v / fs,
            per_s,
            magnitude=True,
            accel_name="acceleration ramp",
        ),
    )

    def psd_terms(self, fs):
        self._require()
        return PsdTerms({})  # deterministic: no first-order contribution to Cov(nu_hat)

    def filter_terms(self, fs, fs_filter, horizon):
        (om,) = self._require()
        return FilterTerms(
            rw_k2=0.75 * om * om * horizon * fs,  # RW with the drift's WV at the horizon
            omega=om,
            assignment="bias (random walk with the drift's WV at the horizon)",
        )

    def _check_value(self, name, v):
        pass  # a drift may have either sign; its WV depends on omega^2

    def basis(self, tau, fs, nl=None):
        return tau**2 / 16.0

    def linear_coef(self):
        (omega,) = self._require()
        return omega**2

    def from_fit(self, h, nl, fs):
        return DR(math.sqrt(max(h, 0.0)))

    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        (om,) = self._require()
        # per sample, as the fit reports it (the R simulator's division by fs is a known defect)
        return om * np.arange(1, n + 1, dtype=float)


def _simulate_ar1(n: int, phi: float, sigma2: float, rng: np.random.Generator) -> np.ndarray:
    from scipy.signal import lfilter  # lazy: scipy.signal takes 0.3 s to import

    e = rng.normal(0.0, math.sqrt(sigma2), n)
    x0 = rng.normal(0.0, math.sqrt(sigma2 / (1.0 - phi * phi)))  # stationary start
    # x_1 = phi x0 + e_1, x_t = phi x_{t-1} + e_t
    return lfilter([1.0], [1.0, -phi], e, zi=[phi * x0])[0]


class _CorrelationTimeSearch:
    """The search coordinate of an AR1 or a GM: ``u = log(correlation time in samples)``,
    ``phi = exp(-1 / exp(u))``, between :data:`TC_MIN` and ``TC_MAX_FACTOR n_max`` samples;
    an AR1 whose ``phi`` may vanish (:attr:`~engine.models.Process.phi_can_vanish`) is
    white (``phi = 0``) below ``u = -50``."""

    phi_can_vanish: ClassVar[bool]

    def search_range(self, n_max: int) -> tuple[float, float]:
        return math.log(TC_MIN), math.log(TC_MAX_FACTOR * n_max)

    def search_axis(self, tau_max: float, k: int) -> np.ndarray:
        # 0.25 to 4x the largest scale; 60 points for one term, 36 for two, 18 for three, 10
        # beyond (the candidates grow as C(n, k))
        n = {1: 60, 2: 36, 3: 18}.get(k, 10)
        return np.linspace(math.log(0.25), math.log(4.0 * tau_max), n)

    def search_nl(self, u, lo, hi):
        if isinstance(u, np.ndarray):
            phi = np.exp(-1.0 / np.exp(np.clip(u, lo, hi)))
            return np.where(u < -50, 0.0, phi) if self.phi_can_vanish else phi
        if self.phi_can_vanish and u < -50:
            return 0.0
        return math.exp(-1.0 / math.exp(min(max(u, lo), hi)))

    def search_of_nl(self, nl):
        if not nl > 0:
            return None
        return math.inf if nl >= 1 else math.log(-1.0 / math.log(nl))

    def correlation_time(self, fs: float) -> float | None:
        phi = self.nl_value(fs)  # type: ignore[attr-defined]
        if phi is None:
            return None
        return -1.0 / math.log(phi) if 0 < phi < 1 else (math.inf if phi >= 1 else 0.0)


@dataclass(frozen=True, repr=False)
class AR1(
    _CorrelationTimeSearch,
    Process,
    order=1,
    description="first-order autoregression",
    nonlinear="phi",
):
    """First-order autoregression ``X_t = phi X_{t-1} + e_t``, ``Var e = sigma2``, ``|phi| < 1``.

    Examples
    --------
    Its autocovariance ``sigma2 phi^h / (1 - phi^2)``, and its WV (:func:`ar1_wv`); at
    ``tau = 2`` the Haar WV of any stationary process is ``(gamma(0) - gamma(1)) / 2``:

    >>> import numpy as np
    >>> import engine as eg
    >>> ar = eg.AR1(phi=0.5, sigma2=1.0)
    >>> print(*(f"{v:.4f}" for v in ar.autocovariance(np.array([0, 1, 2]))))
    1.3333 0.6667 0.3333
    >>> print(*(f"{v:.4f}" for v in ar.wv(np.array([2.0, 4.0, 8.0]))))
    0.3333 0.3125 0.2705
    """

    phi: float | None = param("atanh", coefficient_unit, (-1.0, 1.0), "log10(1-x)")
    sigma2: float | None = param()

    display_name = "AR(1)"
    help = "first-order autoregression (per sample phi, sigma2)"
    shareable = True
    phi_can_vanish = True
    excludes = {
        "GM": "they are the same process in two parametrisations; use only GM (continuous "
        "time) or only AR1 (per sample)"
    }
    quantities = _GM_QUANTITIES  # reported as the GM it samples

    def _check_value(self, name, v):
        if name == "phi" and not -1.0 < v < 1.0:
            raise ValueError(f"AR1.phi must be in (-1, 1), got {v}")
        if name == "sigma2" and v < 0:
            raise ValueError(f"AR1.sigma2 must be >= 0, got {v}")

    # non-linear value: phi itself
    def basis(self, tau, fs, nl=None):
        if type(nl) is float and 0.0 < nl < 1.0 and isinstance(tau, np.ndarray):
            return ar1_wv_pos(tau, nl)  # the search's hot path: ar1_wv without its checks
        return ar1_wv(tau, nl, 1.0)

    def phi_from_nl(self, nl, fs):
        return float(nl)

    def nl_from_phi(self, phi, fs):
        return float(phi)

    def basis_scale(self, phi):
        return 1.0

    def from_fit(self, h, nl, fs):
        return AR1(float(nl), float(h))

    def psd_terms(self, fs):
        phi, s2 = self._require()
        return PsdTerms({}, (phi, s2))

    def filter_terms(self, fs, fs_filter, horizon):
        phi, s2 = self._require()
        return _ar_filter_terms(phi, s2 / (1.0 - phi * phi), fs, fs_filter)

    def datasheet_params(self, fs):
        phi, s2 = self._require()
        if not 0 < phi < 1:
            return None
        return {"beta": -math.log(phi) * fs, "sigma2_gm": s2 / (1.0 - phi * phi)}

    def datasheet_intervals(self, intervals, fs):
        # beta = -ln(phi) fs is monotone in phi alone; sigma2_gm depends on both parameters
        iv = intervals.get("phi")
        if iv is None:
            return {}
        fn = lambda ph: -math.log(ph) * fs if 0 < ph < 1 else math.nan  # noqa: E731
        return {"beta": (fn(iv[0]), fn(iv[1]))}

    @classmethod
    def from_datasheet(cls, values, fs):
        gm = GM.from_datasheet(values, fs)
        phi = math.exp(-gm.beta / fs)
        return AR1(phi=phi, sigma2=gm.sigma2_gm * (1.0 - phi * phi))

    def simulate_shared(self, z, root, phi, rng):
        # c is the innovation covariance; the stationary one is c / (1 - phi^2)
        shrink = math.sqrt(1.0 - phi * phi)
        x0 = rng.standard_normal(z.shape[1]) @ root.T
        return _ar_shared(z, x0 / shrink, phi, 1.0)

    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        phi, s2 = self._require()
        return _simulate_ar1(n, phi, s2, _rng(rng))

    def autocovariance(self, lags, fs=1.0):
        phi, s2 = self._require()
        return s2 / (1 - phi * phi) * phi ** np.abs(np.asarray(lags))


@dataclass(frozen=True, repr=False)
class GM(_CorrelationTimeSearch, Process, order=0, description="Gauss-Markov", nonlinear="beta"):
    """Gauss-Markov (continuous time): ``beta`` [1/s], stationary variance ``sigma2_gm``.

    Sampled at ``fs`` it is an AR1 with ``phi = exp(-beta/fs)`` and innovation variance
    ``sigma2_gm (1 - exp(-2 beta/fs))``.

    Examples
    --------
    A correlation time of 2 s sampled at 10 Hz: the AR1 it samples, the same WV:

    >>> import numpy as np
    >>> import engine as eg
    >>> gm = eg.GM(beta=0.5, sigma2_gm=4.0)
    >>> ar = gm.as_ar1(fs=10.0)
    >>> f"{ar.phi:.6f} {ar.sigma2:.6f}"  # exp(-0.05), 4 (1 - exp(-0.1))
    '0.951229 0.380650'
    >>> tau = np.array([2.0, 32.0, 512.0])
    >>> bool(np.allclose(gm.wv(tau, fs=10.0), ar.wv(tau)))
    True
    >>> print(*(f"{v:.4g}" for v in gm.wv(tau, fs=10.0)))
    0.09754 0.6126 0.276
    """

    beta: float | None = param("log", rate_unit)
    sigma2_gm: float | None = param()

    display_name = "Gauss-Markov"
    help = "Gauss-Markov: a bump at its correlation time 1/beta (bias instability)"
    shareable = True
    quantities = _GM_QUANTITIES

    def _check_value(self, name, v):
        if name == "beta" and not v > 0:
            raise ValueError(f"GM.beta must be > 0 (1/s), got {v}")
        if name == "sigma2_gm" and v < 0:
            raise ValueError(f"GM.sigma2_gm must be >= 0, got {v}")

    # non-linear value: phi = exp(-beta / fs); basis is per unit stationary variance
    def basis(self, tau, fs, nl=None):
        phi = np.asarray(nl, dtype=float)
        return ar1_wv(tau, phi, 1.0 - phi * phi)

    def phi_from_nl(self, nl, fs):
        return math.exp(-float(nl) / fs)

    def nl_from_phi(self, phi, fs):
        return -math.log(phi) * fs

    def basis_scale(self, phi):
        return 1.0 - phi * phi

    def basis_many(self, tau, fs, nls):
        # every row at once (the search's hot path): the AR1 WV times 1 - phi^2
        return ar1_wv_pos(tau, nls) * (1.0 - nls * nls)[:, None]

    def search_kernel(self, tau, fs, lo, hi):
        # basis_many at search_nl's phi, with the scale terms taken once per problem
        t = np.asarray(tau, dtype=float)
        terms = _scale_terms(t).copy()

        def columns(us):
            ps = [math.exp(-1.0 / math.exp(min(max(u, lo), hi))) for u in us]
            return _ar1_rows(ps, terms, t) * np.array([[1.0 - p * p] for p in ps])

        return columns

    def psd_terms(self, fs):
        phi, sigma2 = self.as_ar1(fs)._require()
        return PsdTerms({}, (phi, sigma2))

    def filter_terms(self, fs, fs_filter, horizon):
        beta, s2 = self._require()
        return _ar_filter_terms(math.exp(-beta / fs), s2, fs, fs_filter)

    @classmethod
    def from_datasheet(cls, values, fs):
        t_c, sigma_gm = cls.quantities[0], cls.quantities[1]
        if t_c.inverse is None or sigma_gm.inverse is None:  # pragma: no cover - both invert
            raise ValueError(f"T_c and sigma_gm of {cls.code} must both be invertible")
        return GM(
            beta=t_c.inverse(values["T_c"], fs), sigma2_gm=sigma_gm.inverse(values["sigma_gm"], fs)
        )

    def simulate_shared(self, z, root, phi, rng):
        # c is the stationary covariance; the innovations' is c (1 - phi^2)
        shrink = math.sqrt(1.0 - phi * phi)
        x0 = rng.standard_normal(z.shape[1]) @ root.T
        return _ar_shared(z, x0, phi, shrink)

    def from_fit(self, h, nl, fs):
        return GM(-math.log(float(nl)) * fs, float(h))

    def as_ar1(self, fs: float) -> AR1:
        """The AR1 (phi, sigma2) form of this GM at sampling frequency ``fs``."""
        beta, s2 = self._require()
        phi = math.exp(-beta / fs)
        return AR1(phi, s2 * (1 - phi * phi))

    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        return self.as_ar1(fs).simulate(n, rng)

    def autocovariance(self, lags, fs=1.0):
        return self.as_ar1(fs).autocovariance(lags)
