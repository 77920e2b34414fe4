"""Latent processes of an inertial-sensor error model, with their Haar WV and simulators.

Each process is a small frozen dataclass. Parameters are per sample (discrete time), except
GM, which is continuous time (``beta`` in 1/s). Scales ``tau`` are in samples (``2^j``).
A parameter left as ``None`` is unknown (the fitter estimates it).

For fitting, every process contributes one non-negative *linear* coefficient ``h`` (its
variance-like parameter) times a *basis* WV curve; AR1 and GM also have one non-linear
parameter (phi, beta) that shapes their basis. The fitter solves for ``h`` by non-negative
least squares and searches the non-linear parameters (variable projection).

Reference: Guerrier et al. (2013), "Wavelet variance based estimation for composite
stochastic processes", JASA; CONVENTIONS.md, "Latent processes and their Haar WV".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .model import Model

__all__ = ["Process", "WN", "QN", "RW", "DR", "AR1", "GM", "PROCESS_TYPES", "ar1_wv"]

# Range of the correlation time (in samples) of AR1/GM processes that the fitter explores.
TC_MIN = 1e-2
TC_MAX_FACTOR = 1e4  # times the series length


def ar1_wv_pos(t: np.ndarray, phi: float) -> np.ndarray:
    """:func:`ar1_wv` for one ``0 < phi < 1``, unit innovation variance (the fit's hot path)."""
    x = -math.log(phi)
    e_2 = math.expm1(-2 * x)
    e_1 = math.expm1(-x)
    out = (e_2 * t + 2 * phi * (np.expm1(-x * t) - 4 * np.expm1(-0.5 * x * t))) / (
        e_1**3 * (phi + 1) * t * t
    )
    if x * t[0] < 2e-3:
        small = x * t < 2e-3
        s = t[small]
        out[small] = (
            s / 12
            + 1 / (6 * s)
            + x * (-(s**2) / 32 + s / 12 + 1 / (6 * s))
            + x**2 * (7 * s**3 / 960 - s**2 / 32 + s / 48 + 1 / (20 * s))
            + x**3 * (-(s**4) / 768 + 7 * s**3 / 960 - s**2 / 128 - s / 144 - 1 / (180 * s))
        )
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


@dataclass(frozen=True)
class Process:
    """Base class of a latent process. Subclasses set ``code``, ``param_names``, ``units``."""

    code: ClassVar[str] = ""
    param_names: ClassVar[tuple[str, ...]] = ()
    # the non-linear parameter's name (AR1/GM), else None
    nonlinear: ClassVar[str | None] = None
    description: ClassVar[str] = ""

    # ---- values -------------------------------------------------------------------------
    @property
    def values(self) -> tuple[float | None, ...]:
        """Parameter values in ``param_names`` order (None where unknown)."""
        return tuple(getattr(self, f.name) for f in fields(self))

    @property
    def is_set(self) -> bool:
        """True when every parameter has a value."""
        return all(v is not None for v in self.values)

    def with_values(self, *args: float | None, **kwargs: float | None) -> Process:
        """A copy with new parameter values (positional in ``param_names`` order, or named)."""
        vals = dict(zip(self.param_names, self.values, strict=True))
        if len(args) > len(self.param_names):
            raise ValueError(
                f"{self.code} takes {len(self.param_names)} parameters: "
                f"{', '.join(self.param_names)}"
            )
        for name, v in zip(self.param_names, args, strict=False):
            vals[name] = v
        for name, v in kwargs.items():
            if name not in vals:
                raise ValueError(
                    f"{self.code} has no parameter {name!r}; "
                    f"its parameters are {', '.join(self.param_names)}"
                )
            vals[name] = v
        return type(self)(**vals)

    def cleared(self) -> Process:
        """The same process with every value unknown."""
        return type(self)()

    def _require(self) -> tuple[float, ...]:
        if not self.is_set:
            missing = [n for n, v in zip(self.param_names, self.values, strict=True) if v is None]
            raise ValueError(
                f"{self.code} has no value for {', '.join(missing)}; "
                f"give it, e.g. {self.code}({missing[0]}=...)"
            )
        return tuple(float(v) for v in self.values)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        for name, v in zip(self.param_names, self.values, strict=True):
            if v is None:
                continue
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"{self.code}.{name} must be a finite number, got {v!r}")
            self._check_value(name, float(v))

    def _check_value(self, name: str, v: float) -> None:
        if v < 0:
            raise ValueError(f"{self.code}.{name} must be >= 0, got {v}")

    # ---- bounds and the unconstrained space ------------------------------------------------
    def bounds(self, fs: float = 1.0) -> dict[str, tuple[float, float]]:
        """Admissible range of each parameter (open where the transform is)."""
        return {n: (0.0, math.inf) for n in self.param_names}

    def to_unconstrained(self, fs: float = 1.0) -> np.ndarray:
        """Values mapped to R^k: log of variances and rates, atanh of phi, omega as is."""
        vals = self._require()
        return np.array([_FORWARD[n](v) for n, v in zip(self.param_names, vals, strict=True)])

    def from_unconstrained(self, u: np.ndarray, fs: float = 1.0) -> Process:
        """Inverse of :meth:`to_unconstrained`: a process with the mapped-back values."""
        u = np.asarray(u, dtype=float)
        if u.shape != (len(self.param_names),):
            raise ValueError(
                f"{self.code} takes {len(self.param_names)} unconstrained values, "
                f"got shape {u.shape}"
            )
        return type(self)(
            *(_BACKWARD[n](float(x)) for n, x in zip(self.param_names, u, strict=True))
        )

    # ---- fitting interface ----------------------------------------------------------------
    def basis(self, tau: np.ndarray, fs: float, nl: float | None = None) -> np.ndarray:
        """WV per unit of the linear coefficient, at scales ``tau`` (samples)."""
        raise NotImplementedError

    def linear_coef(self) -> float:
        """The linear coefficient ``h`` of the current values (``basis * h`` is the WV)."""
        raise NotImplementedError

    def from_fit(self, h: float, nl: float | None, fs: float) -> Process:
        """Process with values from a linear coefficient and a non-linear value."""
        raise NotImplementedError

    def nl_value(self, fs: float) -> float | None:
        """The non-linear value in the fitter's space (correlation time in samples)."""
        return None

    # ---- model-implied WV and simulation ------------------------------------------------------
    def wv(self, tau: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Implied Haar WV at scales ``tau`` (samples)."""
        self._require()
        return self.linear_coef() * self.basis(np.asarray(tau, float), fs, self.nl_value(fs))

    def simulate(
        self, n: int, rng: np.random.Generator | int | None = None, fs: float = 1.0
    ) -> np.ndarray:
        """Simulate ``n`` samples (AR1/GM start from the stationary distribution)."""
        raise NotImplementedError

    def autocovariance(self, lags: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Autocovariance at integer lags (stationary processes only)."""
        raise TypeError(f"{self.code} is not stationary: it has no autocovariance function")

    # ---- algebra --------------------------------------------------------------------------
    def __add__(self, other: Any) -> Model:
        from .model import Model

        return Model((self,)) + other

    def __radd__(self, other: Any) -> Model:
        from .model import Model

        if other == 0:
            return Model((self,))
        return Model.coerce(other) + Model((self,))

    def __mul__(self, k: int) -> Model:
        from .model import Model

        return Model((self,)) * k

    __rmul__ = __mul__

    def spec(self) -> str:
        """``CODE`` or ``CODE(name=value, ...)``."""
        if all(v is None for v in self.values):
            return self.code
        parts = [
            f"{n}={v!r}"
            for n, v in zip(self.param_names, self.values, strict=True)
            if v is not None
        ]
        return f"{self.code}({', '.join(parts)})"

    def __repr__(self) -> str:
        if all(v is None for v in self.values):
            return f"{self.code}()"
        return self.spec()


# Transforms to the unconstrained space, by parameter name: variances and rates by log, the AR1
# coefficient by atanh (|phi| < 1), the drift slope (either sign) unchanged.
_FORWARD = {
    "sigma2": math.log,
    "q2": math.log,
    "gamma2": math.log,
    "sigma2_gm": math.log,
    "beta": math.log,
    "phi": math.atanh,
    "omega": float,
}
_BACKWARD = {
    "sigma2": math.exp,
    "q2": math.exp,
    "gamma2": math.exp,
    "sigma2_gm": math.exp,
    "beta": math.exp,
    "phi": lambda u: min(max(math.tanh(u), -1 + 2**-52), 1 - 2**-52),
    "omega": float,
}


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


@dataclass(frozen=True, repr=False)
class WN(Process):
    """White noise: iid, variance ``sigma2`` [u^2]. WV ``sigma2 / tau``."""

    sigma2: float | None = None
    code: ClassVar[str] = "WN"
    param_names: ClassVar[tuple[str, ...]] = ("sigma2",)
    description: ClassVar[str] = "white noise"

    def basis(self, tau, fs, nl=None):
        return 1.0 / tau

    def linear_coef(self):
        return float(self.sigma2)

    def from_fit(self, h, nl, fs):
        return WN(float(h))

    def simulate(self, n, rng=None, fs=1.0):
        (s2,) = self._require()
        return _rng(rng).normal(0.0, math.sqrt(s2), n)

    def autocovariance(self, lags, fs=1.0):
        (s2,) = self._require()
        return np.where(np.asarray(lags) == 0, s2, 0.0)


@dataclass(frozen=True, repr=False)
class QN(Process):
    """Quantization noise ``sqrt(q2) (U_t - U_{t-1})``, ``Var U = 1``. WV ``6 q2 / tau^2``."""

    q2: float | None = None
    code: ClassVar[str] = "QN"
    param_names: ClassVar[tuple[str, ...]] = ("q2",)
    description: ClassVar[str] = "quantization noise"

    def basis(self, tau, fs, nl=None):
        return 6.0 / tau**2

    def linear_coef(self):
        return float(self.q2)

    def from_fit(self, h, nl, fs):
        return QN(float(h))

    def simulate(self, n, rng=None, fs=1.0):
        (q2,) = self._require()
        u = _rng(rng).uniform(-math.sqrt(3.0), math.sqrt(3.0), n + 1)
        return math.sqrt(q2) * np.diff(u)

    def autocovariance(self, lags, fs=1.0):
        (q2,) = self._require()
        lags = np.abs(np.asarray(lags))
        return np.select([lags == 0, lags == 1], [2 * q2, -q2], 0.0)


@dataclass(frozen=True, repr=False)
class RW(Process):
    """Random walk: cumulative sum of iid N(0, gamma2). WV ``gamma2 (tau^2 + 2) / (12 tau)``."""

    gamma2: float | None = None
    code: ClassVar[str] = "RW"
    param_names: ClassVar[tuple[str, ...]] = ("gamma2",)
    description: ClassVar[str] = "random walk"

    def basis(self, tau, fs, nl=None):
        return (tau**2 + 2.0) / (12.0 * tau)

    def linear_coef(self):
        return float(self.gamma2)

    def from_fit(self, h, nl, fs):
        return RW(float(h))

    def simulate(self, n, rng=None, fs=1.0):
        (g2,) = self._require()
        return np.cumsum(_rng(rng).normal(0.0, math.sqrt(g2), n))


@dataclass(frozen=True, repr=False)
class DR(Process):
    """Drift ``omega * t`` (omega per sample). WV ``omega^2 tau^2 / 16``."""

    omega: float | None = None
    code: ClassVar[str] = "DR"
    param_names: ClassVar[tuple[str, ...]] = ("omega",)
    description: ClassVar[str] = "drift (rate ramp)"

    def _check_value(self, name, v):
        pass  # a drift may have either sign; its WV depends on omega^2

    def bounds(self, fs=1.0):
        return {"omega": (-math.inf, math.inf)}

    def basis(self, tau, fs, nl=None):
        return tau**2 / 16.0

    def linear_coef(self):
        return float(self.omega) ** 2

    def from_fit(self, h, nl, fs):
        return DR(math.sqrt(max(h, 0.0)))

    def simulate(self, n, rng=None, fs=1.0):
        (om,) = self._require()
        # per sample, as the fit reports it (the R simulator's division by fs is a known defect)
        return om * np.arange(1, n + 1, dtype=float)


def _simulate_ar1(n: int, phi: float, sigma2: float, rng: np.random.Generator) -> np.ndarray:
    from scipy.signal import lfilter  # lazy: scipy.signal takes 0.3 s to import

    e = rng.normal(0.0, math.sqrt(sigma2), n)
    x0 = rng.normal(0.0, math.sqrt(sigma2 / (1.0 - phi * phi)))  # stationary start
    # x_1 = phi x0 + e_1, x_t = phi x_{t-1} + e_t
    return lfilter([1.0], [1.0, -phi], e, zi=[phi * x0])[0]


@dataclass(frozen=True, repr=False)
class AR1(Process):
    """First-order autoregression ``X_t = phi X_{t-1} + e_t``, ``Var e = sigma2``, ``|phi| < 1``."""

    phi: float | None = None
    sigma2: float | None = None
    code: ClassVar[str] = "AR1"
    param_names: ClassVar[tuple[str, ...]] = ("phi", "sigma2")
    nonlinear: ClassVar[str | None] = "phi"
    description: ClassVar[str] = "first-order autoregression"

    def _check_value(self, name, v):
        if name == "phi" and not -1.0 < v < 1.0:
            raise ValueError(f"AR1.phi must be in (-1, 1), got {v}")
        if name == "sigma2" and v < 0:
            raise ValueError(f"AR1.sigma2 must be >= 0, got {v}")

    def bounds(self, fs=1.0):
        return {"phi": (-1.0, 1.0), "sigma2": (0.0, math.inf)}

    # non-linear value: phi itself
    def basis(self, tau, fs, nl=None):
        return ar1_wv(tau, nl, 1.0)

    def linear_coef(self):
        return float(self.sigma2)

    def nl_value(self, fs):
        return None if self.phi is None else float(self.phi)

    def from_fit(self, h, nl, fs):
        return AR1(float(nl), float(h))

    def simulate(self, n, rng=None, fs=1.0):
        phi, s2 = self._require()
        return _simulate_ar1(n, phi, s2, _rng(rng))

    def autocovariance(self, lags, fs=1.0):
        phi, s2 = self._require()
        return s2 / (1 - phi * phi) * phi ** np.abs(np.asarray(lags))


@dataclass(frozen=True, repr=False)
class GM(Process):
    """Gauss-Markov (continuous time): ``beta`` [1/s], stationary variance ``sigma2_gm``.

    Sampled at ``fs`` it is an AR1 with ``phi = exp(-beta/fs)`` and innovation variance
    ``sigma2_gm (1 - exp(-2 beta/fs))``.
    """

    beta: float | None = None
    sigma2_gm: float | None = None
    code: ClassVar[str] = "GM"
    param_names: ClassVar[tuple[str, ...]] = ("beta", "sigma2_gm")
    nonlinear: ClassVar[str | None] = "beta"
    description: ClassVar[str] = "Gauss-Markov"

    def _check_value(self, name, v):
        if name == "beta" and not v > 0:
            raise ValueError(f"GM.beta must be > 0 (1/s), got {v}")
        if name == "sigma2_gm" and v < 0:
            raise ValueError(f"GM.sigma2_gm must be >= 0, got {v}")

    # non-linear value: phi = exp(-beta / fs); basis is per unit stationary variance
    def basis(self, tau, fs, nl=None):
        phi = np.asarray(nl, dtype=float)
        return ar1_wv(tau, phi, 1.0 - phi * phi)

    def linear_coef(self):
        return float(self.sigma2_gm)

    def nl_value(self, fs):
        return None if self.beta is None else math.exp(-float(self.beta) / fs)

    def from_fit(self, h, nl, fs):
        return GM(-math.log(float(nl)) * fs, float(h))

    def as_ar1(self, fs: float) -> AR1:
        """The AR1 (phi, sigma2) form of this GM at sampling frequency ``fs``."""
        beta, s2 = self._require()
        phi = math.exp(-beta / fs)
        return AR1(phi, s2 * (1 - phi * phi))

    def simulate(self, n, rng=None, fs=1.0):
        return self.as_ar1(fs).simulate(n, rng)

    def autocovariance(self, lags, fs=1.0):
        return self.as_ar1(fs).autocovariance(lags)


PROCESS_TYPES: dict[str, type[Process]] = {p.code: p for p in (GM, AR1, QN, WN, RW, DR)}
