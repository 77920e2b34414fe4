"""Inference for GMWM: covariance of the WV, efficient weights, intervals, goodness of fit.

* ``V = Cov(nu_hat)`` across levels, three ways:

  - :func:`wv_cov_data`: from the data, per level (diagonal), Percival & Walden's asymptotic
    estimator ``2 A_j / M_j`` with ``A_j = s_0^2 / 2 + sum_{tau>0} s_tau^2`` (``s`` the
    autocovariances of the level-j coefficients, i.e. the spectral density of the coefficients
    integrated squared), as in the R ``gmwm`` package;
  - :func:`wv_cov_model`: from a fitted model, Gaussian and asymptotic but full:
    ``Cov(nu_j, nu_k) = 2 / max(M_j, M_k) int |H_j(f)|^2 |H_k(f)|^2 S(f)^2 df`` with the Haar
    squared gains ``|H_j(f)|^2 = sin^4(pi f 2^(j-1)) / (4^(j-1) sin^2(pi f))`` and the model's
    spectral density ``S`` (checked against Monte Carlo in the tests);
  - :func:`wv_cov_bootstrap`: parametric bootstrap from a fitted model (simulate, recompute
    the WV, sample covariance).

* Efficient two-step GMWM (:func:`fit_efficient`): fit with ``weights="ci"``, estimate V from
  that fit, refit with ``Omega = V^-1`` (the GMWM paper, Corollary 1).
* Parameter intervals (:func:`param_intervals`): asymptotic sandwich
  ``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2) in the
  unconstrained space of each parameter (log variances, log beta, atanh phi) mapped back, so
  intervals stay inside the parameter space; or the parametric bootstrap (percentile).
* Goodness of fit (:func:`j_test`): ``T = (nu_hat - nu)' V^-1 (nu_hat - nu)`` against a
  chi-square with ``J - p`` degrees of freedom.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from .fit import FitError, GMWMResult, fit_gmwm
from .models import AR1, DR, FROM_UNCONSTRAINED, GM, QN, RW, TO_UNCONSTRAINED, WN, Model, Process
from .wv import WaveletVariance, as_series, cumsum_demeaned, wavelet_variance

__all__ = [
    "wv_cov_data",
    "wv_cov_model",
    "wv_cov_bootstrap",
    "fit_efficient",
    "param_intervals",
    "ParamInterval",
    "j_test",
    "JTest",
    "jacobian",
]


# ------------------------------------------------------------------------------------------
# covariance of the WV
# ------------------------------------------------------------------------------------------
def wv_cov_data(x: Any, wv: WaveletVariance) -> np.ndarray:
    """Diagonal asymptotic covariance of the classical WV from the data (Percival & Walden).

    ``Var(nu_j) = 2 A_j / M_j``, ``A_j = s_0^2/2 + sum_{tau >= 1} s_tau^2`` with ``s_tau`` the
    (biased) autocovariances of the boundary-free level-j coefficients, computed by FFT.

    Parameters
    ----------
    x : array_like, shape (N,)
        The series the WV was computed from.
    wv : WaveletVariance
        Its WV (gives the levels).
    """
    a = as_series(x)
    if a.size != wv.n:
        raise ValueError(f"the series has {a.size} samples but the WV was computed from {wv.n}")
    s = cumsum_demeaned(a)
    out = np.empty(wv.n_levels)
    for i, j in enumerate(wv.levels):
        m = 1 << (int(j) - 1)
        w = (s[2 * m :] - 2.0 * s[m:-m] + s[: s.size - 2 * m]) / (2.0 * m)
        nfft = 1 << int(math.ceil(math.log2(2 * w.size)))
        spec = np.fft.rfft(w, nfft)
        acf = np.fft.irfft(spec.real**2 + spec.imag**2, nfft)[: w.size] / w.size
        a_j = float(acf @ acf) - 0.5 * acf[0] ** 2
        out[i] = 2.0 * a_j / w.size
    return np.diag(out)


def _spectral_density(p: Process, f: np.ndarray, fs: float) -> np.ndarray:
    """Two-sided spectral density on f in cycles/sample (0 < f <= 1/2); RW generalised."""
    sin2 = np.sin(np.pi * f) ** 2
    if isinstance(p, WN):
        return np.full_like(f, float(p.sigma2))
    if isinstance(p, QN):
        return 4.0 * float(p.q2) * sin2
    if isinstance(p, RW):
        return float(p.gamma2) / (4.0 * sin2)
    if isinstance(p, DR):
        return np.zeros_like(f)  # deterministic: no first-order contribution to Cov(nu_hat)
    if isinstance(p, (AR1, GM)):
        ar = p if isinstance(p, AR1) else p.as_ar1(fs)
        phi, s2 = float(ar.phi), float(ar.sigma2)
        # 1 - 2 phi cos w + phi^2 = (1 - phi)^2 + 4 phi sin^2(w/2), stable near phi = 1
        return s2 / ((1.0 - phi) ** 2 + 4.0 * phi * sin2)
    raise TypeError(f"no spectral density for {p.code}")  # pragma: no cover


def _frequency_grid(levels: int, model: Model, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on (0, 1/2] and weights of the periodic trapezoid rule for an even integrand.

    With ``2F`` equispaced nodes on a period, the rule is exact for trigonometric polynomials
    of degree below ``2F``: the Haar gains of levels j, k have degree ``2^j + 2^k``, so
    ``F = 2^(J+1)`` integrates white-noise-like terms exactly; AR1/GM terms need ``F`` above a
    few correlation times (the rule then equals the lag-domain sum up to a negligible wrap).
    """
    need = 2 ** (levels + 1)
    for p in model.processes:
        if isinstance(p, (AR1, GM)):
            ar = p if isinstance(p, AR1) else p.as_ar1(fs)
            if 0 < float(ar.phi) < 1:
                # a few correlation times, but no more than 8x the longest scale: beyond the
                # series' span a near-unit-root AR1 acts as a random walk
                need = max(need, int(min(-16.0 / math.log(float(ar.phi)), 2.0 ** (levels + 4))))
    f_nodes = 1 << int(math.ceil(math.log2(need)))
    f = np.arange(1, f_nodes + 1) / (2.0 * f_nodes)
    w = np.full(f_nodes, 1.0 / f_nodes)  # 2 / (2F): the mirrored node counts twice
    w[-1] = 0.5 / f_nodes  # f = 1/2 is its own mirror image
    return f, w


