"""Why the recorded-signal filter benchmark misses its 5 % criterion (issue 28; docs/filters.md).

    python tests/benchmarks/filter_recorded_analysis.py kurtosis
    python tests/benchmarks/filter_recorded_analysis.py cells accel 10 1
    python tests/benchmarks/filter_recorded_analysis.py cells gyro 100
    python tests/benchmarks/filter_recorded_analysis.py quantiles
    python tests/benchmarks/filter_recorded_analysis.py own gyro 100
    python tests/benchmarks/filter_recorded_analysis.py horizon accel 10 2*GM+WN+RW
    python tests/benchmarks/filter_recorded_analysis.py checkcut gyro 100

``quantiles``: per ADIS16405 unit and channel, the ratio of the 0.95 and 0.99 quantiles of the
absolute Haar coefficients at each scale 2^j (j = 1..15) to the Gaussian's (1.96 and 2.576 times
their root mean square), point estimates: where the tails are heavier than Gaussian.

``kurtosis``: per ADIS16405 unit and channel (each minus its whole-log mean), the kurtosis of the
differences of consecutive 1 s and 10 s block means (3.0 for Gaussian errors; a simulated WN+RW
for reference): how Gaussian the error is at the scale of the aiding interval.

``cells KIND T_FIX ...``: the one-axis filter of ``tests/filtersim.py`` with unit 1's
WN+RW export (per axis, 100 Hz), on the recorded segments of 20 min (as
``bench_filter.py --recorded``), split by unit, by axis, without unit 4 (its bursts at samples
11,710-11,900, 404,530-404,640 and 514,580-514,690), and with other exports of the same fits
(``data="estimate"``, ``data="high"``, the horizon equal to the aiding interval) and with the
tail factors of :mod:`engine.formats.tails` at the levels 0.99, 0.995 and 0.999 (the "default"
rows are the data bound alone, the export before the tail factors). Per cell: the
segment count M, the mean NEES, the fractions of epochs below / above the 95 % band
``chi2_M / M`` and the variance of the segment-averaged NEES over epochs divided by the ``2 / M``
it has when the M segments are independent and the filter consistent ("var ratio": 1 for a
consistent filter on Gaussian errors; above 1, the band is too narrow for these errors).

``own KIND T_FIX``: each unit's **own** default export on its own signal (as
``bench_filter.py --recorded --own``: the whole 167 min log as one segment per axis, seed 1 +
unit), fixes every ``T_FIX`` s, for the WN+RW and GM+WN+RW fits: per unit and pooled, when in
the log the pooled units 2-6 exceed the band (the first 1000 s against the rest), without unit
4, without the fix intervals of its bursts, with the filter started after the first 1000 s
(files of the whole log, and files fitted again on the log from there), with the bound's
horizon equal to the aiding interval, and the same filter on errors simulated from each file's
own WN+RW (the control, split the same way). Then the bias wander: per unit, the RMS of the
differences of consecutive 100 s means in the first 1000 s and after, with the F test's
p-value.

``checkcut KIND T_FIX``: as ``own``, but each unit's log cut where its log check proposes
(``qualify_log(...).suggested_start`` of the triad: the warm-up wander, 0 where nothing is
found), as a user following the check's advice with ``--drop-warmup`` does: the files fitted
on the cut log and the filter started at the cut, on the same number of samples per unit (the
shortest cut log's), for the WN+RW and GM+WN+RW fits.

``horizon KIND T_FIX MODEL``: unit 1's default export of ``MODEL`` (per axis, 100 Hz) with the
bound's horizon the log (the default) and 1, 2, 4 and 10 aiding intervals, with and without
the tail factors, on the 20 min segments of unit 1 and of units 2-6 (as
``bench_filter.py --recorded``, seed 1 + unit): the file's N and K per axis, the mean NEES and
the fraction of epochs above the 95 % band with its standard error.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import kurtosis

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from conftest import real_data_dir  # noqa: E402
from filtersim import FilterNoise, block_fraction, nees_band, run_recorded  # noqa: E402

import engine as eg  # noqa: E402
from engine.formats.tails import quantile_factor, tail_factors  # noqa: E402

FS, SEG = 100.0, 120_000  # 20 min at 100 Hz
CHANNELS = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")


def _logs() -> list[eg.ImuLog]:
    return [eg.load_log(real_data_dir() / f"adis16405_imu{i}.h5") for i in range(1, 7)]


def kurtosis_table() -> None:
    print("| unit | " + " | ".join(f"{c} 1 s | {c} 10 s" for c in CHANNELS) + " |")
    print("|---" * (1 + 2 * len(CHANNELS)) + "|")
    for i, log in enumerate(_logs(), 1):
        row = []
        for ch in CHANNELS:
            x = np.asarray(log[ch], float)
            x = x - x.mean()
            for b in (100, 1000):
                m = x[: x.size // b * b].reshape(-1, b).mean(axis=1)
                row.append(f"{kurtosis(np.diff(m), fisher=False):.1f}")
        print(f"| {i} | " + " | ".join(row) + " |")
    x = eg.parse_model("WN(1e-4)+RW(1e-12)").simulate(10**6, rng=np.random.default_rng(0))
    ref = [
        kurtosis(np.diff(x[: x.size // b * b].reshape(-1, b).mean(axis=1)), fisher=False)
        for b in (100, 1000)
    ]
    print(f"simulated WN+RW (10^6 samples): {ref[0]:.2f} (1 s), {ref[1]:.2f} (10 s)")


def cells(kind: str, fixes: list[float]) -> None:
    t0 = time.process_time()
    logs = _logs()
    chans = tuple(f"{kind}_{a}" for a in "xyz")
    fix_sigma = 1e-3 if kind == "accel" else 0.01  # g s, deg (bench_filter.py)
    segs = {}
    for u, log in enumerate(logs):
        for ch in chans:
            x = np.asarray(log[ch], float)
            x = x - x.mean()  # the turn-on bias, removed as a calibration would
            k = x.size // SEG
            segs[(u, ch)] = x[: k * SEG].reshape(k, SEG)
    first = np.concatenate([s[:, :1000].mean(axis=1) for s in segs.values()])
    pb0 = float(np.mean(first**2))
    fits = {ch: eg.fit_gmwm(logs[0].wavelet_variance(ch), "WN+RW") for ch in chans}

    def noise_of(level: float | None = None, **kw: Any) -> dict[str, FilterNoise]:
        out = {}
        for ch in chans:
            tails = None if level is None else tail_factors(logs[0][ch], fs=FS, level=level)
            p = eg.formats.project(
                fits[ch], "WN+RW", fs_filter=FS, unit="", ci=None, tails=tails, **kw
            )
            out[ch] = FilterNoise(p.value("N"), p.value("K"), ch)
        return out

    def cell(noise: dict[str, FilterNoise], us: list[int], chs: tuple[str, ...], t_fix: float):
        parts = []
        for u in us:
            for ch in chs:
                r = run_recorded(
                    segs[(u, ch)],
                    noise[ch],
                    fs=FS,
                    hold=1,
                    t_fix_s=t_fix,
                    fix_sigma=fix_sigma,
                    pb0=pb0,
                    seed=u,
                )
                parts.append((r.segments, r.nees))
        m = sum(k for k, _ in parts)
        nees = sum(k * v for k, v in parts) / m
        lo, hi = nees_band(1, m)
        return (
            f"| {m} | {nees.mean():.3f} | {100 * np.mean(nees < lo):.1f} / "
            f"{100 * np.mean(nees > hi):.1f} % | {nees.var() / (2 / m):.2f} |"
        )

    base = noise_of()
    others = [1, 2, 3, 4, 5]
    print("| sensor | T_fix s | export | errors from | M | mean NEES | below / above | var ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for t_fix in fixes:
        rows = [
            ("default", "unit 1 (calibrated)", base, [0], chans),
            ("default", "units 2-6", base, others, chans),
            ("default", "units 2, 3, 5, 6 (not 4)", base, [1, 2, 4, 5], chans),
            ("default", "unit 4 alone", base, [3], chans),
        ]
        rows += [("default", f"units 2-6, {ch} alone", base, others, (ch,)) for ch in chans]
        rows += [("default", f"unit {u + 1}", base, [u], chans) for u in range(6)]
        rows += [
            (f"horizon {t_fix:g} s", "units 2-6", noise_of(horizon_s=t_fix), others, chans),
            ("data=estimate", "units 2-6", noise_of(data="estimate"), others, chans),
            ("data=high", "units 2-6", noise_of(data="high"), others, chans),
        ]
        for lev in (0.99, 0.995, 0.999):  # the tail factors' level (engine.formats.tails)
            nz = noise_of(level=lev)
            rows += [
                (f"tails {lev:g}", "unit 1 (calibrated)", nz, [0], chans),
                (f"tails {lev:g}", "units 2-6", nz, others, chans),
            ]
        for what, who, nz, us, chs in rows:
            print(f"| {kind} | {t_fix:g} | {what} | {who} " + cell(nz, us, chs, t_fix), flush=True)
    print(f"\nCPU {time.process_time() - t0:.0f} s")


def quantiles_table() -> None:
    print("| unit | channel | j: q95 ratio / q99 ratio ... |")
    print("|---|---|---|")
    for i, log in enumerate(_logs(), 1):
        for ch in CHANNELS:
            cells = []
            for j in range(1, 16):
                ratio95 = quantile_factor(eg.wv.haar_coefficients(log[ch], j), 0.95, None)[0]
                ratio99 = quantile_factor(eg.wv.haar_coefficients(log[ch], j), 0.99, None)[0]
                cells.append(f"{j}: {ratio95:.2f} / {ratio99:.2f}")
            print(f"| {i} | {ch} | " + ", ".join(cells) + " |")


#: unit 4's bursts (samples; docs/filters.md): the fix intervals they fall in are left out by
#: the "not the bursts" rows of ``own``
BURSTS_4 = ((11_710, 11_900), (404_530, 404_640), (514_580, 514_690))


def own(kind: str, t_fix: float, skip_s: float = 1000.0) -> None:
    """The ``own`` tables (module docstring)."""
    from scipy.stats import f as f_dist

    sys.path.insert(0, str(REPO / "tests" / "benchmarks"))
    from bench_filter import CHANNELS as FIX
    from bench_filter import bias_prior
    from filter_fleet_spread import unit_exports

    t0 = time.process_time()
    logs = _logs()
    n_log = min(int(log.n) for log in logs)
    chans = tuple(f"{kind}_{a}" for a in "xyz")
    fix_sigma = FIX[f"{kind}_x"][0]
    m = int(round(t_fix * FS))
    k_skip = int(round(skip_s / t_fix))  # fix intervals in the first skip_s
    raw = {
        (u, ch): np.asarray(log[ch], float)[:n_log] for u, log in enumerate(logs) for ch in chans
    }
    errs = {k: x - x.mean() for k, x in raw.items()}  # the turn-on bias removed
    pb0 = bias_prior([e[None, :] for e in errs.values()], int(1200 * FS), FS)
    cut = int(round(skip_s * FS))
    errs_cut = {k: x[cut:] - x[cut:].mean() for k, x in raw.items()}

    def run(e: np.ndarray, nz: FilterNoise, u: int) -> np.ndarray:
        return run_recorded(
            e[None, :], nz, fs=FS, hold=1, t_fix_s=t_fix, fix_sigma=fix_sigma, pb0=pb0, seed=1 + u
        ).nees

    def judge(nees: dict, us: list[int], drop: frozenset[int] = frozenset()) -> tuple:
        """Pooled mean NEES, fraction above the band ± s.e. over the kept fix intervals, and
        the per-interval fractions."""
        v = np.mean([nees[(u, ch)] for u in us for ch in chans], axis=0)
        hi = nees_band(1, len(us) * len(chans))[1]
        f = (v > hi)[1:]
        nb = f.size // m
        per = f[: nb * m].reshape(nb, m).mean(axis=1)
        keep = np.array([i not in drop for i in range(nb)])
        p = per[keep]
        return float(v.mean()), float(p.mean()), float(p.std(ddof=1) / np.sqrt(p.size)), per

    def cell(label: str, who: str, nees: dict, us: list[int], drop=frozenset()) -> str:
        mean, frac, se, _ = judge(nees, us, drop)
        ok = "yes" if 0.5 <= mean <= 1.3 and frac <= 0.05 else "NO"
        return f"| {label} | {who} | {mean:.3f} | {100 * frac:.1f} ± {100 * se:.1f} % | {ok} |"

    burst_iv = frozenset(i for a, b in BURSTS_4 for i in range((a - 1) // m, (b - 1) // m + 2))
    others = [1, 2, 3, 4, 5]
    for model in ("WN+RW", "GM+WN+RW"):
        ex = unit_exports(logs, chans, model)
        nees = {(u, ch): run(errs[(u, ch)], ex[(u, ch)], u) for u in range(6) for ch in chans}
        print(f"\n## {kind}, {model}, each unit's own file, fixes every {t_fix:g} s\n")
        print("| case | errors from | mean NEES | above band ± s.e. | criterion met |")
        print("|---|---|---|---|---|")
        print(cell("whole log", "unit 1", nees, [0]))
        print(cell("whole log", "units 2-6", nees, others))
        for u in range(6):
            print(cell("whole log", f"unit {u + 1} alone", nees, [u]))
        print(cell("whole log", "units 2, 3, 5, 6 (not 4)", nees, [1, 2, 4, 5]))
        print(cell("whole log, not unit 4's burst intervals", "units 2-6", nees, others, burst_iv))
        _, _, _, per = judge(nees, others)
        first = per[:k_skip].mean()
        rest = per[k_skip:].mean()
        share = per[:k_skip].sum() / per.sum()
        print(
            cell(
                f"whole log, first {skip_s:g} s only",
                "units 2-6",
                nees,
                others,
                frozenset(range(k_skip, per.size)),
            )  # fmt: skip
        )
        print(cell(f"whole log, after {skip_s:g} s only", "units 2-6", nees, others,
                   frozenset(range(k_skip))))  # fmt: skip
        later = {k: run(errs_cut[k], ex[k], k[0]) for k in nees}
        print(cell(f"filter started at {skip_s:g} s, files of the whole log", "unit 1", later, [0]))
        print(cell(f"filter started at {skip_s:g} s, files of the whole log", "units 2-6",
                   later, others))  # fmt: skip
        cut_logs = [
            eg.ImuLog({ch: raw[(u, ch)][cut:] for ch in chans}, FS, units=dict(logs[u].units))
            for u in range(6)
        ]
        ex_cut = unit_exports(cut_logs, chans, model)
        refit = {k: run(errs_cut[k], ex_cut[k], k[0]) for k in nees}
        print(cell(f"filter started at {skip_s:g} s, files fitted from there", "unit 1",
                   refit, [0]))  # fmt: skip
        print(cell(f"filter started at {skip_s:g} s, files fitted from there", "units 2-6",
                   refit, others))  # fmt: skip
        hz = {}
        for u, log in enumerate(logs):
            for ch in chans:
                fit = eg.fit_gmwm(log.wavelet_variance(ch), model)
                p = eg.formats.project(fit, "WN+RW", unit="", ci=None, horizon_s=t_fix,
                               tails=tail_factors(log[ch], fs=FS, channel=ch))  # fmt: skip
                hz[(u, ch)] = run(errs[(u, ch)], FilterNoise(p.value("N"), p.value("K"), ""), u)
        print(cell(f"horizon {t_fix:g} s (default: the log)", "units 2-6", hz, others))
        rng = np.random.default_rng(7)
        ctrl = {}
        for (u, ch), nz in ex.items():
            sim = eg.Model((eg.WN(sigma2=nz.N**2 * FS), eg.RW(gamma2=nz.K**2 / FS)))
            x = sim.simulate(n_log, rng=rng)
            ctrl[(u, ch)] = run(x - x.mean(), nz, u)
        print(cell("control: each file's own WN+RW simulated", "units 2-6", ctrl, others))
        _, _, _, cper = judge(ctrl, others)
        print(
            f"\nunits 2-6: above the band in the first {skip_s:g} s ({k_skip} fix intervals) "
            f"{100 * first:.1f} %, after it {100 * rest:.1f} % ({100 * share:.0f} % of all the "
            f"epochs above); control {100 * cper[:k_skip].mean():.1f} % and "
            f"{100 * cper[k_skip:].mean():.1f} %; unit 4's burst intervals: "
            f"{sorted(burst_iv)}"
        )
    # the bias wander: consecutive 100 s means
    b = int(100 * FS)
    k10 = int(skip_s * FS) // b
    print(f"\n## {kind}: RMS of the differences of consecutive 100 s means, first {skip_s:g} s "
          "against the rest (log units; the three axes pooled)\n")  # fmt: skip
    print("| unit | first | rest | variance ratio | F test p (one-sided) |")
    print("|---|---|---|---|---|")
    pooled = [[], []]
    for u in range(6):
        d = [np.diff(raw[(u, ch)][: n_log // b * b].reshape(-1, b).mean(axis=1)) for ch in chans]
        a = np.concatenate([x[: k10 - 1] for x in d])
        r = np.concatenate([x[k10 - 1 :] for x in d])
        if u:
            pooled[0].append(a)
            pooled[1].append(r)
        va, vr = float(np.mean(a**2)), float(np.mean(r**2))
        p = float(f_dist.sf(va / vr, a.size, r.size))
        print(f"| {u + 1} | {va**0.5:.3g} | {vr**0.5:.3g} | {va / vr:.2f} | {p:.2g} |")
    a, r = np.concatenate(pooled[0]), np.concatenate(pooled[1])
    va, vr = float(np.mean(a**2)), float(np.mean(r**2))
    p = float(f_dist.sf(va / vr, a.size, r.size))
    print(f"| 2-6 | {va**0.5:.3g} | {vr**0.5:.3g} | {va / vr:.2f} | {p:.2g} |")
    print(f"\nCPU {time.process_time() - t0:.0f} s")


def check_cut(kind: str, t_fix: float) -> None:
    """The ``checkcut`` table (module docstring)."""
    from engine.io.qualify import qualify_log

    sys.path.insert(0, str(REPO / "tests" / "benchmarks"))
    from bench_filter import CHANNELS as FIX
    from bench_filter import bias_prior
    from filter_fleet_spread import unit_exports

    t0 = time.process_time()
    logs = _logs()
    chans = tuple(f"{kind}_{a}" for a in "xyz")
    fix_sigma = FIX[f"{kind}_x"][0]
    cuts = [qualify_log(log, list(chans)).suggested_start for log in logs]
    keep = min(int(log.n) - c for log, c in zip(logs, cuts, strict=True))
    print(f"{kind}: the log check's cut per unit (s): " + ", ".join(f"{c / FS:g}" for c in cuts))
    print(f"filter on {keep / FS:g} s per unit from its cut\n")
    cut_logs = [
        eg.ImuLog({ch: np.asarray(log[ch], float)[c:] for ch in chans}, FS, units=dict(log.units))
        for log, c in zip(logs, cuts, strict=True)
    ]
    errs = {}
    for u, lg in enumerate(cut_logs):
        for ch in chans:
            x = np.asarray(lg[ch], float)[:keep]
            errs[(u, ch)] = x - x.mean()
    pb0 = bias_prior([e[None, :] for e in errs.values()], int(1200 * FS), FS)
    m = int(round(t_fix * FS))
    print("| model | errors from | mean NEES | above band ± s.e. | criterion met |")
    print("|---|---|---|---|---|")
    for model in ("WN+RW", "GM+WN+RW"):
        ex = unit_exports(cut_logs, chans, model)
        nees = {
            k: run_recorded(e[None, :], ex[k], fs=FS, hold=1, t_fix_s=t_fix,
                            fix_sigma=fix_sigma, pb0=pb0, seed=1 + k[0]).nees
            for k, e in errs.items()
        }  # fmt: skip
        groups = [("unit 1", [0]), ("units 2-6", [1, 2, 3, 4, 5])]
        groups += [(f"unit {u + 1} alone", [u]) for u in range(1, 6)]
        for who, us in groups:
            v = np.mean([nees[(u, ch)] for u in us for ch in chans], axis=0)
            frac, se, _ = block_fraction(v > nees_band(1, len(us) * len(chans))[1], m)
            ok = "yes" if 0.5 <= v.mean() <= 1.3 and frac <= 0.05 else "NO"
            print(f"| {model} | {who} | {v.mean():.3f} | {100 * frac:.1f} ± {100 * se:.1f} % "
                  f"| {ok} |", flush=True)  # fmt: skip
    print(f"\nCPU {time.process_time() - t0:.0f} s")


def horizon(kind: str, t_fix: float, model: str) -> None:
    """The ``horizon`` table (module docstring)."""
    sys.path.insert(0, str(REPO / "tests" / "benchmarks"))
    from bench_filter import CHANNELS as FIX
    from bench_filter import bias_prior

    t0 = time.process_time()
    logs = _logs()
    chans = tuple(f"{kind}_{a}" for a in "xyz")
    fix_sigma = FIX[f"{kind}_x"][0]
    errs = {}
    for u, log in enumerate(logs):
        for ch in chans:
            x = np.asarray(log[ch], float)
            k = x.size // SEG
            errs[(u, ch)] = (x - x.mean())[: k * SEG].reshape(k, SEG)
    pb0 = bias_prior(list(errs.values()), SEG, FS)
    fits = {ch: eg.fit_gmwm(logs[0].wavelet_variance(ch), model) for ch in chans}
    tails = {ch: tail_factors(logs[0][ch], fs=FS, channel=ch) for ch in chans}
    print(f"{kind}, {model} fitted to unit 1, fixes every {t_fix:g} s\n")
    print("| horizon | tail factors | N x, y, z | K x, y, z | unit 1: mean NEES, above ± s.e. "
          "| units 2-6: mean NEES, above ± s.e. |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for h in (None, t_fix, 2 * t_fix, 4 * t_fix, 10 * t_fix):
        for tl in (True, False):
            nz = {}
            for ch in chans:
                p = eg.formats.project(fits[ch], "WN+RW", fs_filter=FS, unit="", ci=None,
                               tails=tails[ch] if tl else None, horizon_s=h)  # fmt: skip
                nz[ch] = FilterNoise(p.value("N"), p.value("K"), ch)
            cells = []
            for us in ([0], [1, 2, 3, 4, 5]):
                parts = []
                for u in us:
                    for ch in chans:
                        r = run_recorded(errs[(u, ch)], nz[ch], fs=FS, hold=1, t_fix_s=t_fix,
                                         fix_sigma=fix_sigma, pb0=pb0, seed=1 + u)  # fmt: skip
                        parts.append((r.segments, r.nees))
                m = sum(k for k, _ in parts)
                v = sum(k * x for k, x in parts) / m
                frac, se, _ = block_fraction(v > nees_band(1, m)[1], int(round(t_fix * FS)))
                cells.append(f"{v.mean():.3f}, {100 * frac:.1f} ± {100 * se:.1f} %")
            print(
                f"| {'the log' if h is None else f'{h:g} s'} | {'yes' if tl else 'no'} | "
                + ", ".join(f"{nz[c].N:.2e}" for c in chans) + " | "
                + ", ".join(f"{nz[c].K:.2e}" for c in chans) + " | " + " | ".join(cells) + " |",
                flush=True,
            )  # fmt: skip
    print(f"\nCPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    if sys.argv[1:2] == ["kurtosis"]:
        kurtosis_table()
    elif sys.argv[1:2] == ["quantiles"]:
        quantiles_table()
    elif sys.argv[1:2] == ["horizon"] and len(sys.argv) == 5:
        horizon(sys.argv[2], float(sys.argv[3]), sys.argv[4])
    elif sys.argv[1:2] == ["checkcut"] and len(sys.argv) == 4:
        check_cut(sys.argv[2], float(sys.argv[3]))
    elif sys.argv[1:2] == ["own"] and len(sys.argv) == 4:
        own(sys.argv[2], float(sys.argv[3]))
    elif sys.argv[1:2] == ["cells"] and len(sys.argv) >= 4:
        cells(sys.argv[2], [float(v) for v in sys.argv[3:]])
    else:
        sys.exit(__doc__)
