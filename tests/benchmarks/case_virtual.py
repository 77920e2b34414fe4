"""Case study: the optimal virtual gyroscope of six ADIS16405 replicates (gyro X).

The use of the MGMWM the multivariate paper names (after Zhang et al., PLANS 2018; Vaccaro &
Zaki, Sensors 2017): from the fitted dependence of k redundant sensors, the weighted mean
with the smallest wavelet variance. Data: the X gyroscopes of the six ADIS16405 replicates
in ``../shared/data`` (100 Hz, 1e6 samples each), taken sample by sample as one array of six
sensors. They are separate recordings (no common time base), so their cross-covariances are
near 0 and the gain over the plain average can only come from the sensors' unequal noise;
the study shows the machinery on real noise, not a physical array.

Model: GM+WN+RW for every sensor, WN, RW and GM shared (one 6 x 6 covariance each, one GM
beta), fitted by MGMWM on every level; the virtual gyro minimises the WV over every level,
each relative to the plain average's (the default), and, second, the WV at 81.92 s (near the
bias-instability floor).

Run from the repository root::

    python tests/benchmarks/case_virtual.py [--out docs/figures/virtual_adis_gyro.png]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

import engine as eg

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
FIG = ROOT / "docs" / "figures" / "virtual_adis_gyro.png"
MODEL, SHARED = "GM+WN+RW", ["WN", "RW", "GM"]
TABLE_SCALES = (0.16, 1.28, 10.24, 81.92, 655.36)  # s
DEG_H = 3600.0  # deg/h per deg/s


def run() -> dict[str, Any]:
    """Load the six logs, fit the MGMWM and build the two virtual gyros."""
    data = {}
    for k in range(1, 7):
        log = eg.load_log(DATA / f"adis16405_imu{k}.h5", channel="gyro_x")
        data[f"IMU {k}"] = log["gyro_x"]
    wvm = eg.wv.wv_matrix(data, fs=log.fs, units=["deg/s"] * 6)
    res = eg.fit_mgmwm(wvm, eg.MultiModel(list(data), MODEL, shared=SHARED))
    return {
        "data": data,
        "res": res,
        "band": eg.virtual_sensor(res),
        "scale": eg.virtual_sensor(res, scale=81.92),
    }


def adev_deg_h(wv: float) -> float:
    """Allan deviation ``sqrt(2 WV)`` in deg/h of a WV in (deg/s)^2."""
    return math.sqrt(2 * max(wv, 0.0)) * DEG_H


def table(out: dict[str, Any]) -> str:
    """The docs/multichannel.md table: Allan deviation (deg/h) of each sensor, the average and the
    virtual gyros at a few scales, with the weights."""
    vs, vs2 = out["band"], out["scale"]
    idx = [int(np.argmin(np.abs(vs.tau_s - s))) for s in TABLE_SCALES]
    head = "| sensor | weight (every level) | weight (81.92 s) | " + " | ".join(
        f"ADEV at {vs.tau_s[i]:g} s [deg/h]" for i in idx
    )
    lines = [head + " |", "|---" * (3 + len(idx)) + "|"]
    for p, c in enumerate(vs.channels):
        cells = [f"{adev_deg_h(vs.sensors_empirical[i, p]):.3g}" for i in idx]
        lines.append(
            f"| {c} | {vs.fitted_weights[p]:.3f} | {vs2.fitted_weights[p]:.3f} | "
            + " | ".join(cells)
        )
    rows = [
        ("plain average", "1/6", "1/6", vs.average_empirical),
        ("**virtual (every level)**", "", "", vs.empirical),
        ("virtual (every level), implied", "", "", vs.implied),
        ("**virtual (81.92 s)**", "", "", vs2.empirical),
    ]
    for name, a, b, v in rows:
        lines.append(
            f"| {name} | {a} | {b} | " + " | ".join(f"{adev_deg_h(v[i]):.3g}" for i in idx)
        )
    lines = [ln if ln.endswith("|") else ln + " |" for ln in lines]
    return "\n".join(lines)


def plot(out: dict[str, Any], path: Path) -> None:
    """Allan deviation of each sensor, the average and the virtual gyro; the weights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    vs = out["band"]
    t = vs.tau_s
    ad = lambda v: np.sqrt(2 * np.maximum(v, 0.0)) * DEG_H  # noqa: E731
    fig, (ax, bx) = plt.subplots(
        1, 2, figsize=(9.0, 4.0), dpi=80, gridspec_kw={"width_ratios": [2.4, 1]}
    )
    for p in range(len(vs.channels)):
        ax.loglog(t, ad(vs.sensors_empirical[:, p]), "-", color="0.65", lw=1,
                  label="each sensor" if p == 0 else None)  # fmt: skip
    ax.loglog(t, ad(vs.average_empirical), "--", color="C0", lw=2, label="plain average")
    ax.fill_between(t, ad(vs.ci_low), ad(vs.ci_high), color="C3", alpha=0.2)
    ax.loglog(t, ad(vs.implied), "-", color="C3", lw=1.5, label="virtual: implied (95 % band)")
    ax.loglog(t, ad(vs.empirical), "o", ms=3.5, color="k", label="virtual: empirical")
    ax.set_xlabel("scale tau = 2^j / fs [s] (Allan averaging time tau / 2)")
    ax.set_ylabel("Allan deviation sqrt(2 WV) [deg/h]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"ADIS16405 gyro X, six replicates: {MODEL}, shared WN, RW, GM", fontsize=9)
    x = np.arange(len(vs.channels))
    bx.bar(x - 0.2, vs.fitted_weights, 0.4, color="C3", label="every level")
    bx.bar(x + 0.2, out["scale"].fitted_weights, 0.4, color="C2", label="at 81.92 s")
    bx.axhline(1 / 6, color="C0", ls="--", lw=1, label="average 1/6")
    bx.set_xticks(x, [c.replace("IMU ", "") for c in vs.channels])
    bx.set_xlabel("replicate")
    bx.set_ylabel("weight [1]")
    bx.legend(fontsize=7)
    bx.set_title("optimal weights (sum 1)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: write the figure, print the summary and the docs table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=FIG, help="the figure (PNG)")
    fig_path = ap.parse_args(argv).out
    out = run()
    plot(out, fig_path)
    res, vs, vs2 = out["res"], out["band"], out["scale"]
    print(f"MGMWM: objective {res.objective:.6g}, converged {res.converged}")
    for lab, est in res.shared.items():
        off = est.corr[np.triu_indices(6, 1)]
        print(f"  shared {lab}: correlations {off.min():+.3f} to {off.max():+.3f}")
    print(vs.table())
    print()
    print(vs2.table().splitlines()[0])
    print(
        f"  fitted weights {np.round(vs2.fitted_weights, 3)}, used {np.round(vs2.weights, 3)} "
        f"(lambda {vs2.shrinkage:.3f}{'; fell back: ' + vs2.fallback if vs2.fell_back else ''}); "
        f"gain vs average {vs2.gain_vs_average:.3f} out of sample, {vs2.fitted_gain:.3f} in sample"
    )
    print()
    print(table(out))
    print(f"figure: {fig_path}")


if __name__ == "__main__":
    main()
