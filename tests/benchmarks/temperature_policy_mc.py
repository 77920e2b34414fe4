"""Monte Carlo of ``temperature="auto"``'s rule (engine.inference.temperature): compensate
only when the joint Wald test that every temperature coefficient is 0 rejects at 5 %.

R simulated gyro logs per case (2e5 samples at 100 Hz, 33 min) of WN (sigma2 1e-4 (deg/s)^2)
+ RW (gamma2 1e-10 (deg/s)^2) plus ``c`` times the temperature:

- ``zero, slow ramp``: c = 0, the temperature barely moves (30.1 to 30.6 degC, a 900 s
  approach, 0.01 degC of sensor noise): the false-compensation rate, which should be the
  test's level, 5 %;
- ``zero, warm-up``: c = 0 under the warm-up profile of ``temperature_mc.py`` (25 to 35 degC,
  300 s time constant, a 2 degC cycle of 600 s);
- ``zero, segments``: c = 0, the warm-up profile, three still segments with their own bias
  offsets (``temperature_mc.py --segments``'s layout);
- ``7.2, warm-up`` and ``0.72, warm-up``: c = 2e-3 and 2e-4 deg/s per degC (7.2 and 0.72
  deg/h per degC): the detection rate.

Each log is fitted once with the channel named (``compensate=True``, WN+RW on the slow ramp
only): the rule's decision is its p-value below 0.05 (what ``compensate="auto"`` applies,
``tests/engine/test_temperature_compensation.py`` checks the two agree); on the slow ramp the
RW of the fit the rule keeps is set beside that of compensating always.

Usage::

    nice python tests/benchmarks/temperature_policy_mc.py [--reps 300]

Prints a Markdown table (docs/qualify.md, section Temperature, holds its output).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from temperature_mc import FS, SEGMENTS, C, N, band  # the thermal logs of temperature_mc.py

import engine as eg
from engine.inference.temperature import fit_temperature


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    t = np.arange(N) / FS
    warm = 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sin(2 * np.pi * t / 600)
    model = eg.parse_model("WN(sigma2=1e-4)+RW(gamma2=1e-10)")
    cases = [
        ("0, slow ramp 30.1-30.6 degC", 0.0, "ramp", ()),
        ("0, warm-up 25-37 degC", 0.0, "warm", ()),
        ("0, warm-up, 3 still segments", 0.0, "warm", SEGMENTS),
        ("7.2, warm-up 25-37 degC", C, "warm", ()),
        ("0.72, warm-up 25-37 degC", C / 10, "warm", ()),
    ]
    print(f"{args.reps} logs per case, seed {args.seed}\n")
    print(
        "| true sensitivity (deg/h per degC), temperature | compensated by `auto`, % "
        "[Clopper-Pearson 95 %] | median sensitivity [median interval] |"
    )
    print("|---|---|---|")
    rw_note = ""
    t0 = time.process_time()
    for k, (label, c, kind, segs) in enumerate(cases):
        hits, sens, los, his, rw_auto, rw_named = 0, [], [], [], [], []
        for r in range(args.reps):
            seed = [args.seed, k, r]
            gen = np.random.default_rng(seed)
            if kind == "ramp":
                temp = 30.1 + 0.5 * (1 - np.exp(-t / 900)) + gen.normal(0.0, 0.01, N)
            else:
                temp = warm
            y = model.simulate(N, fs=FS, rng=gen) + c * temp
            for a, b in segs:
                y[a:b] += gen.normal(0.0, 0.05)
            tf = fit_temperature(
                y,
                temp,
                fs=FS,
                unit="deg/s",
                segments=segs,
                model="WN+RW" if kind == "ramp" else None,
            )
            auto = tf.p_value < 1 - tf.level
            hits += auto
            sens.append(tf.sensitivity)
            los.append(tf.sensitivity_interval[0])
            his.append(tf.sensitivity_interval[1])
            if tf.fit is not None and tf.fit_raw is not None:
                rw_named.append(tf.fit.params["RW.gamma2"])
                rw_auto.append((tf.fit if auto else tf.fit_raw).params["RW.gamma2"])
        print(
            f"| {label} | {band(hits, args.reps)} | {np.median(sens):.3g} "
            f"[{np.median(los):.3g}, {np.median(his):.3g}] |"
        )
        if rw_auto:
            ra, rn = np.array(rw_auto), np.array(rw_named)
            rw_note = (
                f"slow ramp, RW.gamma2 (truth 1e-10 (deg/s)^2): with `auto` median "
                f"{np.median(ra):.3g}, mean {np.mean(ra):.3g}; compensated always median "
                f"{np.median(rn):.3g}, mean {np.mean(rn):.3g}; "
                f"always / auto, median ratio {np.median(rn / ra):.3g}, 90th percentile "
                f"{np.quantile(rn / ra, 0.9):.3g}"
            )
    print(f"\n{rw_note}\nCPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()
