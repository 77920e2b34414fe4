"""Case study: the NavChip gyroscope, GMWM model against the manufacturer's (GMWM paper, sec. V).

Guerrier, Jurado, Khaghani et al., "Wavelet-Based Moment-Matching Techniques for Inertial
Sensor Calibration", IEEE TIM 2020, section V and Fig. 3-4: 3.5 h of static NavChip data;
the GMWM model is "quantization noise, white noise, two first-order Gauss-Markov processes,
random walk, and drift"; the datasheet model is "far from [the data] and too optimist at
most scales". The paper prints no parameter values and does not name the gyroscope axis;
this script uses gyro X of ``../shared/data/derived/navchip_wv_av.h5`` (WV summary of the
same 3.45 h, 250 Hz log).

Manufacturer's values (Intersense NavChip product brief, the paper's ref. [19]; the values
are those the SMAC group's own GUI uses for this sensor, ``SMAC-Group/gui4gmwm``,
``gui4gmwm/app.R``): gyroscope angle random walk 0.003 (deg/s)/sqrt(Hz) (= 0.18
deg/sqrt(h)) and in-run bias instability 10 deg/h. The datasheet model is white noise
plus the bias-instability floor of the Allan variance, ``(0.664 B)^2`` (CONVENTIONS.md),
i.e. ``(0.664 B)^2 / 2`` in wavelet variance (``nu2_j = AVAR(tau_j / 2) / 2``).

Run from the repository root::

    python tests/benchmarks/case_navchip.py [--out tests/benchmarks/figures/case_navchip_gyro_x.png]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

import engine as eg

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "derived" / "navchip_wv_av.h5"
FIG = ROOT / "tests" / "benchmarks" / "figures" / "navchip_gyro_x.png"
CHANNEL = "gyro_x"
MODEL = "QN+WN+2*GM+RW+DR"  # the paper's model (sec. V)

#: NavChip datasheet (the paper's ref. [19]), gyroscope
DATASHEET_ARW_DEG_S_RTHZ = 0.003  # (deg/s)/sqrt(Hz)  (= 0.18 deg/sqrt(h))
DATASHEET_BI_DEG_H = 10.0  # deg/h, in-run bias instability
BI_FACTOR = 0.664  # AV floor of flicker noise: AV = (0.664 B)^2 (CONVENTIONS.md)


def datasheet_params(fs: float) -> dict[str, float]:
    """Convert the datasheet values to per-sample WN variance and a WV floor (rad/s units).

    Kept in this one function (CONVENTIONS.md formulas), independent of the engine's
    datasheet module, which is being rewritten: ``N = sqrt(sigma2 dt)`` so
    ``sigma2 = N^2 fs``; the bias-instability floor of the AV is ``(0.664 B)^2`` and the
    WV is half the AV.

    Parameters
    ----------
    fs : float
        Sampling frequency [Hz].

    Returns
    -------
    dict
        ``wn_sigma2`` [(rad/s)^2 per sample], ``bi_floor_wv`` [(rad/s)^2],
        ``N`` [(rad/s)/sqrt(Hz)], ``B`` [rad/s].
    """
    d2r = math.pi / 180.0
    n = DATASHEET_ARW_DEG_S_RTHZ * d2r
    b = DATASHEET_BI_DEG_H / 3600.0 * d2r
    return {
        "wn_sigma2": n * n * fs,
        "bi_floor_wv": (BI_FACTOR * b) ** 2 / 2.0,
        "N": n,
        "B": b,
    }


def datasheet_wv(wv: Any) -> dict[str, np.ndarray]:
    """WV implied by the datasheet model at the WV's scales: WN, the BI floor, their sum."""
    p = datasheet_params(wv.fs)
    wn = eg.Model([eg.WN(sigma2=p["wn_sigma2"])]).wv(wv.tau_samples)
    floor = np.full(wn.shape, p["bi_floor_wv"])
    return {"WN": wn, "BI floor": floor, "total": wn + floor}


def objective(wv: Any, implied: np.ndarray, omega: np.ndarray) -> float:
    """GMWM objective ``(nu_hat - nu)' Omega (nu_hat - nu)``."""
    d = np.asarray(wv.variance) - implied
    return float(d @ omega @ d)


