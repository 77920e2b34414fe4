"""Monte Carlo check of `gmwm plan` (engine.inference.planning.plan_run).

For each sensor model, the plan gives the shortest log meeting a precision target; here R logs
of that length are simulated from the model, each fitted by the efficient GMWM, and the
realised precision is compared with the plan:

* ``sd(log q_hat)``: the spread of the estimates on the log scale, against the plan's
  ``log(1 + rel) / z`` (the plan's intervals are log-symmetric: ``q exp(+-z s)``);
* ``within``: the share of estimates within the target (``|q_hat / q - 1| <= rel``), against
  the interval level (95 %), with its Wilson 95 % band.

Models: a tactical-grade gyro (WN+RW at 20 Hz), the ADIS16405 gyro and accelerometer
(GM+WN+RW fitted to ../shared/data/adis16405_imu1.h5, gyro_x and accel_x, at 100 Hz; the
gyro's B row at 10 Hz, :func:`at_rate`), a consumer MEMS gyro with a Gauss-Markov term
(GM+WN+RW at 100 Hz), and the XSens MTi-G gyro (../shared/data/mtig_cont_imu1.h5, B only, at
10 Hz: a model the B bound ``SPAN_B`` was not tuned on).

Usage::

    nice python tests/benchmarks/plan_mc.py [--reps 200] [--seed 1] [--json out.json]
    nice python tests/benchmarks/plan_mc.py --only "B within"    # the B rows

Prints a Markdown table (docs/planning.md holds its output).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import engine as eg
from engine.inference.planning import PlanTarget, plan_precision, plan_run

Z = 1.959963984540054
DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def wilson(k: int, n: int, z: float = Z) -> tuple[float, float]:
    """Wilson score interval of a binomial share."""
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def settings() -> list[tuple[str, eg.Model, float, str, PlanTarget, str]]:
    """(name, model, fs, unit, target, model to fit)."""
    out = []
    # the RW's precision depends on the duration, not on fs: the tactical gyro is planned at
    # 20 Hz so that 200 logs of the hours its K needs stay affordable here
    tactical = eg.inference.parse_datasheet("arw=0.01 deg/sqrt(h), rrw=0.1 deg/h/sqrt(h)").model(
        20.0, "deg/s"
    )
    out.append(("tactical gyro", tactical, 20.0, "deg/s", PlanTarget("N", 0.005), "WN+RW"))
    out.append(("tactical gyro", tactical, 20.0, "deg/s", PlanTarget("K", 0.3), "WN+RW"))
    out.append(("tactical gyro", tactical, 20.0, "deg/s", PlanTarget("B", 0.3), "WN+RW"))
    consumer = eg.parse_model(
        "GM(beta=0.05, sigma2_gm=4e-6)+WN(sigma2=2.5e-5)+RW(gamma2=1e-10)"
    )  # per sample at 100 Hz, in rad/s: a 20 s Gauss-Markov bias on a MEMS gyro
    out.append(
        ("consumer MEMS gyro (GM)", consumer, 100.0, "rad/s", PlanTarget("N", 0.01), "GM+WN+RW")
    )
    out.append(
        ("consumer MEMS gyro (GM)", consumer, 100.0, "rad/s", PlanTarget("K", 0.3), "GM+WN+RW")
    )
    # N again at about 50 correlation times of the GM (engine.inference.planning.SPAN_GM)
    out.append(
        ("consumer MEMS gyro (GM)", consumer, 100.0, "rad/s", PlanTarget("N", 0.0044), "GM+WN+RW")
    )
    out.append(
        ("consumer MEMS gyro (GM)", consumer, 100.0, "rad/s", PlanTarget("B", 0.3), "GM+WN+RW")
    )
    path = DATA / "adis16405_imu1.h5"
    if path.exists():
        log = eg.load_log(path)
        for ch, unit in (("gyro_x", "deg/s"), ("accel_x", "g")):
            model = adis_model(log.wavelet_variance(ch))
            for target in (PlanTarget("N", 0.01), PlanTarget("K", 0.3)):
                if ch.startswith("accel"):
                    out.append((f"ADIS16405 {ch}", model, 100.0, unit, target, "GM+WN+RW"))
            if ch.startswith("gyro"):  # its B needs tens of hours: simulated at 10 Hz
                out.append(
                    (f"ADIS16405 {ch}", model, 100.0, unit, PlanTarget("N", 0.01), "GM+WN+RW")
                )
                out.append(
                    (
                        f"ADIS16405 {ch} at 10 Hz",
                        at_rate(model, 100.0, 10.0),
                        10.0,
                        unit,
                        PlanTarget("B", 0.3),
                        "GM+WN+RW",
                    )
                )
            else:
                out.append(
                    (f"ADIS16405 {ch}", model, 100.0, unit, PlanTarget("B", 0.3), "GM+WN+RW")
                )
    else:
        print(f"({path} missing: the ADIS16405 rows are skipped)", file=sys.stderr)
    # a model the B rule (engine.inference.planning.SPAN_B) was not tuned on: the MTi-G gyro
    path = DATA / "mtig_cont_imu1.h5"
    if path.exists():
        model = adis_model(eg.load_log(path).wavelet_variance("gyro_x"))
        out.append(
            (
                "XSens MTi-G gyro_x at 10 Hz",
                at_rate(model, 100.0, 10.0),
                10.0,
                "rad/s",
                PlanTarget("B", 0.3),
                "GM+WN+RW",
            )
        )
    return out


def at_rate(m: eg.Model, fs: float, rate: float) -> eg.Model:
    """The same continuous-time noise sampled at ``rate`` Hz instead of ``fs``: the white
    noise's density and the random walk's K kept (sigma2 * rate / fs, gamma2 * fs / rate), the
    GM (continuous time) unchanged. Its B lies at thousands of seconds, far above either rate's
    sample, so B and the plan's precision of it are the same (docs/planning.md) and 200 logs of
    the tens of hours B needs cost a tenth at 10 Hz."""
    procs = []
    for p in m.processes:
        if p.code == "WN":
            p = p.with_values(sigma2=p.sigma2 * rate / fs)
        elif p.code == "RW":
            p = p.with_values(gamma2=p.gamma2 * fs / rate)
        elif p.code != "GM":
            raise ValueError(f"at_rate: {p.code} is not converted")
        procs.append(p)
    return eg.Model(tuple(procs))


def adis_model(wv: eg.WaveletVariance) -> eg.Model:
    """The efficient 2*GM+WN+RW fit of an ADIS16405 channel with its sub-sample GM folded into
    the white noise (its white-noise equivalent: engine.fit.ieee.white_share), the slow GM and
    the RW kept: GM+WN+RW with values."""
    from engine.fit.ieee import white_share

    fit = eg.fit_gmwm(wv, "2*GM+WN+RW", weights="efficient")
    s2, _ = white_share(fit.model, wv.fs)
    slow = [p for p in fit.model.processes if p.code == "GM" and p.values[0] < wv.fs]
    rw = [p for p in fit.model.processes if p.code == "RW"]
    return eg.Model((*slow[:1], eg.WN(sigma2=s2), *rw))


def estimate(res: eg.GMWMResult, key: str) -> float:
    q = res.ieee.get(key)
    return math.nan if q is None else q.value


def run(reps: int, seed: int, only: str = "") -> list[dict]:
    rows = []
    for name, model, fs, unit, target, fitted in settings():
        if only and not any(o in f"{name} {target}" for o in only.split("|")):
            continue
        t0 = time.perf_counter()
        plan = plan_run(model, fs, (target,), unit=unit)
        n = plan.required[target.key]
        if n is None:
            print(f"{name}: {target} not reachable", file=sys.stderr)
            continue
        truth = plan_precision(model, fs, n, unit=unit)[target.key]
        rel_planned = max(truth.high / truth.value - 1.0, 1.0 - truth.low / truth.value)
        rng = np.random.default_rng(seed)
        est, edge = [], 0
        for _ in range(reps):
            x = model.simulate(n, fs=fs, rng=rng)
            wv = eg.wavelet_variance(x, fs=fs, unit=unit)
            try:
                res = eg.fit_gmwm(wv, fitted, weights="efficient")
            except eg.FitError:
                est.append(math.nan)
                continue
            est.append(estimate(res, target.key))
            q = res.ieee.get(target.key)
            edge += bool(q is not None and q.upper_bound)  # B, ADEV_min: no floor found
        e = np.asarray(est)
        ok = np.isfinite(e) & (e > 0)
        lr = np.log(e[ok] / truth.value)
        within = int(np.sum(np.abs(e[ok] / truth.value - 1.0) <= target.rel))
        sd_planned = math.log(1.0 + rel_planned) / Z
        sd = float(np.std(lr, ddof=1))
        se_sd = sd / math.sqrt(2 * (ok.sum() - 1))
        lo, hi = wilson(within, int(ok.sum()))
        rows.append(
            {
                "model": name,
                "target": str(target),
                "samples": n,
                "hours": n / fs / 3600.0,
                "reps": int(ok.sum()),
                "sd_planned": sd_planned,
                "sd_realised": sd,
                "sd_band": (sd - Z * se_sd, sd + Z * se_sd),
                "bias_pct": 100 * float(np.expm1(np.mean(lr))),
                "within": within / ok.sum(),
                "within_band": (lo, hi),
                "seconds": time.perf_counter() - t0,
                "estimates": [float(v) for v in e],
                "upper_bounds": edge,
                "truth": truth.value,
            }
        )
        r = rows[-1]
        print(
            f"{name:<26} {r['target']:<16} {r['hours']:8.3g} h  sd planned {sd_planned:.4f} "
            f"realised {sd:.4f}  within {100 * r['within']:.1f} %  ({r['seconds']:.0f} s)",
            file=sys.stderr,
        )
    return rows


def markdown(rows: list[dict], reps: int) -> str:
    head = (
        "| sensor model | target (95 %) | planned length | sd of log estimate: planned | "
        "realised [95 % band] | mean bias | share within target [Wilson 95 %] |\n"
        "|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        b0, b1 = r["sd_band"]
        w0, w1 = r["within_band"]
        h = r["hours"]
        length = f"{h:.3g} h" if h >= 1 else f"{60 * h:.3g} min"
        lines.append(
            f"| {r['model']} | {r['target']} | {length} ({r['samples']:,} samples) | "
            f"{r['sd_planned']:.4f} | {r['sd_realised']:.4f} [{b0:.4f}, {b1:.4f}] | "
            f"{r['bias_pct']:+.2f} % | {100 * r['within']:.1f} % [{100 * w0:.1f}, "
            f"{100 * w1:.1f}] |"
        )
    return "\n".join(lines) + f"\n\n{reps} logs per row (tests/benchmarks/plan_mc.py)."


def rules_table() -> str:
    """docs/planning.md's table: the rule '100 tau_c' (10x a decade past the WN/RW crossing)
    against the plan, for the three sensor models (the tactical gyro at 200 Hz)."""

    def rel(q) -> float:
        return max(q.high / q.value - 1.0, 1.0 - q.low / q.value)

    tact = eg.inference.parse_datasheet("arw=0.01 deg/sqrt(h), rrw=0.1 deg/h/sqrt(h)")
    models = [("tactical gyro (WN+RW)", tact.model(200.0, "deg/s"), 200.0, "deg/s")]
    if (DATA / "adis16405_imu1.h5").exists():
        log = eg.load_log(DATA / "adis16405_imu1.h5")
        models.append(
            ("ADIS16405 gyro_x", adis_model(log.wavelet_variance("gyro_x")), 100.0, "deg/s")
        )
    models.append(("low-cost MEMS gyro (GM+WN+RW)", settings()[2][1], 100.0, "rad/s"))
    lines = [
        "| sensor | N | K | tau_c | 100 tau_c | K at 100 tau_c | B at 100 tau_c | "
        "K within 30 % needs | K within 10 % needs | K at 20 min |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, m, fs, unit in models:
        t = plan_precision(m, fs, 2**20, unit=unit)
        tau_c = math.sqrt(3) * t["N"].native / t["K"].native
        at = plan_precision(m, fs, int(100 * tau_c * fs), unit=unit)
        k20 = rel(plan_precision(m, fs, int(1200 * fs), unit=unit)["K"])
        need = [plan_run(m, fs, f"K within {r} %", unit=unit).required["K"] for r in (30, 10)]
        hours = [f"{n / fs / 3600:.3g} h" if n else "-" for n in need]
        lines.append(
            f"| {name} | {t['N'].datasheet_value:.3g} {t['N'].datasheet_unit} | "
            f"{t['K'].datasheet_value:.3g} {t['K'].datasheet_unit} | {tau_c:.0f} s | "
            f"{100 * tau_c / 3600:.3g} h | +-{100 * rel(at['K']):.0f} % | "
            f"+-{100 * rel(at['B']):.0f} % | {hours[0]} | {hours[1]} | "
            + (f"+-{100 * k20:.0f} % |" if k20 < 100 else "no information |")
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json")
    ap.add_argument("--rules", action="store_true", help="print the rules-of-thumb table only")
    ap.add_argument(
        "--only",
        default="",
        help="run only the rows whose 'model target' has this (or one of A|B|...)",
    )
    a = ap.parse_args()
    if a.rules:
        print(rules_table())
        return
    rows = run(a.reps, a.seed, a.only)
    print(markdown(rows, a.reps))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