def wv_cov_model(model: Model, wv: WaveletVariance) -> np.ndarray:
    """Asymptotic Gaussian covariance of the WV implied by a model (full J x J matrix).

    ``Cov(nu_j, nu_k) = (2 / max(M_j, M_k)) int_{-1/2}^{1/2} |H_j|^2 |H_k|^2 S^2 df``.

    Parameters
    ----------
    model : Model
        Every parameter set (e.g. ``result.model``).
    wv : WaveletVariance
        Gives the levels, ``M_j`` and fs.
    """
    if not model.is_set:
        raise FitError("wv_cov_model needs a model with every value set (a fitted model)")
    levels = wv.n_levels
    # processes fitted at zero contribute nothing (and their phi/beta is arbitrary)
    model = Model(tuple(p for p in model.processes if p.linear_coef() != 0))
    f, wts = _frequency_grid(levels, model, wv.fs)
    m_j = wv.n_coef.astype(float)
    out = np.zeros((levels, levels))
    inv_m2 = 1.0 / 4.0 ** np.arange(levels)  # 1 / m^2, m = 2^(j-1)
    chunk = 1 << 14
    g = np.empty((levels, chunk))
    for a in range(0, f.size, chunk):
        fc, wc = f[a : a + chunk], wts[a : a + chunk]
        k = fc.size
        s = np.zeros_like(fc)
        for p in model.processes:
            s += _spectral_density(p, fc, wv.fs)
        # |H_j|^2 S = sin^4(pi f m) / (m^2 sin^2(pi f)) S, by sin(2x) = 2 sin x cos x
        x = np.pi * fc
        sin_m, cos_m = np.sin(x), np.cos(x)
        base = s / (sin_m * sin_m)
        for j in range(levels):
            sin2 = sin_m * sin_m
            np.multiply(sin2 * sin2, base * inv_m2[j], out=g[j, :k])
            sin_m, cos_m = 2.0 * sin_m * cos_m, 1.0 - 2.0 * sin2
        gk = g[:, :k]
        out += (gk * wc) @ gk.T
    v = 2.0 * out / np.maximum.outer(m_j, m_j)
    return v


