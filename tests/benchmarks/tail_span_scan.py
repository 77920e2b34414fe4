"""Where the tail factors belong: the span below the horizon, the default horizon, and what
no WN+RW file of unit 1 can do at 100 s (docs/filters.md, "The tails' span").

    python tests/benchmarks/tail_span_scan.py span [--kinds accel]
    python tests/benchmarks/tail_span_scan.py defaults [--kinds gyro accel] [--horizons 40 100 0]
    python tests/benchmarks/tail_span_scan.py scale

The cells are those of ``bench_filter.py --recorded --control-runs 0`` (the same filter,
segments, fixes, bias prior and seeds; unit 1's WN+RW, GM+WN+RW and 2*GM+WN+RW fits of each
axis, exported at 100 Hz with the data bound and the tail factors; fixes every 1, 10 and 100
s; on unit 1 and on units 2-6), counted against the criterion (mean NEES in [0.5, 1.3], at
most 5 % of epochs above the band).

``span``: the horizon 4 aiding intervals, the tail factors at the scales ``H / k .. H`` for
k = 2, 4 (``engine.formats.tails.TAIL_SPAN``), 8, 16 and on the whole band (the code before),
and none. ``defaults``: one horizon for every aiding interval (``--horizons``, s; 0: none
given, the log length with the factors on the whole band, the default). ``scale``: fixes every
100 s, the file of the horizon 400 s times ``a`` on N and ``b`` on K, on unit 1 and units 2-6.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "tests" / "benchmarks"))

import numpy as np  # noqa: E402
from bench_filter import CHANNELS, KINDS, _segments, bias_prior  # noqa: E402
from conftest import real_data_dir  # noqa: E402
from filtersim import FilterNoise, block_fraction, nees_band, run_recorded  # noqa: E402

import engine as eg  # noqa: E402
import engine.formats.tails as tails_mod  # noqa: E402
from engine.formats.tails import TailFactors, tail_factors  # noqa: E402

FS = 100.0
MODELS = ("WN+RW", "GM+WN+RW", "2*GM+WN+RW")
GROUPS = (("unit 1", (0,)), ("units 2-6", (1, 2, 3, 4, 5)))


class Kind:
    """One sensor kind's recorded errors, unit 1's fits and tail factors."""

    def __init__(self, kind: str, logs: list) -> None:
        self.chans = KINDS[kind]
        self.fix_sigma = CHANNELS[f"{kind}_x"][0]
        self.n_log = min(int(lg.n) for lg in logs)
        self.errs = {
            (u, ch): np.asarray(lg[ch], float) - float(np.mean(lg[ch]))
            for u, lg in enumerate(logs)
            for ch in self.chans
        }
        self.pb0 = bias_prior(list(self.errs.values()), int(20 * 60 * FS), FS)
        self.tails = {ch: tail_factors(logs[0][ch], fs=FS, channel=ch) for ch in self.chans}
        self.fits = {
            (m, ch): eg.fit_gmwm(logs[0].wavelet_variance(ch), m)
            for m in MODELS
            for ch in self.chans
        }

    def noise(self, model: str, horizon: float | None, tails: dict) -> dict:
        out = {}
        for ch in self.chans:
            p = eg.formats.project(
                self.fits[(model, ch)], "WN+RW", fs_filter=FS, unit="", ci=None,
                tails=tails.get(ch), horizon_s=horizon,
            )  # fmt: skip
            out[ch] = (p.value("N"), p.value("K"))
        return out

    def cell(self, t_fix: float, noise: dict) -> list[tuple[float, float, float]]:
        """Per group (unit 1, units 2-6): mean NEES, fraction above the band, its s.e."""
        seg = min(max(int(20 * 60 * FS), int(round(100 * t_fix * FS))), self.n_log)
        out = []
        for _, us in GROUPS:
            parts = []
            for u in us:
                for ch in self.chans:
                    r = run_recorded(
                        _segments(self.errs[(u, ch)], seg),
                        FilterNoise(*noise[ch]),
                        fs=FS,
                        hold=1,
                        t_fix_s=t_fix,
                        fix_sigma=self.fix_sigma,
                        pb0=self.pb0,
                        seed=1 + u,
                    )
                    parts.append((r.segments, r.nees))
            n_seg = sum(m for m, _ in parts)
            nees = sum(m * v for m, v in parts) / n_seg
            hi = nees_band(1, n_seg)[1]
            above, se, _ = block_fraction(nees > hi, int(round(t_fix * FS)))
            out.append((float(nees.mean()), above, se))
        return out


def met(r: tuple[float, float, float]) -> bool:
    return 0.5 <= r[0] <= 1.3 and r[1] <= 0.05


def fmt(r: tuple[float, float, float]) -> str:
    return f"{r[0]:.3f}, {100 * r[1]:.1f} ± {100 * r[2]:.1f} %"


def restricted(tf: TailFactors, lo_s: float, hi_s: float) -> TailFactors:
    t = tf.tau_samples / tf.fs
    keep = (t >= lo_s * (1 - 1e-9)) & (t <= hi_s * (1 + 1e-9))
    return dataclasses.replace(tf, factor=np.where(keep, tf.factor, 1.0))


def table(kind: Kind, name: str, horizon, tails_of) -> int:
    """Print one variant's 18 cells; return how many meet the criterion."""
    n_ok = 0
    for model in MODELS:
        for t_fix in (1.0, 10.0, 100.0):
            h = horizon(t_fix)
            r = kind.cell(t_fix, kind.noise(model, h, tails_of(h)))
            n_ok += sum(met(x) for x in r)
            print(
                f"| {name} | {model} | {t_fix:g} | "
                + " | ".join(f"{fmt(x)}{'' if met(x) else ' (NO)'}" for x in r)
                + " |",
                flush=True,
            )
    return n_ok


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["span", "defaults", "scale"])
    ap.add_argument("--kinds", nargs="+", default=None, choices=list(KINDS))
    ap.add_argument("--horizons", nargs="+", type=float, default=[40.0, 100.0, 400.0, 1000.0, 0.0])
    args = ap.parse_args()
    data = real_data_dir()
    logs = [eg.load_log(data / f"adis16405_imu{i}.h5") for i in range(1, 7)]
    c0 = time.process_time()
    counts = []
    if args.what == "scale":
        kind = Kind("accel", logs)
        base = kind.noise("WN+RW", 400.0, kind.tails)
        print("| N x | K x | unit 1: mean NEES, above ± s.e. | units 2-6 | met |")
        print("|---|---|---|---|---|")
        for a in (1.0, 1.3, 1.7, 2.2):
            for b in (1.0, 1.1, 1.2, 1.3, 1.45, 1.6, 1.8):
                nz = {ch: (a * n, b * k) for ch, (n, k) in base.items()}
                r = kind.cell(100.0, nz)
                ok = "/".join("yes" if met(x) else "NO" for x in r)
                print(f"| {a:g} | {b:g} | {fmt(r[0])} | {fmt(r[1])} | {ok} |", flush=True)
    for kname in args.kinds or (["accel"] if args.what == "span" else list(KINDS)):
        if args.what == "scale":
            break
        kind = Kind(kname, logs)
        print(f"\n{kname}\n\n| variant | model | T_fix s | unit 1 | units 2-6 |")
        print("|---|---|---|---|---|")
        if args.what == "span":
            # the engine's own span off (its restriction covers the whole band), the
            # variant's applied to the factors themselves
            tails_mod.TAIL_SPAN = math.inf
            for k in (2.0, 4.0, 8.0, 16.0):
                tabs = {
                    h: {c: restricted(tf, h / k, h) for c, tf in kind.tails.items()}
                    for h in (4.0, 40.0, 400.0)
                }
                n = table(kind, f"H = 4 T, factors at H/{k:g} .. H", lambda t: 4 * t, tabs.get)
                counts.append((f"k = {k:g}", n))
            n = table(kind, "H = 4 T, factors on the whole band", lambda t: 4 * t,
                      lambda h, tf=kind.tails: tf)  # fmt: skip
            counts.append(("whole band", n))
            n = table(kind, "H = 4 T, no factors", lambda t: 4 * t, lambda h: {})
            counts.append(("none", n))
            tails_mod.TAIL_SPAN = 4.0
        else:
            for h0 in [h or None for h in args.horizons]:
                name = "no horizon (the log)" if h0 is None else f"H = {h0:g} s"
                n = table(kind, name, lambda t, h0=h0: h0, lambda h, tf=kind.tails: tf)
                counts.append((f"{kname}, {name}", n))
    for name, n in counts:
        print(f"{name}: {n} of 18 cells meet the criterion")
    print(f"\n{time.process_time() - c0:.0f} s of CPU")


if __name__ == "__main__":
    main()
