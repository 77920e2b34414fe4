"""Replicates: one univariate model fitted to several recordings of the same sensor.

The objective is summed over the recordings (each with its own weights); the same variable
projection as :func:`engine.fit.fit_gmwm` with the stacked moments.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..models import Model, ModelError, Process, parse_model
from ..wv import WaveletVariance, wavelet_variance
from ._varpro import (
    NNLSProblem,
    at_bound,
    fitted_model,
    search,
    search_message,
    start_coordinates,
    sub_sample_warnings,
)
from .gmwm import GMWMResult, fit_gmwm, weight_matrix
from .result import FitError, UnivariateFit

__all__ = ["ReplicateResult", "fit_replicates"]


@dataclass(frozen=True, eq=False, kw_only=True)
class ReplicateResult(UnivariateFit):
    """Result of :func:`fit_replicates`: one model fitted to several recordings.

    The fields of :class:`engine.fit.result.FitResult` (``omega`` is block diagonal over the
    recordings' stacked levels; ``objective`` the sum over recordings), plus:

    Attributes
    ----------
    wvs : list of WaveletVariance
        The replicates' WVs.
    objectives : list of float
        Each replicate's term ``(nu_hat_r - nu)' Omega_r (nu_hat_r - nu)``.
    implied : list of ndarray (J_r,)
        Implied WV at each replicate's scales.
    components : dict of str to ndarray
        Implied WV of each process at the scales of the longest replicate.
    """

    wvs: list[WaveletVariance]
    objectives: list[float]
    implied: list[np.ndarray]
    components: dict[str, np.ndarray]

    @property
    def fs(self) -> float:
        return self.wvs[0].fs

    @property
    def unit(self) -> str:
        return self.wvs[0].unit

    def _summary_head(self) -> list[str]:
        return [
            f"GMWM replicate fit of {self.model.spec()} to {len(self.wvs)} recordings",
            f"  data: N = {', '.join(str(w.n) for w in self.wvs)} samples, fs = {self.fs:g} Hz",
            f"  weights: {self.weights}; objective = {self.objective:.6g} (sum); "
            f"{self.method}, {self.n_evaluations} evaluations, "
            f"{1e3 * self.elapsed_s:.1f} ms",
        ]

    def _summary_tail(self) -> list[str]:
        return ["", "  objective by replicate: " + ", ".join(f"{v:.4g}" for v in self.objectives)]

    def _dict_extra(self) -> dict[str, Any]:
        return {
            "kind": "replicates",
            "n": [int(w.n) for w in self.wvs],
            "objectives": list(self.objectives),
            "implied": [v.tolist() for v in self.implied],
            "components": {k: v.tolist() for k, v in self.components.items()},
            "wv": [w.to_dict() for w in self.wvs],
        }


def fit_replicates(
    wvs: Sequence[WaveletVariance | Any],
    model: Model | Process | str,
    *,
    weights: str | Sequence[np.ndarray] = "ci",
    fs: float | None = None,
    levels: int | None = None,
) -> ReplicateResult:
    """Fit one univariate model to several recordings of the same sensor.

    ``theta_hat = argmin sum_r (nu_hat_r - nu(theta))' Omega_r (nu_hat_r - nu(theta))``: the
    replicates may have different lengths (and numbers of levels); each keeps its own
    weights. Solved by variable projection as :func:`engine.fit_gmwm` (exact NNLS for the
    variances; a grid, the replicates' own fits and Nelder-Mead for the AR1/GM terms).

    Parameters
    ----------
    wvs : sequence of WaveletVariance or array_like
        The replicates' WVs, or raw series (WV computed with ``fs``). At least 2.
    model : Model, Process or str
        E.g. ``"2*GM+WN+RW"``.
    weights : "ci", "identity" or sequence of (J_r,) arrays
        Diagonal weights per replicate (the univariate ``"ci"`` by default).
    fs : float, optional
        Sampling frequency of raw series; must agree with the WVs' fs.
    levels : int, optional
        Use only the first ``levels`` levels of every replicate.

    Returns
    -------
    ReplicateResult
    """
    t0 = time.perf_counter()
    m = parse_model(model)
    items = list(wvs)
    if len(items) < 2:
        raise FitError(
            f"a replicate fit needs at least 2 recordings, got {len(items)}; use fit_gmwm for one"
        )
    out: list[WaveletVariance] = []
    for r, it in enumerate(items):
        try:
            if isinstance(it, WaveletVariance):
                wv = it
            else:
                wv = wavelet_variance(it, fs=1.0 if fs is None else fs)
        except (ValueError, TypeError) as e:
            raise FitError(f"replicate {r + 1}: {e}") from None
        if levels is not None:
            if not 1 <= levels <= wv.n_levels:
                raise FitError(
                    f"replicate {r + 1}: levels={levels} is out of range (it has "
                    f"{wv.n_levels} levels)"
                )
            wv = wv.truncate(levels)
        if not np.any(wv.variance > 0):
            raise FitError(f"replicate {r + 1}: the WV is 0 at every level (constant signal)")
        out.append(wv)
    fs0 = out[0].fs
    for r, wv in enumerate(out):
        if not math.isclose(wv.fs, fs0, rel_tol=1e-9):
            raise FitError(
                f"replicate {r + 1} has fs = {wv.fs:g} Hz but replicate 1 has "
                f"{fs0:g} Hz: replicates of one sensor share fs"
            )
    if fs is not None and not math.isclose(fs, fs0, rel_tol=1e-9):
        raise FitError(f"fs={fs} Hz disagrees with the replicates' fs={fs0} Hz")
    m.validate(sum(w.n_levels for w in out))
    if isinstance(weights, str):
        ws = []
        for r, wv in enumerate(out):
            try:
                ws.append(np.diagonal(weight_matrix(wv, weights)[0]).copy())
            except FitError as e:
                raise FitError(f"replicate {r + 1}: {e}") from None
        wname = weights
    else:
        ws = [np.asarray(v, float) for v in weights]
        if len(ws) != len(out) or any(
            v.shape != (wv.n_levels,) for v, wv in zip(ws, out, strict=False)
        ):
            raise FitError("give one (J_r,) weight vector per replicate")
        if any(np.any(~np.isfinite(v)) or np.any(v < 0) for v in ws):
            raise FitError("the weights must be finite and non-negative")
        wname = "user"
    prob = NNLSProblem(
        m.cleared(),
        np.concatenate([w.tau_samples for w in out]),
        fs0,
        np.diag(np.sqrt(np.concatenate(ws))),
        np.concatenate([w.variance for w in out]),
        max(max(w.n for w in out), 2 ** (max(w.n_levels for w in out) + 1)),
    )
    if prob.k == 0:
        u = np.zeros(0)
        converged, method, msg = True, "closed-form", "closed-form non-negative least squares"
    else:
        # the replicates' own fits (GM/AR1 most persistent first) are candidates too
        starts: list[tuple[float, ...]] = []
        for wv, w in zip(out, ws, strict=True):
            try:
                fr: GMWMResult = fit_gmwm(wv, m.cleared(), weights=w)
            except (FitError, ModelError):  # pragma: no cover - a degenerate replicate
                continue
            st = start_coordinates(fr.model, fs0)
            if st is not None:
                starts.append(st)
        st = start_coordinates(m, fs0) if m.is_set else None
        if st is not None:
            starts.append(st)
        _, u, converged = search(prob, starts, keep=4)
        method, msg = "grid+nelder-mead", search_message(converged)
    fitted = fitted_model(prob, u, fs0)
    implied = [fitted.wv(w.tau_samples, fs0) for w in out]
    objs = [
        float(np.sum(wt * (w.variance - im) ** 2))
        for w, wt, im in zip(out, ws, implied, strict=True)
    ]
    longest = max(out, key=lambda w: w.n_levels)
    return ReplicateResult(
        model=fitted,
        wvs=out,
        weights=wname,
        omega=np.diag(np.concatenate(ws)),
        objective=float(sum(objs)),
        objectives=objs,
        implied=implied,
        components=fitted.components(longest.tau_samples, fs0),
        converged=converged,
        at_bound=at_bound(fitted, fs0, prob.tc_min, prob.tc_max),
        warnings=sub_sample_warnings(fitted, fs0, out[0].unit),
        n_evaluations=prob.n_eval,
        method=method,
        message=msg,
        elapsed_s=time.perf_counter() - t0,
    )