_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _boot_wv(args: tuple) -> np.ndarray:
    model, n, fs, levels, robust, eff, seed = args
    x = model.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    return wavelet_variance(x, fs=fs, levels=levels, robust=robust, eff=eff).variance


def _map(fn, items: list, workers: int) -> list:
    """``map`` over processes. Workers are spawned with one BLAS thread each: forked workers
    that inherit a multithreaded BLAS spin on each other's small matrix products (10x slower)."""
    main_file = getattr(sys.modules.get("__main__"), "__file__", None)
    if workers <= 1 or len(items) < 4 or not main_file or not os.path.exists(main_file):
        return [fn(it) for it in items]  # spawned workers cannot re-import an interactive main
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
            return list(ex.map(fn, items, chunksize=max(1, len(items) // (4 * workers))))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def wv_cov_bootstrap(
    model: Model, wv: WaveletVariance, *, B: int = 100, seed: int | None = 0, workers: int = 1
) -> np.ndarray:
    """Parametric-bootstrap covariance of the WV: simulate ``B`` series of the model's length.

    Parameters
    ----------
    model : Model
        Every value set. B, seed, workers: replicates, base seed (replicate b uses
        ``[seed, b]``), processes (results do not depend on it).
    """
    if B < 2:
        raise ValueError(f"B must be at least 2, got {B}")
    seeds = np.random.SeedSequence(seed).spawn(B)
    items = [(model, wv.n, wv.fs, wv.n_levels, wv.robust, wv.eff, s) for s in seeds]
    sims = np.array(_map(_boot_wv, items, workers))
    return np.cov(sims, rowvar=False)


# ------------------------------------------------------------------------------------------
# efficient GMWM
# ------------------------------------------------------------------------------------------
def _inverse(v: np.ndarray) -> np.ndarray:
    """Symmetric inverse of a covariance, with eigenvalues floored for stability."""
    vals, vecs = np.linalg.eigh((v + v.T) / 2)
    vals = np.maximum(vals, vals.max() * 1e-12)
    inv = (vecs / vals) @ vecs.T
    return (inv + inv.T) / 2


def fit_efficient(
    wv: WaveletVariance,
    model: Model | str,
    *,
    v: str | np.ndarray = "model",
    x: Any = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
) -> GMWMResult:
    """Two-step efficient GMWM: ``weights="ci"``, then ``Omega = V^-1`` with V estimated.

    Parameters
    ----------
    v : {"model", "bootstrap", "data"} or array
        How V is estimated: from the first-step fit (analytic Gaussian or parametric
        bootstrap), from the data (needs ``x``; diagonal), or given.
    """
    first = fit_gmwm(wv, model)
    vmat = _covariance(first, v, x=x, B=B, seed=seed, workers=workers)
    res = fit_gmwm(wv, first.model, weights=_inverse(vmat))
    object.__setattr__(res, "weights", "efficient")
    return res


def _covariance(
    res: GMWMResult,
    v: str | np.ndarray,
    *,
    x: Any = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
) -> np.ndarray:
    if isinstance(v, np.ndarray):
        if v.shape != (res.wv.n_levels,) * 2:
            raise FitError(f"V has shape {v.shape}, expected {(res.wv.n_levels,) * 2}")
        return v
    if v == "model":
        return wv_cov_model(res.model, res.wv)
    if v == "bootstrap":
        return wv_cov_bootstrap(res.model, res.wv, B=B, seed=seed, workers=workers)
    if v == "data":
        if x is None:
            raise FitError("v='data' needs the raw series x")
        return wv_cov_data(x, res.wv)
    raise FitError(f"unknown V estimator {v!r}: use 'model', 'bootstrap', 'data' or a matrix")


# ------------------------------------------------------------------------------------------
# intervals and goodness of fit
# ------------------------------------------------------------------------------------------
def _free(res: GMWMResult) -> list[tuple[int, str]]:
    """(process index, parameter name) of the free parameters: not on a boundary, and not
    belonging to an AR1/GM whose variance is 0 (its phi/beta is then not identified)."""
    out = []
    for i, (lab, p) in enumerate(zip(res.model.labels, res.model.processes, strict=True)):
        if p.linear_coef() <= 0:
            continue
        for name in p.param_names:
            if f"{lab}.{name}" not in res.at_bound:
                out.append((i, name))
    return out


def _set(model: Model, free: list[tuple[int, str]], u: np.ndarray) -> Model:
    """The model with the free parameters set from unconstrained coordinates ``u``."""
    procs = list(model.processes)
    for (i, name), ui in zip(free, u, strict=True):
        procs[i] = procs[i].with_values(**{name: FROM_UNCONSTRAINED[name](float(ui))})
    return Model(tuple(procs))


def _u0(model: Model, free: list[tuple[int, str]]) -> np.ndarray:
    """Unconstrained coordinates of the free parameters."""
    return np.array([TO_UNCONSTRAINED[n](float(getattr(model.processes[i], n))) for i, n in free])


def jacobian(res: GMWMResult, free: list[tuple[int, str]] | None = None) -> np.ndarray:
    """d nu / d u (J x p) at the estimate, u the unconstrained coordinates of free parameters."""
    free = _free(res) if free is None else free
    u0 = _u0(res.model, free)
    tau = res.wv.tau_samples
    jac = np.empty((tau.size, len(free)))
    for k in range(len(free)):
        h = 1e-5 * max(1.0, abs(u0[k]))
        up, dn = u0.copy(), u0.copy()
        up[k] += h
        dn[k] -= h
        jac[:, k] = (
            _set(res.model, free, up).wv(tau, res.fs) - _set(res.model, free, dn).wv(tau, res.fs)
        ) / (2 * h)
    return jac


@dataclass(frozen=True)
class ParamInterval:
    """A parameter estimate with its two-sided interval."""

    name: str
    value: float
    low: float
    high: float
    unit: str
    method: str
    level: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "low": self.low,
            "high": self.high,
            "unit": self.unit,
            "method": self.method,
            "level": self.level,
        }


def _boot_fit(args: tuple) -> dict[str, float] | None:
    model, spec, n, fs, levels, omega, seed = args
    x = model.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    try:
        wv = wavelet_variance(x, fs=fs, levels=levels)
        w = "ci" if omega is None else omega
        return fit_gmwm(wv, spec, weights=w).params
    except (FitError, ValueError):  # pragma: no cover - degenerate replicate
        return None


def param_intervals(
    res: GMWMResult,
    *,
    method: str = "asymptotic",
    level: float = 0.95,
    v: str | np.ndarray = "model",
    x: Any = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
) -> list[ParamInterval]:
    """Two-sided intervals for every parameter of a fit.

    Parameters
    ----------
    method : {"asymptotic", "bootstrap"}
        ``asymptotic``: the sandwich covariance in the unconstrained space (log of variances
        and beta, atanh of phi, omega as is) and Wald intervals mapped back, so they respect
        the parameter space; parameters estimated on a boundary get ``nan`` bounds.
        ``bootstrap``: parametric bootstrap percentile intervals (B refits).
    level : float
        Two-sided coverage (0.95 gives the 2.5 % and 97.5 % quantiles, unlike the R packages'
        normal quantile at 1 - alpha).
    v : {"model", "bootstrap", "data"} or array
        Covariance of the WV for the asymptotic method.
    """
    from scipy import stats

    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    recs = res.param_records
    if method == "asymptotic":
        free = _free(res)
        vmat = _covariance(res, v, x=x, B=B, seed=seed, workers=workers)
        a = jacobian(res, free)
        w = res.omega
        bread = np.linalg.pinv(a.T @ w @ a)
        cov = bread @ a.T @ w @ vmat @ w @ a @ bread
        se = np.sqrt(np.maximum(np.diagonal(cov), 0.0))
        z = stats.norm.ppf(0.5 + level / 2)
        u0 = _u0(res.model, free)
        bounds = {}
        for k, (i, name) in enumerate(free):
            lo = FROM_UNCONSTRAINED[name](u0[k] - z * se[k])
            hi = FROM_UNCONSTRAINED[name](u0[k] + z * se[k])
            bounds[(res.model.labels[i], name)] = (min(lo, hi), max(lo, hi))
        out = []
        for r in recs:
            lo, hi = bounds.get((r.label, r.name), (math.nan, math.nan))
            if r.name == "omega":  # the sign of a drift is not identified: report |omega|
                lo, hi = (max(lo, 0.0), hi) if r.value >= 0 else (lo, hi)
            out.append(
                ParamInterval(
                    r.full_name, r.value, float(lo), float(hi), r.unit, "asymptotic", level
                )
            )
        return out
    if method == "bootstrap":
        seeds = np.random.SeedSequence(seed).spawn(B)
        omega = None if res.weights == "ci" else res.omega
        items = [
            (res.model, res.model.cleared(), res.wv.n, res.fs, res.wv.n_levels, omega, s)
            for s in seeds
        ]
        fits = [f for f in _map(_boot_fit, items, workers) if f is not None]
        if len(fits) < max(10, B // 2):
            raise FitError("too many bootstrap refits failed; the model may be unidentifiable")
        out = []
        for r in recs:
            vals = np.array([f[r.full_name] for f in fits])
            lo, hi = np.quantile(vals, [0.5 - level / 2, 0.5 + level / 2])
            out.append(
                ParamInterval(
                    r.full_name, r.value, float(lo), float(hi), r.unit, "bootstrap", level
                )
            )
        return out
    raise ValueError(f"unknown interval method {method!r}: use 'asymptotic' or 'bootstrap'")


@dataclass(frozen=True)
class JTest:
    """Hansen's J-test of over-identifying restrictions for a GMWM fit."""

    statistic: float
    df: int
    p_value: float
    method: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "statistic": self.statistic,
            "df": self.df,
            "p_value": self.p_value,
            "method": self.method,
        }


def j_test(
    res: GMWMResult,
    *,
    v: str | np.ndarray = "model",
    x: Any = None,
    B: int = 200,
    seed: int | None = 0,
    workers: int = 1,
    method: str = "asymptotic",
) -> JTest:
    """Goodness of fit: ``T = (nu_hat - nu(theta_hat))' V^-1 (nu_hat - nu(theta_hat))``.

    Under a correct model and efficient weights, ``T ~ chi2(J - p)`` asymptotically
    (``method="asymptotic"``). ``method="bootstrap"`` compares T with its distribution over
    parametric-bootstrap replicates refitted the same way (no chi-square assumption).
    """
    from scipy import stats

    vmat = _covariance(res, v, x=x, B=B, seed=seed, workers=workers)
    vinv = _inverse(vmat)
    r = res.wv.variance - res.implied
    t = float(r @ vinv @ r)
    df = res.wv.n_levels - len(_free(res))
    if df < 1:
        raise FitError(f"the J-test needs more levels than free parameters (J - p = {df})")
    if method == "asymptotic":
        return JTest(t, df, float(stats.chi2.sf(t, df)), "asymptotic")
    if method == "bootstrap":
        seeds = np.random.SeedSequence(seed).spawn(B)
        stats_b = []
        for s in seeds:
            xb = res.model.simulate(res.wv.n, fs=res.fs, rng=np.random.default_rng(s))
            wvb = wavelet_variance(xb, fs=res.fs, levels=res.wv.n_levels)
            fb = fit_gmwm(wvb, res.model.cleared(), weights=res.omega)
            rb = wvb.variance - fb.implied
            stats_b.append(float(rb @ vinv @ rb))
        p = (1 + np.sum(np.array(stats_b) >= t)) / (1 + len(stats_b))
        return JTest(t, df, float(p), "bootstrap")
    raise ValueError(f"unknown J-test method {method!r}")
