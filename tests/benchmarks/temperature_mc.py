"""Monte Carlo of the temperature compensation (engine.inference.temperature).

R simulated gyro logs (2e5 samples at 100 Hz, 33 min) of WN (sigma2 1e-4 (deg/s)^2) + RW
(gamma2 1e-10 (deg/s)^2) + a bias-temperature sensitivity of 2e-3 deg/s/degC (7.2 deg/h/degC)
under a thermal profile (warm-up from 25 to 35 degC with a 300 s time constant, and a 2 degC
cycle of 600 s). For each log: the sensitivity with its 95 % interval, the GMWM (WN+RW) of
the compensated signal with asymptotic 95 % parameter intervals, and the same GMWM of the
raw signal; and a WN+RW+DR fit of the raw signal (the drift users then see).

With ``--lag TAU`` the bias follows the temperature through a first-order thermal lag of
time constant TAU seconds (``dT_lag/dt = (T - T_lag) / TAU``, integrated here by
``scipy.integrate.solve_ivp`` on the continuous profile, independently of the engine's
discretisation), and the table gives how often the fit keeps the lag (BIC), the median
``tau`` and how often its profile interval covers the truth; without ``--lag`` the same
columns give the false-lag rate.

With ``--segments`` each log is a flight's still parts: three segments (samples 0-60,000,
80,000-140,000 and 160,000-200,000), each with its own bias offset (normal, SD 0.05 deg/s),
and motion between them (a 1 deg/s swing at 0.5 Hz and white noise of SD 0.3 deg/s); the fit
is ``fit_temperature(..., segments=)`` (each segment keeps its own offset; no lag tried) and
the WVs pool the segments.

Usage::

    nice python tests/benchmarks/temperature_mc.py [--reps 200] [--seed 1] [--lag 120]
    nice python tests/benchmarks/temperature_mc.py --segments [--reps 200]

Prints a Markdown table (docs/qualify.md, section Temperature, holds its output).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import stats

import engine as eg
from engine.inference import param_intervals
from engine.inference.temperature import fit_temperature

FS = 100.0
N = 200_000
TRUE = {"WN.sigma2": 1e-4, "RW.gamma2": 1e-10}
C = 2e-3
SEGMENTS = ((0, 60_000), (80_000, 140_000), (160_000, N))


def band(k: int, n: int) -> str:
    lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def profile(t: np.ndarray) -> np.ndarray:
    """Warm-up from 25 to 35 degC (300 s time constant) with a 2 degC cycle of 600 s."""
    return 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sin(2 * np.pi * t / 600)


def lagged_profile(t: np.ndarray, tau: float) -> np.ndarray:
    """The profile through a first-order lag of time constant ``tau`` (s), integrated by
    ``solve_ivp`` on the continuous profile, from the logged temperature at t = 0."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(
        lambda s, x: (profile(s) - x) / tau,
        (0.0, float(t[-1])),
        [float(profile(np.zeros(1))[0])],
        t_eval=t,
        rtol=1e-9,
        atol=1e-9,
        max_step=5.0,
    )
    return np.asarray(sol.y[0])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--lag", type=float, default=0.0, help="planted thermal lag tau (s)")
    ap.add_argument("--segments", action="store_true", help="three still parts of a flight")
    a = ap.parse_args()
    segs = SEGMENTS if a.segments else ()
    rng = np.random.default_rng(a.seed)
    t = np.arange(N) / FS
    temp = profile(t)
    seen = lagged_profile(t, a.lag) if a.lag > 0 else temp  # what the bias follows
    lag_kept, lag_cover, taus = 0, 0, []
    model = eg.parse_model("WN(sigma2=1e-4)+RW(gamma2=1e-10)")
    cover = dict.fromkeys(["sensitivity", *TRUE], 0)
    est: dict[str, list[float]] = {k: [] for k in ["sensitivity", *TRUE, "raw RW", "raw DR"]}
    t0 = time.process_time()
    for _ in range(a.reps):
        y = model.simulate(N, fs=FS, rng=rng) + C * seen
        for lo_s, hi_s in segs:  # each still part's own bias offset
            y[lo_s:hi_s] += rng.normal(0.0, 0.05)
        for (_, m0), (m1, _) in zip(segs[:-1], segs[1:], strict=True):  # the motion
            y[m0:m1] += np.sin(np.pi * t[m0:m1]) + 0.3 * rng.standard_normal(m1 - m0)
        tf = fit_temperature(
            y, temp, fs=FS, model="WN+RW", unit="deg/s", channel="gyro_x", segments=segs
        )
        if tf.tau_s > 0:
            lag_kept += 1
            taus.append(tf.tau_s)
            lag_cover += tf.tau_interval[0] <= a.lag <= tf.tau_interval[1]
        lo, hi = tf.interval[0]
        cover["sensitivity"] += lo <= C <= hi
        est["sensitivity"].append(tf.sensitivity)
        for iv in param_intervals(tf.fit, method="asymptotic", level=0.95):
            if iv.name in TRUE:
                cover[iv.name] += iv.low <= TRUE[iv.name] <= iv.high
                est[iv.name].append(iv.value)
        est["raw RW"].append(tf.fit_raw.params["RW.gamma2"])
        raw_dr = eg.fit_gmwm(tf.wv_raw, "WN+RW+DR")
        est["raw DR"].append(raw_dr.params["DR.omega"])
    cpu = time.process_time() - t0
    r = a.reps
    where = "; three still segments, own offsets, motion between" if segs else ""
    print(f"{r} logs; planted lag {a.lag:g} s{where}; CPU {cpu:.0f} s\n")
    print("| quantity | truth | median estimate | 95 % interval covers truth, % [95 % band] |")
    print("|---|---|---|---|")
    print(
        f"| sensitivity (deg/h/degC) | 7.2 | {np.median(est['sensitivity']):.3g} "
        f"| {band(cover['sensitivity'], r)} |"
    )
    for k, v in TRUE.items():
        print(
            f"| {k} compensated ((deg/s)^2) | {v:.3g} | {np.median(est[k]):.3g} "
            f"| {band(cover[k], r)} |"
        )
    print(
        f"| RW.gamma2 raw, no compensation ((deg/s)^2) | 1e-10 | {np.median(est['raw RW']):.3g} "
        f"(x{np.median(est['raw RW']) / 1e-10:.2g}) | - |"
    )
    print(
        f"| DR.omega raw, WN+RW+DR (deg/s per sample) | 0 | {np.median(np.abs(est['raw DR'])):.3g} "
        "(median of the absolute value) | - |"
    )
    med = f"{np.median(taus):.3g}" if taus else "-"
    print(f"| thermal lag kept (BIC), % of logs | {a.lag:g} s | {band(lag_kept, r)} | - |")
    if a.lag > 0 and lag_kept:
        print(
            f"| lag tau (s), logs where it is kept | {a.lag:g} | {med} "
            f"| {band(lag_cover, lag_kept)} |"
        )


if __name__ == "__main__":
    main()
