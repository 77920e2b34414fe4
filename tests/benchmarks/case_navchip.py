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
plus the bias-instability floor of the Allan variance, ``(0.664 B)^2`` (docs/conventions.md;
``engine.units.BI_FACTOR = sqrt(2 ln 2 / pi) = 0.6643``), i.e. ``(0.664 B)^2 / 2`` in wavelet
variance (``nu2_j = AVAR(tau_j / 2) / 2``): ``engine.check_datasheet`` draws it and gives the
per-scale verdicts (inside, above or below the empirical 95 % interval).

Run from the repository root::

    python tests/benchmarks/case_navchip.py [--out docs/figures/case_navchip_gyro_x.png]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

import engine as eg
from engine.units import BI_FACTOR, DISPLAY, si_factor, to_datasheet

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "derived" / "navchip_wv_av.h5"
FIG = ROOT / "docs" / "figures" / "case_navchip_gyro_x.png"
CHANNEL = "gyro_x"
MODEL = "QN+WN+2*GM+RW+DR"  # the paper's model (sec. V)

#: NavChip datasheet (the paper's ref. [19]), gyroscope
DATASHEET_ARW_DEG_S_RTHZ = 0.003  # (deg/s)/sqrt(Hz)  (= 0.18 deg/sqrt(h))
DATASHEET_BI_DEG_H = 10.0  # deg/h, in-run bias instability
DATASHEET = eg.inference.DatasheetSpec.from_values(
    {"arw": (DATASHEET_ARW_DEG_S_RTHZ, "deg/s/sqrt(Hz)"), "bi": (DATASHEET_BI_DEG_H, "deg/h")},
    source="NavChip product brief",
)


def objective(wv: Any, implied: np.ndarray, omega: np.ndarray) -> float:
    """GMWM objective ``(nu_hat - nu)' Omega (nu_hat - nu)``."""
    d = np.asarray(wv.variance) - implied
    return float(d @ omega @ d)


def run(channel: str = CHANNEL) -> dict[str, Any]:
    """Fit the paper's model and check the datasheet model on one NavChip gyroscope.

    The datasheet model and its per-scale verdicts are ``engine.check_datasheet``'s: white
    noise ``N^2 fs`` per sample plus the bias-instability floor ``(BI_FACTOR B)^2 / 2`` in WV.

    Returns
    -------
    dict
        ``wv``, ``fit`` (GMWMResult), ``check`` (DatasheetCheck), ``datasheet`` (WV arrays:
        ``WN``, ``BI floor``, ``total``), ``obj_gmwm``, ``obj_datasheet`` (same Omega),
        ``outside`` (bool per scale: datasheet WV outside the empirical 95 % interval),
        ``below`` (below it), ``fit_outside`` (the fit outside it).
    """
    log = eg.load_log(DATA)
    wv = log.wv[channel]
    fit = eg.fit_gmwm(wv, MODEL)
    chk = eg.check_datasheet(wv, DATASHEET, fit=fit)
    ds = {**chk.components, "total": chk.datasheet_wv}
    verdict = np.asarray(chk.verdict)
    return {
        "wv": wv,
        "fit": fit,
        "check": chk,
        "datasheet": ds,
        "obj_gmwm": fit.objective,
        "obj_datasheet": objective(wv, ds["total"], fit.omega),
        "outside": verdict != "inside",
        "below": verdict == "below",
        "fit_outside": np.asarray(chk.fit_verdict) != "inside",
    }


def print_tables(res: dict[str, Any]) -> None:
    """Print the fitted parameters, the datasheet comparison and the scale table."""
    wv, fit, chk = res["wv"], res["fit"], res["check"]
    fs = wv.fs
    print(fit.summary())
    print()
    n_fit = to_datasheet("WN", fit.params["WN.sigma2"], fs)
    n_ds = chk.datasheet.values["N"]
    deg_s = si_factor("deg/s")[1]  # rad/s per deg/s
    arw, bi = DISPLAY[("gyroscope", "N")].factor, DISPLAY[("gyroscope", "B")].factor
    print("quantity                         GMWM            datasheet [19]")
    print(f"white noise N [(deg/s)/sqrt(Hz)]  {n_fit / deg_s:.4g}       {n_ds / deg_s:.4g}")
    print(f"ARW [deg/sqrt(h)]                 {n_fit * arw:.4g}        {n_ds * arw:.4g}")
    print(
        f"min implied WV [(rad/s)^2]        {np.min(fit.implied):.3g}      "
        f"{chk.datasheet.floor_wv(wv.unit):.3g} (BI floor, B = {DATASHEET_BI_DEG_H:g} deg/h)"
    )
    bi_emp = math.sqrt(2 * np.min(wv.variance)) / BI_FACTOR * bi
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
