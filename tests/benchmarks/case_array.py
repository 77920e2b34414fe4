"""Case study: two accelerometer channels with a shared AR1 (multivariate paper, sec. VI).

Xu, Guerrier, Molinari, Karemera, "Multivariate Signal Modelling with Applications to
Inertial Sensor Calibration", section VI and Fig. 2: the X accelerometers of two XSens MTi-G
IMUs (250 Hz, about 1 h, recorded together), each modelled as 2*AR1 + RW, with one of the
AR1 processes shared (its WCCV describes the cross-covariance).

The shared data has no simultaneous MTi-G pair (``mtig_cont_imu1.h5`` is one gyro axis,
``derived/mtig_imu6_wv.h5`` holds six WVs without cross-covariances), and the six ADIS16405
replicates are separate recordings (no common time base, so no physical shared process).
The closest feasible study, done here:

(a) the array: two simultaneously recorded accelerometer axes (X and Y) of ADIS16405
    replicate 1 (100 Hz, 2.78 h), the paper's model 2*AR1+RW per channel, one AR1 shared,
    fitted by MGMWM; compared with the independent fit (no shared process);
(b) the MTi-G univariately: the paper's per-channel model 2*AR1+RW on the MTi-G X
    accelerometer WV (``derived/mtig_imu6_wv.h5``).

Run from the repository root::

    python tests/benchmarks/case_array.py [--out docs/figures/array_adis_accel.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

import engine as eg
import engine.multivariate as mv

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
ADIS = DATA / "adis16405_imu1.h5"
MTIG = DATA / "derived" / "mtig_imu6_wv.h5"
FIG = ROOT / "docs" / "figures" / "array_adis_accel.png"
CHANNELS = ["accel_x", "accel_y"]
MODEL = "2*AR1+RW"  # the paper's per-channel model (sec. VI)


def run_array() -> dict[str, Any]:
    """MGMWM fits of the two-channel array: each AR1 shared in turn, and no sharing.

    Returns
    -------
    dict
        ``wvm`` (WVMatrix), ``fits`` (label shared -> MGMWMResult), ``independent``
        (MGMWMResult without shared process), ``best`` (label of the lowest objective).
    """
    log = eg.load_log(ADIS)
    wvm = eg.wv.wv_matrix(log, channels=CHANNELS)
    fits = {}
    for lab in ("AR1_1", "AR1_2"):
        fits[lab] = mv.fit_mgmwm(wvm, mv.MultiModel(CHANNELS, MODEL, shared=[lab]))
    indep = mv.fit_mgmwm(wvm, mv.MultiModel(CHANNELS, MODEL))
    best = min(fits, key=lambda k: fits[k].objective)
    return {"wvm": wvm, "fits": fits, "independent": indep, "best": best}


def run_mtig() -> Any:
    """The paper's per-channel model on the MTi-G X accelerometer WV (univariate GMWM)."""
    log = eg.load_log(MTIG)
    return eg.fit_gmwm(log.wv["accel_x"], MODEL)


def print_tables(arr: dict[str, Any], mtig: Any) -> None:
    """Print the array fits, the shared-process estimates and the MTi-G fit."""
    print("(a) ADIS16405 replicate 1, accel_x + accel_y, MGMWM")
    print(f"  independent fit (no shared process): objective = {arr['independent'].objective:.6g}")
    for lab, r in arr["fits"].items():
        sh = r.shared[lab]
        corr = sh.cov[0, 1] / np.sqrt(sh.cov[0, 0] * sh.cov[1, 1])
        print(
            f"  shared {lab}: objective = {r.objective:.6g}; {sh.nl_name} = {sh.nl:.4f} "
            f"(correlation time {-1 / (arr['wvm'].fs * np.log(sh.nl)):.3g} s); "
            f"var = {sh.cov[0, 0]:.3e}, {sh.cov[1, 1]:.3e} {sh.unit}; corr = {corr:.3f}"
        )
    print()
    print(arr["fits"][arr["best"]].summary())
    print()
    print("(b) MTi-G accel_x (WV summary), univariate GMWM of 2*AR1+RW")
    print(mtig.summary())


def plot(arr: dict[str, Any], out: Path) -> None:
    """The paper's Fig. 2: WV on the diagonal, WCCV off it, empirical and implied."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wvm, r = arr["wvm"], arr["fits"][arr["best"]]
    ind = arr["independent"]
    t = np.asarray(wvm.tau_s)
    k = len(CHANNELS)
    fig, axes = plt.subplots(k, k, figsize=(7.2, 5.8), dpi=80, sharex=True)
    for a in range(k):
        for b in range(k):
            ax = axes[a, b]
            v = wvm.values[:, a, b]
            lo, hi = wvm.ci_low[:, a, b], wvm.ci_high[:, a, b]
            imp = r.implied[:, a, b]
            if a == b:
                ax.fill_between(t, lo, hi, color="C0", alpha=0.2, label="95 % interval")
                ax.loglog(t, v, "o-", ms=3, color="C0", label="empirical WV")
                ax.loglog(t, imp, "--", color="C1", lw=2, label="MGMWM implied")
                for i, (lab, comp) in enumerate(r.components.items()):
                    c = np.asarray(comp)[:, a, b]
                    if np.any(c > 0) and (lab == r_label(r) or lab.startswith(CHANNELS[a])):
                        ax.loglog(t, np.where(c > 0, c, np.nan), ":", color=f"C{i + 3}", label=lab)
                ax.set_title(f"WV {CHANNELS[a]}", fontsize=9)
            else:
                ax.fill_between(t, lo, hi, color="C0", alpha=0.2)
                ax.semilogx(t, v, "o-", ms=3, color="C0", label="empirical WCCV")
                ax.semilogx(t, imp, "--", color="C1", lw=2, label="MGMWM implied")
                ax.semilogx(t, ind.implied[:, a, b], "-", color="grey", lw=1, label="independent")
                ax.set_yscale("symlog", linthresh=1e-9)
                ax.set_title(f"WCCV {CHANNELS[a]} x {CHANNELS[b]}", fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=6)
            if a == k - 1:
                ax.set_xlabel("scale tau [s]")
            if b == 0:
                ax.set_ylabel("[g^2]")
    fig.suptitle(
        f"ADIS16405 accel X/Y: {MODEL}, shared {arr['best']} (multivariate paper, Fig. 2)",
        fontsize=9,
    )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)


def r_label(r: Any) -> str:
    """Label of the (single) shared process of a fit."""
    return next(iter(r.shared))


def main() -> None:
    """Command-line entry: print the tables, write the figure."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=FIG)
    args = ap.parse_args()
    arr = run_array()
    mtig = run_mtig()
    print_tables(arr, mtig)
    plot(arr, args.out)
    print(f"figure: {args.out}")


if __name__ == "__main__":
    main()
