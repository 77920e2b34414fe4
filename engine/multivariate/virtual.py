"""The optimal virtual sensor: the weighted mean of k redundant sensors with the smallest WV.

k channels measure the same quantity (one axis of k IMUs); the virtual sensor is
``v_t = sum_i w_i x_{i,t}`` with ``sum_i w_i = 1``. Its WV at level j is ``w' N(j) w``, with
``N(j)`` the k x k matrix of WVs and cross-covariances (the fitted MGMWM's or the data's), so
the optimal weights are ``N^-1 1 / (1' N^-1 1)`` for one scale or a band of levels; the
virtual sensor's own latent model (:func:`virtual_model`) is exact for the WV, and it carries
a sampling interval and a delta-method confidence interval. The formulas, the assumptions and
the two intervals: docs/methods.md, "The optimal virtual sensor"; the user's view, with the
shrinkage of estimated weights and the real-data case: docs/multichannel.md.

Use of the MGMWM named by the multivariate paper (after Zhang et al., PLANS 2018, and
Vaccaro & Zaki, Sensors 2017).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._optim import chi2_isf
from ..fit import FitError, GMWMResult, weight_matrix
from ..fit._varpro import sub_sample_warnings
from ..models import Model, Process
from ..units import squared
from ..wv import WaveletVariance, WVMatrix
from .delta import (
    delta_variance,
    implied_jacobian,
    kept_share,
    parameter_covariance,
    selection_bias,
    weight_noise,
)
from .spec import MultiModel

__all__ = [
    "VirtualSensor",
    "optimal_weights",
    "virtual_sensor",
    "virtual_model",
    "virtual_signal",
    "implied_jacobian",
    "weight_noise",
]


def optimal_weights(n: Any) -> np.ndarray:
    """Weights summing to 1 that minimise ``w' N w``: ``N^-1 1 / (1' N^-1 1)``.

    Parameters
    ----------
    n : array_like, shape (k, k)
        Symmetric positive semi-definite matrix (a WV/WCCV matrix at one level or a band sum).

    Returns
    -------
    ndarray, shape (k,)
        The weights, from the KKT system ``[[N, 1], [1', 0]]`` (equal to the closed form for a
        regular ``N``; a singular ``N``, where a combination has zero WV, gives that
        combination).

    Raises
    ------
    ValueError
        Not a square, finite, symmetric matrix with a positive diagonal.

    Examples
    --------
    >>> optimal_weights([[1.0, 0.0], [0.0, 3.0]]).round(3).tolist()
    [0.75, 0.25]
    """
    a = np.asarray(n, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] < 1:
        raise ValueError(f"N must be a square (k, k) matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("N has non-finite entries")
    scale = float(np.max(np.abs(a))) or 1.0
    if not np.allclose(a, a.T, rtol=0, atol=1e-10 * scale):
        raise ValueError("N must be symmetric (a WV/WCCV matrix)")
    if np.any(np.diagonal(a) <= 0):
        bad = int(np.argmin(np.diagonal(a)))
        raise ValueError(f"N has a non-positive variance at channel {bad}: {a[bad, bad]:g}")
    a = 0.5 * (a + a.T) / scale
    k = a.shape[0]
    # the KKT system of min w'Nw s.t. 1'w = 1: [[N, 1], [1', 0]] [w; -lambda/2] = [0; 1];
    # it is regular whenever N is positive definite on {d : 1'd = 0} (also for a singular N)
    kkt = np.zeros((k + 1, k + 1))
    kkt[:k, :k] = a
    kkt[:k, k] = kkt[k, :k] = 1.0
    rhs = np.zeros(k + 1)
    rhs[k] = 1.0
    sol = np.linalg.lstsq(kkt, rhs, rcond=1e-13)[0]
    w = sol[:k]
    if not (np.all(np.isfinite(w)) and math.isclose(float(w.sum()), 1.0, abs_tol=1e-9)):
        raise ValueError("no weights minimise w' N w: N is not positive semi-definite")
    return w / w.sum()


def _quad(n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``w' N(j) w`` for every level of a (J, k, k) array."""
    return np.einsum("p,jpq,q->j", w, n, w)


def virtual_model(model: MultiModel, weights: Any, fs: float) -> Model:
    """The single-channel latent model of ``w' x`` implied by a multivariate model.

    Each process of ``model`` (every value set) gives ``w_g' C w_g`` (``C`` its g x g
    covariance, or the 1 x 1 variance of a channel's own process, ``w_g`` the weights of its
    channels) in its linear parametrisation; terms of one code and, for AR1/GM, one phi are
    summed; AR1/GM terms with different phis stay separate, the most persistent first (the
    module docstring gives the assumptions, e.g. for drifts).

    Parameters
    ----------
    model : MultiModel
        A fitted (every value set) multivariate model.
    weights : array_like, shape (k,)
        One weight per channel, in ``model.channels`` order.
    fs : float
        Sampling frequency (Hz).

    Returns
    -------
    Model
        Its implied WV equals ``w' model.implied(tau, fs) w`` at every scale.
    """
    w = _check_weights(weights, model.k)
    parts: dict[tuple[str, float | None], list[Any]] = {}
    for t in model.terms():
        c, phi = model.term_values(t, fs)
        wt = w[list(t.chans)]
        h = float(wt @ np.asarray(c, float) @ wt)
        key = (t.code, None if phi is None else float(phi))
        if key not in parts:
            parts[key] = [t.proto, 0.0, phi]
        parts[key][1] += h
    procs: list[Process] = []
    for proto, h, phi in sorted(parts.values(), key=lambda v: -(v[2] or 0.0)):
        if h > 0:
            procs.append(proto.cleared().from_fit(max(h, 0.0), phi, fs))
    if not procs:
        raise ValueError("the weights give a virtual sensor with no noise at all (w' N w = 0)")
    return Model(tuple(procs))


def _check_weights(weights: Any, k: int) -> np.ndarray:
    w = np.asarray(weights, dtype=float).ravel()
    if w.size != k:
        raise ValueError(f"give {k} weights (one per channel), got {w.size}")
    if not np.all(np.isfinite(w)):
        raise ValueError("the weights must be finite")
    if not math.isclose(float(w.sum()), 1.0, rel_tol=0, abs_tol=1e-9):
        raise ValueError(f"the weights must sum to 1 (the signal is kept), got {w.sum():.6g}")
    return w


def virtual_signal(data: Any, weights: Any, channels: Sequence[str] | None = None) -> np.ndarray:
    """The combined signal ``v_t = sum_i w_i x_{i,t}``.

    Parameters
    ----------
    data : ndarray (N, k), sequence of k series, ImuLog or mapping of name to series
        The channels, in the weights' order (``channels`` selects them from a log/mapping).
        Series of different lengths (separate recordings) are cut to the shortest.
    weights : array_like, shape (k,)
        Summing to 1 (e.g. ``VirtualSensor.weights``).
    channels : sequence of str, optional
        Channel names, for a log or a mapping.

    Returns
    -------
    ndarray, shape (N,)
    """
    if channels is not None:
        try:
            cols = [np.asarray(data[c], float) for c in channels]
        except KeyError as e:
            raise KeyError(f"unknown channel {e.args[0]!r}") from None
    elif isinstance(data, np.ndarray) and data.ndim == 2:
        cols = list(np.asarray(data, float).T)
    elif isinstance(data, Mapping):
        cols = [np.asarray(v, float) for v in data.values()]
    elif isinstance(getattr(data, "channels", None), Mapping):  # an ImuLog: every channel
        cols = [np.asarray(v, float) for v in data.channels.values()]
    else:
        cols = [np.asarray(v, float) for v in data]
    if any(c.ndim != 1 for c in cols):
        raise ValueError("each channel must be a 1-D series")
    w = _check_weights(weights, len(cols))
    n = min(c.size for c in cols)
    if n < 2:
        raise ValueError(f"the series are too short ({n} samples)")
    return np.sum([wi * c[:n] for wi, c in zip(w, cols, strict=True)], axis=0)


@dataclass(frozen=True, eq=False)
class VirtualSensor:
    """The optimal virtual sensor of a fitted multivariate model (:func:`virtual_sensor`).

    Attributes
    ----------
    channels : tuple of str, length k
        The sensors, in the weights' order.
    weights : ndarray (k,)
        The weights of the virtual sensor (sum 1): the fitted model's optimum shrunk towards
        the plain average by ``shrinkage`` (the average itself when it fell back).
    fitted_weights : ndarray (k,)
        The fitted model's optimum ``M^-1 1 / (1' M^-1 1)`` (in sample).
    empirical_weights : ndarray (k,)
        The same optimum computed from the empirical WV/WCCV matrix (no model).
    levels, tau_samples : ndarray of int (J,)
        Levels and scales (samples).
    fs : float
        Sampling frequency (Hz).
    unit : str
        The sensors' common unit (WVs are in its square).
    target : str
        ``"level j (tau s)"`` or ``"band j1..j2 (tau1 to tau2 s)"``, the criterion's levels.
    target_levels : ndarray of int
        Indices (0-based) of the criterion's levels.
    relative : bool
        Band levels weighted by ``1 / nu_avg(j)`` (else summed plainly).
    implied : ndarray (J,)
        ``w' N(j) w``: the model-implied WV of the virtual sensor (in sample).
    ci_low, ci_high : ndarray (J,)
        ``1 - alpha`` interval of the empirical WV of the combined series under the model
        (sampling).
    conf_low, conf_high : ndarray (J,)
        ``1 - alpha`` confidence interval of the implied WV (delta method from the fit's
        sandwich covariance; the weights taken as given).
    sensors_implied : ndarray (J, k)
        The model-implied WV of each sensor.
    average_implied : ndarray (J,)
        The model-implied WV of the plain average (weights ``1/k``).
    empirical : ndarray (J,)
        The empirical WV of the combined series (``w' N_hat(j) w``, exact).
    sensors_empirical : ndarray (J, k), average_empirical : ndarray (J,)
        The empirical WVs of each sensor and of the plain average.
    objective, average_objective : float
        The criterion (band sum of ``nu(j) / a_j``) of the virtual sensor and of the average,
        in the fitted model (in sample).
    sensor_objectives : ndarray (k,)
        The criterion of each sensor alone; ``best_sensor`` the smallest's name.
    fitted_objective : float
        The in-sample criterion of ``fitted_weights`` (optimistic by ``2 excess``).
    expected_objective : float
        The expected criterion of ``weights`` out of sample (on a new realisation, or under
        the true model): ``A - 2 lambda (D_in - S) + lambda^2 D_in`` (:func:`virtual_sensor`).
    excess : float
        ``S``: the expected excess criterion of estimated weights over the optimum
        (:func:`weight_noise`).
    noise_threshold : float
        The fallback test's critical in-sample improvement (:func:`weight_noise`'s ``q``).
    shrinkage : float
        ``lambda`` in [0, 1]: the share of the fitted optimum's departure from the average
        that is kept (0: the plain average).
    fallback : str
        Why the plain average is used (``""`` when it is not).
    model : Model
        The virtual sensor's single-channel model (:func:`virtual_model`).
    n : int
        Samples of the series.
    alpha : float
        Interval level.
    warnings : tuple of str
        The fit's warnings (e.g. an AR1/GM faster than one sample, by channel) and the
        virtual model's (``virtual.GM_1 ...``).
    """

    channels: tuple[str, ...]
    weights: np.ndarray
    fitted_weights: np.ndarray
    empirical_weights: np.ndarray
    levels: np.ndarray
    tau_samples: np.ndarray
    fs: float
    unit: str
    target: str
    target_levels: np.ndarray
    relative: bool
    implied: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    conf_low: np.ndarray
    conf_high: np.ndarray
    sensors_implied: np.ndarray
    average_implied: np.ndarray
    empirical: np.ndarray
    sensors_empirical: np.ndarray
    average_empirical: np.ndarray
    objective: float
    average_objective: float
    sensor_objectives: np.ndarray
    fitted_objective: float
    expected_objective: float
    excess: float
    noise_threshold: float
    shrinkage: float
    fallback: str
    model: Model
    n: int
    alpha: float = 0.05
    warnings: tuple[str, ...] = ()

    @property
    def tau_s(self) -> np.ndarray:
        """Scales in seconds."""
        return self.tau_samples / self.fs

    @property
    def best_sensor(self) -> str:
        """The sensor with the smallest criterion on its own."""
        return self.channels[int(np.argmin(self.sensor_objectives))]

    @property
    def fell_back(self) -> bool:
        """True when the virtual sensor is the plain average (``fallback`` says why)."""
        return bool(self.fallback)

    @property
    def gain_vs_average(self) -> float:
        """The out-of-sample gain: ``expected_objective / average_objective`` (1 when it fell
        back to the average; the expected criterion of ``weights`` on new data relative to
        the plain average's)."""
        return self.expected_objective / self.average_objective

    @property
    def fitted_gain(self) -> float:
        """The in-sample gain of the fitted optimum, ``fitted_objective / average_objective``
        (optimistic: :attr:`gain_vs_average` is the one that holds out of sample)."""
        return self.fitted_objective / self.average_objective

    @property
    def gain_vs_best(self) -> float:
        """``expected_objective / min(sensor_objectives)`` (out of sample)."""
        return self.expected_objective / float(np.min(self.sensor_objectives))

    def wv(self) -> WaveletVariance:
        """The empirical WV of the combined series, with its eta3 intervals."""
        return WaveletVariance.from_arrays(
            np.maximum(self.empirical, 0.0), n=self.n, fs=self.fs, alpha=self.alpha, unit=self.unit
        )

    def as_fit(self) -> GMWMResult:
        """The virtual sensor as a single-channel fit, for :func:`engine.formats.export` and
        every single-channel view: ``model`` is :attr:`model` (not refitted), ``wv`` the
        empirical WV of the combined series, ``objective`` its ``"ci"``-weighted distance
        to the implied WV."""
        wv = self.wv()
        omega, wname = weight_matrix(wv, "ci")
        comps = self.model.components(wv.tau_samples, wv.fs)
        implied = np.sum(np.array(list(comps.values())), axis=0)
        r = wv.variance - implied
        return GMWMResult(
            model=self.model,
            weights=wname,
            omega=omega,
            objective=float(r @ omega @ r),
            method="virtual sensor: w' Sigma w of the MGMWM fit",
            message=f"weights {', '.join(f'{w:.4g}' for w in self.weights)} on "
            f"{', '.join(self.channels)} ({self.target})",
            wv=wv,
            implied=implied,
            components=comps,
            warnings=sub_sample_warnings(self.model, wv.fs, wv.unit),
        )

    def table(self) -> str:
        """Readable summary: weights and the Allan deviation of each sensor, the average and
        the virtual sensor at every level."""
        u = self.unit
        lines = [
            f"Optimal virtual sensor of {', '.join(self.channels)}: minimum WV over "
            f"{self.target}{' (relative to the average)' if self.relative else ''}",
            f"  {'channel':<18} {'weight':>10} {'weight (model)':>15} {'weight (data)':>14} "
            f"{'criterion':>11}",
        ]
        for c, w, wf, we, o in zip(
            self.channels,
            self.weights,
            self.fitted_weights,
            self.empirical_weights,
            self.sensor_objectives,
            strict=True,
        ):
            lines.append(f"  {c:<18} {w:>10.4f} {wf:>15.4f} {we:>14.4f} {o:>11.4g}")
        if self.fell_back:
            how = f"  weights: the plain average: {self.fallback}"
        else:
            how = (
                f"  weights: the model's optimum shrunk towards the average (lambda = "
                f"{self.shrinkage:.3f}, the share of its departure from 1/{len(self.channels)} "
                "that is kept)"
            )
        lines += [
            how,
            f"  gain out of sample: {self.gain_vs_average:.3f} x the average's criterion, "
            f"{self.gain_vs_best:.3f} x the best sensor {self.best_sensor}'s (the model's "
            f"optimum in sample: {self.fitted_gain:.3f}, optimistic by 2 x the estimated "
            f"weights' expected excess {self.excess / self.average_objective:.3g})",
            f"  model: {self.model.spec(values=True)}",
            "",
            f"  Allan deviation sqrt(2 WV) [{u}]: empirical (the best sensor, the average, the "
            f"virtual sensor), implied, its {100 * (1 - self.alpha):g}% sampling range of the "
            "empirical and its confidence interval (delta method)",
            f"  {'tau [s]':>10} {'best':>10} {'average':>10} {'virtual':>10} {'implied':>10} "
            f"{'samp. low':>10} {'samp. high':>10} {'conf. low':>10} {'conf. high':>10}",
        ]
        b = int(np.argmin(self.sensor_objectives))
        for i in range(self.levels.size):
            ad = [
                math.sqrt(2 * max(v, 0.0))
                for v in (
                    self.sensors_empirical[i, b],
                    self.average_empirical[i],
                    self.empirical[i],
                    self.implied[i],
                    self.ci_low[i],
                    self.ci_high[i],
                    self.conf_low[i],
                    self.conf_high[i],
                )
            ]
            lines.append(f"  {self.tau_s[i]:>10.4g} " + " ".join(f"{a:>10.4e}" for a in ad))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (``gmwm virtual --json``)."""
        return {
            "kind": "virtual_sensor",
            "channels": list(self.channels),
            "weights": self.weights.tolist(),
            "fitted_weights": self.fitted_weights.tolist(),
            "shrinkage": self.shrinkage,
            "fell_back": self.fell_back,
            "fallback": self.fallback,
            "empirical_weights": self.empirical_weights.tolist(),
            "target": self.target,
            "target_levels": (self.target_levels + 1).tolist(),
            "relative": self.relative,
            "fs": self.fs,
            "n": self.n,
            "unit": self.unit,
            "wv_unit": squared(self.unit) if self.unit else "",
            "alpha": self.alpha,
            "levels": self.levels.tolist(),
            "tau_s": self.tau_s.tolist(),
            "implied": self.implied.tolist(),
            "ci_low": self.ci_low.tolist(),
            "ci_high": self.ci_high.tolist(),
            "conf_low": [v if math.isfinite(v) else None for v in self.conf_low.tolist()],
            "conf_high": [v if math.isfinite(v) else None for v in self.conf_high.tolist()],
            "empirical": self.empirical.tolist(),
            "sensors_implied": self.sensors_implied.tolist(),
            "sensors_empirical": self.sensors_empirical.tolist(),
            "average_implied": self.average_implied.tolist(),
            "average_empirical": self.average_empirical.tolist(),
            "objective": self.objective,
            "average_objective": self.average_objective,
            "sensor_objectives": self.sensor_objectives.tolist(),
            "best_sensor": self.best_sensor,
            "fitted_objective": self.fitted_objective,
            "expected_objective": self.expected_objective,
            "excess": self.excess,
            "noise_threshold": self.noise_threshold,
            "gain_vs_average": self.gain_vs_average,
            "fitted_gain": self.fitted_gain,
            "gain_vs_best": self.gain_vs_best,
            "model": self.model.spec(values=True),
            "warnings": list(self.warnings),
        }


def target_levels(
    tau_s: np.ndarray, scale: float | None = None, band: tuple[float, float] | None = None
) -> tuple[np.ndarray, str]:
    """Indices of the levels a criterion uses and a readable name.

    ``scale`` (s): the level whose scale is nearest in log (within a factor 2^0.5 of a
    level); ``band`` (s, s): the levels with ``s1 <= tau <= s2``; neither: every level.
    """
    tau_s = np.asarray(tau_s, float)
    if scale is not None and band is not None:
        raise ValueError("give a scale or a band, not both")
    if scale is not None:
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"the scale must be > 0 s, got {scale}")
        d = np.abs(np.log2(tau_s / scale))
        i = int(np.argmin(d))
        if d[i] > 0.5 + 1e-9:
            raise ValueError(
                f"the scale {scale:g} s is outside the WV's scales "
                f"({tau_s[0]:g} to {tau_s[-1]:g} s)"
            )
        return np.array([i]), f"level {i + 1} ({tau_s[i]:g} s)"
    if band is None:
        sel = np.arange(tau_s.size)
    else:
        lo, hi = (float(v) for v in band)
        if not (lo > 0 and hi >= lo):
            raise ValueError(f"the band must be 0 < s1 <= s2 seconds, got {lo:g}:{hi:g}")
        sel = np.flatnonzero((tau_s >= lo * (1 - 1e-9)) & (tau_s <= hi * (1 + 1e-9)))
        if sel.size == 0:
            raise ValueError(
                f"no WV scale in the band {lo:g} to {hi:g} s (scales {tau_s[0]:g} to "
                f"{tau_s[-1]:g} s, powers of 2 / fs)"
            )
    return sel, (
        f"band levels {sel[0] + 1}..{sel[-1] + 1} ({tau_s[sel[0]]:g} to {tau_s[sel[-1]]:g} s)"
    )


def band_matrix(
    n: np.ndarray, sel: np.ndarray, relative: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """``(sum_j N(j) / a_j, a)`` over the selected levels of a (J, k, k) array (``a_j = 1``,
    or the plain average's WV ``1' N(j) 1 / k^2`` when ``relative``)."""
    k = n.shape[1]
    a = np.ones(n.shape[0])
    if relative:
        a = np.einsum("jpq->j", n) / k**2
        a = np.where(a > 0, a, 1.0)
    return np.sum(n[sel] / a[sel, None, None], axis=0), a


def _interval(
    nu: np.ndarray, var: np.ndarray, alpha: float, confidence: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Chi-square ``1 - alpha`` range of an estimate with mean nu and variance var
    (``eta = 2 nu^2 / var`` degrees of freedom): where the estimate falls, ``nu chi2 / eta``,
    or with ``confidence`` the interval of the true value, ``eta nu / chi2`` (eta3 form)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where(var > 0, 2 * nu**2 / np.where(var > 0, var, 1.0), 1e12)
    eta = np.clip(eta, 1e-3, 1e12)
    q_hi, q_lo = chi2_isf(eta, alpha / 2), chi2_isf(eta, 1 - alpha / 2)
    if confidence:
        return eta * nu / q_hi, eta * nu / q_lo
    return nu * q_lo / eta, nu * q_hi / eta


def virtual_sensor(
    result: Any,
    *,
    scale: float | None = None,
    band: tuple[float, float] | None = None,
    relative: bool = True,
    alpha: float = 0.05,
    confidence: bool = True,
    shrink: bool = True,
    fallback_level: float = 0.05,
) -> VirtualSensor:
    """The optimal virtual sensor of a fitted multivariate model.

    The weights that minimise the fitted model's criterion (``fitted_weights``) are noisy
    estimates, and their in-sample gain is optimistic: the expected excess criterion ``S`` of
    estimated weights (:func:`weight_noise`, delta method from the fit's sandwich
    covariance) is counted twice (the in-sample criterion is ``S`` below the optimum, the
    out-of-sample one ``S`` above). With ``u = w_fit - 1/k`` and the in-sample improvement
    over the plain average ``D_in = u' M u``, the improvement of the true optimum is
    estimated by ``D = D_in - S`` and the weights are shrunk towards the average,
    ``w = 1/k + lambda u`` with ``lambda = 1 - S / D_in`` (positive-part James-Stein; it
    minimises the expected out-of-sample criterion ``A - 2 lambda D + lambda^2 (D + S)``,
    ``A`` the average's). When ``D_in`` is within its own noise (below the ``1 -
    fallback_level`` point of ``D_in`` for an optimal average, or below ``S``) the plain
    average is used (``fallback`` says why). ``gain_vs_average`` is the expected
    out-of-sample criterion of the weights used, ``A - lambda D`` plus the winner's curse of
    weights that passed the test (:func:`selection_bias`, by simulation of the weights'
    error around the shrunk optimum), over ``A``; when that is not below 1 the average is
    used, and the gain is 1.

    Parameters
    ----------
    result : MGMWMResult
        A fit of k channels measuring the same quantity (e.g. one axis of k IMUs, with
        shared WN/RW/AR1/GM).
    scale : float, optional
        Minimise the WV at this scale (s; the nearest dyadic level).
    band : (float, float), optional
        Minimise over the levels with ``s1 <= tau <= s2`` (s). Neither: every level.
    relative : bool
        Band levels weighted by ``1 / nu_avg(j)`` (default) or summed plainly.
    alpha : float
        Interval level ``1 - alpha``.
    confidence : bool
        Give the delta-method confidence interval of the implied WV (False leaves
        ``conf_low/conf_high`` nan; the fit's covariance is computed either way, for the
        out-of-sample gain: about as long as the fit for 3 channels).
    shrink : bool
        Shrink towards (or fall back to) the average (default); False uses the fitted
        optimum as it is (``gain_vs_average`` is then its out-of-sample gain, the in-sample
        one plus ``2 S``).
    fallback_level : float
        The fallback test's level: the probability that the weights leave the average when
        the average is the optimum.

    Returns
    -------
    VirtualSensor

    Raises
    ------
    ValueError
        A scale or band outside the WV's scales, a bad alpha or fallback_level.
    FitError
        ``result`` is not a multivariate fit.

    Examples
    --------
    Three independent sensors with white-noise variances 1, 2 and 4: the optimal weights are
    proportional to the inverse variances, (4, 2, 1) / 7 = (0.571, 0.286, 0.143), and the
    combined variance is ``(1/1 + 1/2 + 1/4)^-1 = 0.571`` against ``7 / 9 = 0.778`` for the
    plain average (a ratio of 0.735):

    >>> import numpy as np
    >>> import engine as eg
    >>> truth = eg.MultiModel(["a", "b", "c"], {"a": "WN(1)", "b": "WN(2)", "c": "WN(4)"})
    >>> x = truth.simulate(2**13, rng=np.random.default_rng(2))
    >>> vs = eg.virtual_sensor(eg.fit_mgmwm(x, eg.MultiModel(["a", "b", "c"], "WN")))
    >>> print(*(f"{w:.3f}" for w in vs.weights), f"gain {vs.gain_vs_average:.3f}")
    0.573 0.284 0.143 gain 0.733
    """
    if not hasattr(result, "wvm") or not isinstance(getattr(result, "model", None), MultiModel):
        raise FitError(
            f"virtual_sensor needs a multivariate fit (fit_mgmwm), got {type(result).__name__}"
        )
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    if not 0 < fallback_level < 1:
        raise ValueError(f"fallback_level must be in (0, 1), got {fallback_level}")
    wvm: WVMatrix = result.wvm
    model: MultiModel = result.model
    k = wvm.k
    sel, name = target_levels(wvm.tau_s, scale, band)
    imp = np.asarray(result.implied, float)
    emp = np.asarray(wvm.values, float)
    n_model, a = band_matrix(imp, sel, relative)
    w_fit = optimal_weights(n_model)
    n_emp, _ = band_matrix(emp, sel, relative)
    w_emp = optimal_weights(n_emp)
    avg = np.full(k, 1.0 / k)
    deriv, cov = parameter_covariance(result)
    excess, threshold, cov_d = weight_noise(deriv, cov, n_model, sel, a, w_fit, fallback_level)
    u = w_fit - avg
    gap = max(float(u @ n_model @ u), 0.0)  # in-sample improvement over the average
    avg_obj = float(avg @ n_model @ avg)
    fallback = ""
    if not shrink:
        lam = 1.0
    elif gap <= max(threshold, excess):
        lam = 0.0
        fallback = (
            f"the estimated improvement over the plain average ({100 * gap / avg_obj:.3g} % of "
            f"its criterion in sample) is within its own noise (below "
            f"{100 * max(threshold, excess) / avg_obj:.3g} %, what estimated weights show "
            f"{100 * (1 - fallback_level):g} % of the time when the average is the optimum)"
        )
    else:
        lam = float(kept_share(gap, excess, threshold))
    w = avg + lam * u
    w = w / w.sum()
    expected = avg_obj - 2 * lam * (gap - excess) + lam * lam * gap
    if shrink and lam > 0:  # the weights passed the test: correct for the selection
        expected += selection_bias(lam * u, n_model, cov_d, excess, threshold)
        if expected >= avg_obj:
            fallback = (
                f"the shrunk weights' expected criterion out of sample ({expected / avg_obj:.4g}"
                " x the average's, the selection of passing weights counted) is not below the "
                "plain average's"
            )
            lam, w, expected = 0.0, avg.copy(), avg_obj
    nu = _quad(imp, w)
    vmodel = virtual_model(model, w, wvm.fs)
    # sampling variance of w' N_hat(j) w under the model: c' V_jj c with V the moments'
    # covariance (moment_covariance), which is the univariate Var(nu_hat_j) of the virtual
    # model (v is one Gaussian series with spectral density w' S(f) w; Isserlis on both
    # sides) and costs one J x J integral instead of (P J)^2
    from ..fit.asymptotic import wv_cov_model

    shape = WaveletVariance.from_arrays(np.maximum(nu, 0.0), n=wvm.n, fs=wvm.fs, alpha=alpha)
    var = np.diagonal(wv_cov_model(vmodel, shape)).copy()
    lo, hi = _interval(nu, var, alpha)
    if confidence:
        conf_lo, conf_hi = _interval(nu, delta_variance(deriv, cov, w), alpha, confidence=True)
    else:
        conf_lo = conf_hi = np.full(nu.shape, np.nan)
    diag = np.einsum("jpp->jp", imp)
    units = set(wvm.units) if wvm.units else {""}
    unit = units.pop() if len(units) == 1 else ""
    warnings = [
        *getattr(result, "warnings", ()),
        *sub_sample_warnings(vmodel, wvm.fs, unit, "virtual."),
    ]
    return VirtualSensor(
        channels=wvm.channels,
        weights=w,
        fitted_weights=w_fit,
        empirical_weights=w_emp,
        levels=wvm.levels,
        tau_samples=wvm.tau_samples,
        fs=wvm.fs,
        unit=unit,
        target=name,
        target_levels=sel,
        relative=relative,
        implied=nu,
        ci_low=lo,
        ci_high=hi,
        conf_low=conf_lo,
        conf_high=conf_hi,
        sensors_implied=diag,
        average_implied=_quad(imp, avg),
        empirical=np.maximum(_quad(emp, w), 0.0),
        sensors_empirical=np.einsum("jpp->jp", emp),
        average_empirical=_quad(emp, avg),
        objective=float(np.sum(nu[sel] / a[sel])),
        average_objective=avg_obj,
        sensor_objectives=np.sum(diag[sel] / a[sel, None], axis=0),
        fitted_objective=float(w_fit @ n_model @ w_fit),
        expected_objective=float(expected),
        excess=excess,
        noise_threshold=threshold,
        shrinkage=lam,
        fallback=fallback,
        model=vmodel,
        n=int(wvm.n),
        alpha=alpha,
        warnings=tuple(warnings),
    )
