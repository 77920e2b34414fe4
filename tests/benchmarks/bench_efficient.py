"""Efficient GMWM against the WV itself. Run from the repository root:

    python tests/benchmarks/bench_efficient.py [--n 6.3e6] [--repeat 3] [--no-old]

For each model (WN+RW+DR at 1 Hz; 2*GM+WN+RW at 100 Hz with a slow GM, beta = 0.01): the time
of the WV of all levels, of the ci-weighted fit, of ``fit_efficient`` (the ci fit, V from the
closed form, the refit with ``Omega = V^-1``) and their ratio to the WV; then the previous
V (the 2^(J+1)-node frequency quadrature, rebuilt here from ``frequency_grid``) for the same
first-step model: its time, and how far it and the efficient fit it gives are from the new ones
(the previous quadrature left out the f = 0 node, which matters for a random walk).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import engine as eg
from engine.fit import fit_efficient
from engine.fit.asymptotic import frequency_grid, inverse_cov, spectral_density, wv_cov_model
from engine.models import Model

MODELS = [
    ("WN(sigma2=1e-4)+RW(gamma2=1e-12)+DR(omega=1e-9)", "WN+RW+DR", 1.0),
    (
        "GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.01, sigma2_gm=1e-4)+WN(sigma2=1e-2)"
        "+RW(gamma2=1e-10)",
        "2*GM+WN+RW",
        100.0,
    ),
]


def best(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, min(times)


def previous_v(model: Model, wv) -> np.ndarray:
    """The previous wv_cov_model (periodic trapezoid rule without the f = 0 node)."""
    model = Model(tuple(p for p in model.processes if p.linear_coef() != 0))
    levels = wv.n_levels
    f, wts = frequency_grid(levels, model, wv.fs)
    out = np.zeros((levels, levels))
    inv_m2 = 1.0 / 4.0 ** np.arange(levels)
    chunk = 1 << 14
    g = np.empty((levels, chunk))
    for a in range(0, f.size, chunk):
        fc, wc = f[a : a + chunk], wts[a : a + chunk]
        k = fc.size
        s = np.zeros_like(fc)
        for p in model.processes:
            s += spectral_density(p, fc, wv.fs)
        x = np.pi * fc
        sin_m, cos_m = np.sin(x), np.cos(x)
        base = s / (sin_m * sin_m)
        for j in range(levels):
            sin2 = sin_m * sin_m
            np.multiply(sin2 * sin2, base * inv_m2[j], out=g[j, :k])
            sin_m, cos_m = 2.0 * sin_m * cos_m, 1.0 - 2.0 * sin2
        gk = g[:, :k]
        out += (gk * wc) @ gk.T
    m_j = wv.n_coef.astype(float)
    return 2.0 * out / np.maximum.outer(m_j, m_j)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=float, default=6.3e6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-old", action="store_true", help="skip the previous quadrature")
    args = ap.parse_args()
    n = int(args.n)
    for truth, spec, fs in MODELS:
        x = eg.parse_model(truth).simulate(n, fs=fs, rng=1)
        wv, t_wv = best(lambda x=x, fs=fs: eg.wavelet_variance(x, fs=fs), args.repeat)
        fit_efficient(wv, spec)  # warm: the integer kernels of J levels are cached per process
        _, t_ci = best(lambda wv=wv, spec=spec: eg.fit_gmwm(wv, spec), args.repeat)
        eff, t_eff = best(lambda wv=wv, spec=spec: fit_efficient(wv, spec), args.repeat)
        first = eg.fit_gmwm(wv, spec)
        v_new, t_v = best(lambda first=first, wv=wv: wv_cov_model(first.model, wv), args.repeat)
        print(f"{spec} at {fs:g} Hz, N = {n:,} ({wv.n_levels} levels)")
        print(f"  WV                       {t_wv * 1e3:9.1f} ms")
        print(f"  fit, ci weights          {t_ci * 1e3:9.1f} ms")
        print(f"  V (closed form)          {t_v * 1e3:9.1f} ms")
        print(
            f"  fit_efficient (V incl.)  {t_eff * 1e3:9.1f} ms  = {t_eff / t_wv:.2f} x the WV"
            "   (target <= 1)"
        )
        if args.no_old:
            continue
        v_old, t_old = best(lambda first=first, wv=wv: previous_v(first.model, wv), 1)
        old = eg.fit_gmwm(wv, first.model, weights=inverse_cov(v_old))
        rel_v = np.abs(v_old - v_new) / v_new
        d = np.diagonal(rel_v)
        top = ", ".join(f"{r:.1e}" for r in d[-3:])
        print(f"  previous V (quadrature)  {t_old * 1e3:9.1f} ms  ({t_old / t_v:,.0f} x the new V)")
        print(
            f"  previous vs new V: max rel. {rel_v.max():.1e}; levels 1..J-3 {d[:-3].max():.1e},"
            f" the last three {top}"
        )
        for r_new, r_old in zip(eff.param_records, old.param_records, strict=True):
            rel = abs(r_old.value - r_new.value) / max(abs(r_new.value), 1e-300)
            name = f"{r_new.label}.{r_new.name}"
            print(f"    {name:<16} {r_new.value:13.6e}  previous rel. {rel:.1e}")


if __name__ == "__main__":
    main()