def run(channel: str = CHANNEL) -> dict[str, Any]:
    """Fit the paper's model and evaluate the datasheet model on one NavChip gyroscope.

    Returns
    -------
    dict
        ``wv``, ``fit`` (GMWMResult), ``datasheet`` (WV arrays), ``params`` (datasheet
        conversion), ``obj_gmwm``, ``obj_datasheet`` (same Omega), ``outside`` (bool per
        scale: datasheet WV outside the empirical 95 % interval), ``below`` (below it).
    """
    log = eg.load_log(DATA)
    wv = log.wv[channel]
    fit = eg.fit_gmwm(wv, MODEL)
    ds = datasheet_wv(wv)
    lo, hi = np.asarray(wv.ci_low), np.asarray(wv.ci_high)
    return {
        "wv": wv,
        "fit": fit,
        "datasheet": ds,
        "params": datasheet_params(wv.fs),
        "obj_gmwm": fit.objective,
        "obj_datasheet": objective(wv, ds["total"], fit.omega),
        "outside": (ds["total"] < lo) | (ds["total"] > hi),
        "below": ds["total"] < lo,
        "fit_outside": (fit.implied < lo) | (fit.implied > hi),
    }


def print_tables(res: dict[str, Any]) -> None:
    """Print the fitted parameters, the datasheet comparison and the scale table."""
    wv, fit, p = res["wv"], res["fit"], res["params"]
    fs = wv.fs
    print(fit.summary())
    print()
    n_fit = math.sqrt(fit.params["WN.sigma2"] / fs)
    r2d = 180.0 / math.pi
    print("quantity                         GMWM            datasheet [19]")
    print(f"white noise N [(deg/s)/sqrt(Hz)]  {n_fit * r2d:.4g}       {p['N'] * r2d:.4g}")
    print(
        f"ARW [deg/sqrt(h)]                 {60 * n_fit * r2d:.4g}        {60 * p['N'] * r2d:.4g}"
    )
    print(
        f"min implied WV [(rad/s)^2]        {np.min(fit.implied):.3g}      "
        f"{p['bi_floor_wv']:.3g} (BI floor, B = {DATASHEET_BI_DEG_H:g} deg/h)"
    )
    bi_emp = math.sqrt(2 * np.min(wv.variance)) / BI_FACTOR * r2d * 3600
    print(f"bias instability from min WV [deg/h]  {bi_emp:.3g}    {DATASHEET_BI_DEG_H:g}")
    print(
        f"objective, same Omega (ci weights)  {res['obj_gmwm']:.4g}    {res['obj_datasheet']:.4g}"
    )
    print()
    print("  tau [s]     WV emp      95% low     95% high    GMWM        datasheet   ds outside")
    for j in range(len(wv.variance)):
        print(
            f"  {wv.tau_s[j]:9.3g}  {wv.variance[j]:.3e}  {wv.ci_low[j]:.3e}  "
            f"{wv.ci_high[j]:.3e}  {fit.implied[j]:.3e}  {res['datasheet']['total'][j]:.3e}  "
            f"{'below' if res['below'][j] else ('above' if res['outside'][j] else '')}"
        )
    print(
        f"datasheet outside the 95 % interval at {int(res['outside'].sum())} of "
        f"{len(wv.variance)} scales ({int(res['below'].sum())} below); "
        f"GMWM outside at {int(res['fit_outside'].sum())}"
    )


def plot(res: dict[str, Any], out: Path) -> None:
    """Fig. 3 and 4 of the paper in one figure: data, GMWM, its decomposition, datasheet."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wv, fit, ds = res["wv"], res["fit"], res["datasheet"]
    t = np.asarray(wv.tau_s)
    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=90)
    ax.fill_between(t, wv.ci_low, wv.ci_high, color="C0", alpha=0.2, label="95 % interval")
    ax.loglog(t, wv.variance, "o-", color="C0", ms=3, label="empirical WV")
    ax.loglog(t, fit.implied, "-", color="C1", lw=2, label=f"GMWM {MODEL}")
    for i, (lab, comp) in enumerate(fit.components.items()):
        comp = np.asarray(comp)
        keep = comp > 0
        if keep.any():
            ax.loglog(t[keep], comp[keep], ":", color=f"C{i + 3}", lw=1.2, label=lab)
    ax.loglog(t, ds["total"], "--", color="C2", lw=2, label="datasheet (ARW + BI)")
    ymin = np.min(wv.ci_low) / 30
    ax.set_ylim(ymin, np.max(wv.ci_high) * 2)
    ax.set_xlabel("scale tau [s]")
    ax.set_ylabel("wavelet variance [(rad/s)^2]")
    ax.set_title(f"NavChip {CHANNEL}: GMWM vs datasheet (GMWM paper, Fig. 3-4)", fontsize=9)
    ax.legend(fontsize=7, ncol=2, loc="upper center")
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)


def main() -> None:
    """Command-line entry: print the tables, write the figure."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=FIG)
    args = ap.parse_args()
    res = run()
    print_tables(res)
    plot(res, args.out)
    print(f"figure: {args.out}")


if __name__ == "__main__":
    main()
