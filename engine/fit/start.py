"""Rough starting values of a model's parameters, read off an empirical WV.

Used before a fit (the app's what-if sliders start from them; a model with values is an extra
start of the fit, which otherwise searches from its own grid). AR1/GM correlation times are
spread geometrically over the scales, a process with another non-linear parameter reads its own
off the WV (:meth:`engine.models.Process.start_nl`: MA1); each variance-like parameter is half
the largest value whose WV curve stays below the empirical WV.
"""

from __future__ import annotations

import math

import numpy as np

from ..models import Model
from ..wv import WaveletVariance

__all__ = ["starting_values"]


def starting_values(model: Model, wv: WaveletVariance) -> dict[str, float]:
    """Rough values of every parameter of ``model`` read off the empirical WV ``wv``.

    The correlation times of the nonlinear processes (AR1, GM) are spread geometrically from
    a quarter of the largest scale down to the smallest (at least 2 samples), the slowest
    first; another non-linear parameter is the process's own guess
    (:meth:`engine.models.Process.start_nl`: an MA1's theta is the one whose WV falls from
    the first scale to the second as the empirical WV does). Each process's variance-like
    parameter (sigma2, q2, ...) is then half the largest value whose WV curve alone stays
    below the empirical WV at every scale where both are positive, so that the guessed
    model's WV does not exceed the empirical one by much.

    Parameters
    ----------
    model : Model
        The model (its values, if any, are ignored).
    wv : WaveletVariance
        The empirical WV.

    Returns
    -------
    dict of str to float
        ``{"label.param": value}`` for every parameter of ``model`` (a drift's ``omega`` is
        the square root of its guessed squared slope; a GM's ``beta`` is in 1/s).
    """
    tau = wv.tau_samples.astype(float)
    out: dict[str, float] = {}
    nl = []  # the terms whose start is a correlation time (AR1, GM)
    for i, p in enumerate(model.processes):
        if p.nonlinear is None:
            continue
        own = p.start_nl(tau, wv.variance, wv.fs)
        if own is None:
            nl.append(i)
        else:
            out[f"{model.labels[i]}.{p.nonlinear}"] = p.nl_from_phi(own, wv.fs)
    tcs = np.geomspace(tau[-1] / 4, max(tau[0], 2.0), len(nl)) if nl else np.zeros(0)
    for k, i in enumerate(nl):
        lab, p = model.labels[i], model.processes[i]
        phi = math.exp(-1.0 / float(tcs[k]))
        out[f"{lab}.{p.nonlinear}"] = p.nl_from_phi(phi, wv.fs)
    pos = wv.variance > 0
    for lab, p in zip(model.labels, model.processes, strict=True):
        if p.nonlinear is not None:
            nlv = p.phi_from_nl(out[f"{lab}.{p.nonlinear}"], wv.fs)
        else:
            nlv = None
        basis = np.asarray(p.basis(tau, wv.fs, nlv), float)
        ok = pos & (basis > 0)
        h = 0.5 * float(np.min(wv.variance[ok] / basis[ok])) if np.any(ok) else 1e-12
        h = max(h, 1e-300)
        name = p.param_names[-1] if p.nonlinear else p.param_names[0]
        # the parameter of the linear coefficient h (a drift's omega is its square root)
        out[f"{lab}.{name}"] = float(getattr(p.from_fit(h, nlv, wv.fs), name))
    return out
