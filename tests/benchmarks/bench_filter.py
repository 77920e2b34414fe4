"""Proof in a filter: are exported noise numbers consistent in a Kalman filter?

    python tests/benchmarks/bench_filter.py [--runs 100] [--minutes 20] [--fix 1 10 100]
    python tests/benchmarks/bench_filter.py --recorded [--minutes 20] [--fix 1 10 100]
        [--rates 100 200] [--models WN+RW GM+WN+RW 2*GM+WN+RW] [--kinds gyro accel]
        [--min-fixes 100] [--control-runs 100] [--no-tails] [--data low|estimate|high|none]
        [--fleet | --own] [--control-runs 0] [--horizon-fixes 4] [--drop-warmup]

``--recorded``: the error fed to the filter is the *recorded* ADIS16405 signal, not
a simulation: the six units' logs (all channels), each channel minus its mean over the whole
log (the turn-on bias, removed as a calibration would), cut into segments of ``--minutes`` or
of ``--min-fixes`` fix intervals, the longer (at most the log: fixes every 100 s take the whole
167 min log as one segment per channel, so that the fraction of epochs above the band is
averaged over 100 nearly independent fix intervals, not 12). The filter's N and K are the
default export (``project(fit, "WN+RW", data=, tails=)``: bound on the fitted WV and the
empirical WV's lower 95 % limit times the tail factors of :mod:`engine.formats.tails`, per
axis; ``--no-tails``: the data bound alone, ``--data``: another data bound) of the fits of unit
1 (the calibrated unit); it runs on unit 1's segments and on units 2-6's (not calibrated).
``--fleet``: a fleet file, per axis the largest N and the largest K of the six units' default
exports, run on every unit; ``--own``: every unit's own default export on its own signal.
A filter rate above
the log's holds each sample (zero-order hold): its NEES at the IMU's epochs equals the log
rate's (same densities, same covariance over one IMU period; the 200 Hz rows of the first table
repeated the 100 Hz ones to the last digit), so ``--rates`` defaults to the log's 100 Hz; a
200 Hz filter on a 200 Hz recording needs a 200 Hz log, which the ADIS16405 data do not have.
Its initial bias variance is the mean square, over the sensor kind's 20 min segments, of the
segments' first-10-s means. Per cell: the mean NEES, the fraction of epochs below the band,
the fraction above with its standard error from the spread over fix intervals
(``filtersim.block_fraction``). Control: the same filter on errors simulated from its own
WN + RW (``--control-runs`` runs as long as the cell's segments), where only the filter is
judged (``--control-runs 0``: none). The last column is the fleet file's criterion (mean NEES
at most 1.3, at most 5 % above: not overconfident; docs/filters.md, "One file for a fleet").

The sensor errors are simulated from the ``2*GM+WN+RW`` model fitted to the real ADIS16405 log
(``adis16405_imu1.h5``: gyro_x in deg/s, accel_x in g; its sub-sample GM and its slow GM), and a
one-axis filter (``tests/filtersim.py``: integral and bias states, 100 Hz, an absolute fix of the
integral every T_fix seconds) is given only N and K:

* (a) the plain conversion of the ``WN+RW`` fit (the Kalibr export's numbers);
* (b) the full fit projected onto WN + RW and over-bounded by the engine's projection
  (``engine.formats.projection.project``, the numbers the filter formats write);
* (c) the folk 10x inflation of (a);
* (a0) for reference, the full fit's own WN and RW terms (N = 0: the exports before issue 23).

Per case and fix interval: the mean NEES of the integral (1 when consistent), the fractions of
epochs whose run-averaged NEES is below / inside / above the 95 % band chi2_M(0.025, 0.975)/M,
and the fraction of (run, epoch) pairs whose error is inside its 2-sigma bound (95.4 % when
consistent); the inflation factors are N/N_a and K/K_a.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

import numpy as np  # noqa: E402
from conftest import real_data_dir  # noqa: E402
from filtersim import (  # noqa: E402
    FilterNoise,
    block_fraction,
    filter_cases,
    nees_band,
    run_monte_carlo,
    run_recorded,
)

import engine as eg  # noqa: E402
from engine.formats.tails import tail_factors  # noqa: E402
from engine.io.qualify import drop_warmup, qualify_log  # noqa: E402

#: channel -> (fix standard deviation in the integral's unit, that unit)
CHANNELS = {"gyro_x": (0.01, "deg"), "accel_x": (1e-3, "g s")}
#: sensor kind -> its three axes
KINDS = {
    "gyro": ("gyro_x", "gyro_y", "gyro_z"),
    "accel": ("accel_x", "accel_y", "accel_z"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", type=Path, default=real_data_dir() / "adis16405_imu1.h5")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--fix", type=float, nargs="+", default=[1.0, 10.0, 100.0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--recorded", action="store_true", help="the recorded errors")
    ap.add_argument("--rates", type=float, nargs="+", default=[100.0])
    ap.add_argument("--models", nargs="+", default=["WN+RW", "GM+WN+RW", "2*GM+WN+RW"])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    ap.add_argument(
        "--min-fixes",
        type=int,
        default=100,
        help="--recorded: segments hold at least this many fix intervals (longer than "
        "--minutes when needed, at most the log)",
    )
    ap.add_argument("--control-runs", type=int, default=100)
    ap.add_argument(
        "--drop-warmup",
        action="store_true",
        help="--recorded: each unit's log cut where its log check proposes for the sensor "
        "triad (engine.io.qualify_log(...).suggested_start, gmwm --drop-warmup): the files "
        "fitted on the cut log and the recorded errors from the cut",
    )
    ap.add_argument(
        "--data",
        default="low",
        choices=["low", "estimate", "high", "none"],
        help="--recorded: the export's data bound (project(..., data=))",
    )
    ap.add_argument(
        "--own",
        action="store_true",
        help="--recorded: every unit's own default export on its own signal (all calibrated)",
    )
    ap.add_argument(
        "--fleet",
        action="store_true",
        help="--recorded: a fleet file, per axis the largest N and K of the six units' exports",
    )
    ap.add_argument(
        "--horizon-fixes",
        type=float,
        default=None,
        help="--recorded: the exports' horizon (gmwm export --horizon) this many fix intervals "
        "(default: the log length, the export's default)",
    )
    ap.add_argument(
        "--tails",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="--recorded: the default export's tail factors (engine.formats.tails.tail_factors "
        "of the exporting unit's channels; --no-tails: the data bound alone, the export before)",
    )
    args = ap.parse_args()
    if args.recorded:
        recorded(args)
        return
    if not args.log.is_file():
        sys.exit(f"bench_filter: no log at {args.log}; give --log PATH (see README, Data)")
    log = eg.load_log(args.log)
    fs = float(log.fs)
    t_all = time.perf_counter()
    print(
        f"{args.log.name}, {args.runs} runs of {args.minutes:g} min at {fs:g} Hz; case (b): "
        "engine projection"
    )
    for ch, (fix_sigma, iunit) in CHANNELS.items():
        fc = filter_cases(log[ch], fs, ch)
        unit = log.units.get(ch, "u")
        a = fc.cases["a"]
        print(f"\n{ch} [{unit}]: truth {fc.truth_fit.model.spec()}")
        for key, p in fc.truth_fit.params.items():
            print(f"    {key:14s} {p:.4g}")
        print(f"  fix every T_fix s, sigma {fix_sigma:g} {iunit}; bound: {fc.bound_info}")
        print(
            "\n| case | N | K | N/N_a | K/K_a | T_fix s | mean NEES | below / in / above band"
            " | in 2 sigma |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for key in ("a", "b", "c", "a0"):
            noise = fc.cases[key]
            fn, fk = noise.factors_over(a)
            for t_fix in args.fix:
                r = run_monte_carlo(
                    fc.truth,
                    noise,
                    fs=fs,
                    duration_s=60.0 * args.minutes,
                    t_fix_s=t_fix,
                    fix_sigma=fix_sigma,
                    runs=args.runs,
                    seed=args.seed,
                )
                lo, inside, hi = r.fractions()
                print(
                    f"| {noise.label} | {noise.N:.3g} | {noise.K:.3g} | {fn:.2f} | {fk:.2f} "
                    f"| {t_fix:g} | {r.mean_nees:.3f} "
                    f"| {100 * lo:.0f} / {100 * inside:.0f} / {100 * hi:.0f} % "
                    f"| {100 * r.in_2sigma:.1f} % |"
                )
        print(f"  (band of the {args.runs}-run average: {r.band[0]:.3f} .. {r.band[1]:.3f})")
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s")


def _segments(x: np.ndarray, seg: int) -> np.ndarray:
    """``x`` cut into whole segments of ``seg`` samples (segments x samples)."""
    k = x.size // seg
    return x[: k * seg].reshape(k, seg)


def bias_prior(errors: list[np.ndarray], seg: int, fs: float) -> float:
    """The filter's initial bias variance: the mean square, over the ``seg``-sample segments
    of every error series (a channel's recording minus its mean), of their first-10-s means."""
    first = np.concatenate(
        [_segments(np.ravel(e), seg)[:, : int(10 * fs)].mean(axis=1) for e in errors]
    )
    return float(np.mean(first**2))


def horizon_of(args: argparse.Namespace, t_fix: float) -> float | None:
    """The exports' horizon (s) for fixes every ``t_fix`` s: ``--horizon-fixes`` intervals, or
    None (the export's default, the log length)."""
    return None if args.horizon_fixes is None else args.horizon_fixes * t_fix


def exports(
    args: argparse.Namespace,
    fits: dict,
    tails: dict,
    src: Any,
    chans: tuple[str, ...],
    n_units: int,
    label: str,
    rate: float,
    horizon_s: float | None,
) -> dict[tuple[int, str], FilterNoise]:
    """Per (unit, axis), the filter's N and K: the default exports of the units ``src`` (the
    largest over them, or with ``--own`` each unit's own), at filter ``rate`` and horizon."""
    proj = {
        (u, ch): eg.formats.project(
            fits[(u, ch)],
            "WN+RW",
            fs_filter=rate,
            unit="",
            ci=None,
            data=args.data,
            tails=tails[(u, ch)],
            horizon_s=horizon_s,
        )
        for u in src
        for ch in chans
    }
    noise = {}
    for ch in chans:
        fleet = FilterNoise(
            max(proj[(u, ch)].value("N") for u in src),
            max(proj[(u, ch)].value("K") for u in src),
            label,
        )
        for u in range(n_units):
            own = proj[(u, ch)] if args.own else None
            noise[(u, ch)] = (
                fleet if own is None else FilterNoise(own.value("N"), own.value("K"), label)
            )
    return noise


def recorded(args: argparse.Namespace) -> None:
    """The ``--recorded`` table (module docstring)."""
    data = args.log.parent
    units = [data / f"adis16405_imu{i}.h5" for i in range(1, 7)]
    if not all(u.is_file() for u in units):
        sys.exit(f"bench_filter: the six ADIS16405 logs are needed in {data}")
    t_all = time.perf_counter()
    c_all = time.process_time()
    logs = logs_all = [eg.load_log(u) for u in units]
    fs = float(logs[0].fs)
    n_log = min(int(log.n) for log in logs)
    seg20 = int(round(60.0 * args.minutes * fs))
    print(
        f"recorded ADIS16405 errors: 6 units at {fs:g} Hz, segments of {args.minutes:g} min or "
        f"{args.min_fixes} fix intervals (the longer, at most the log); noise numbers exported "
        f"from unit 1's fits (default export: bound on the fit and the data's lower 95 % "
        f"limit; data={args.data}, tails: {args.tails}, fleet file: {args.fleet}, horizon: "
        f"{'the log' if args.horizon_fixes is None else f'{args.horizon_fixes:g} fix intervals'}, "
        f"each unit's own file: {args.own})"
    )
    rows = []
    for kind, chans in KINDS.items():
        if kind not in args.kinds:
            continue
        fix_sigma = CHANNELS[f"{kind}_x"][0]
        if args.drop_warmup:  # as gmwm --drop-warmup on this triad: fit and fly from the cut
            cuts = [qualify_log(lg, list(chans)).suggested_start for lg in logs_all]
            logs = [drop_warmup(lg, c) for lg, c in zip(logs_all, cuts, strict=True)]
            n_log = min(int(lg.n) for lg in logs)
            print(f"{kind}: cut at (s) " + ", ".join(f"{c / fs:g}" for c in cuts))
        errs: dict[tuple[int, str], np.ndarray] = {}
        for u, log in enumerate(logs):
            for ch in chans:
                x = np.asarray(log[ch], float)
                errs[(u, ch)] = x - x.mean()  # the turn-on bias, removed as a calibration would
        # the filter's initial bias variance: the sensor kind's, from the 20 min segments
        pb0 = bias_prior(list(errs.values()), seg20, fs)
        # the files' sources: unit 1 (the calibrated unit), or with --fleet every unit (the
        # fleet file: per axis the largest N and the largest K of the six units' exports)
        # with --own each unit's own file (every unit calibrated)
        src = range(len(logs)) if args.fleet or args.own else [0]
        tails = {
            (u, ch): tail_factors(logs[u][ch], fs=fs, channel=ch) if args.tails else None
            for u in src
            for ch in chans
        }
        for model in args.models:
            fits = {
                (u, ch): eg.fit_gmwm(logs[u].wavelet_variance(ch), model)
                for u in src
                for ch in chans
            }

            for rate in args.rates:
                hold = int(round(rate / fs))
                for t_fix in args.fix:
                    noise = exports(
                        args, fits, tails, src, chans, len(logs), f"{model} @ {rate:g} Hz", rate,
                        horizon_of(args, t_fix),
                    )  # fmt: skip
                    seg = min(max(seg20, int(round(args.min_fixes * t_fix * fs))), n_log)
                    for group, us in (
                        ("unit 1" if args.fleet or args.own else "unit 1 (calibrated)", [0]),
                        ("units 2-6", [1, 2, 3, 4, 5]),
                    ):
                        parts = []
                        for u in us:
                            for ch in chans:
                                r = run_recorded(
                                    _segments(errs[(u, ch)], seg),
                                    noise[(u, ch)],
                                    fs=fs,
                                    hold=hold,
                                    t_fix_s=t_fix,
                                    fix_sigma=fix_sigma,
                                    pb0=pb0,
                                    seed=args.seed + u,
                                )
                                parts.append((r.segments, r.nees))
                        n_seg = sum(m for m, _ in parts)
                        nees = sum(m * v for m, v in parts) / n_seg
                        lo, hi = nees_band(1, n_seg)
                        tot = float(nees.mean())
                        cnt, se, nfix = block_fraction(nees > hi, int(round(t_fix * fs)))
                        ok = 0.5 <= tot <= 1.3 and cnt <= 0.05
                        safe = tot <= 1.3 and cnt <= 0.05  # the fleet file's criterion
                        rows.append(
                            f"| {kind} | {model} | {rate:g} | {t_fix:g} | {group} "
                            f"| {n_seg} x {seg / fs / 60:.0f} min | {nfix} | {tot:.3f} "
                            f"| {100 * float(np.mean(nees < lo)):.1f} % | {100 * cnt:.1f} "
                            f"± {100 * se:.1f} % | {'yes' if ok else 'NO'} "
                            f"| {'yes' if safe else 'NO'} |"
                        )
                        print(rows[-1], flush=True)
            # control: the filter on its own model (x axis, the first rate), runs as long as
            # the recorded segments of the cell
            if args.control_runs <= 0:
                continue
            for t_fix in args.fix:
                nz = exports(
                    args,
                    fits,
                    tails,
                    src,
                    chans,
                    len(logs),
                    model,
                    args.rates[0],
                    horizon_of(args, t_fix),
                )[(0, chans[0])]
                own = eg.Model((eg.WN(sigma2=nz.N**2 * fs), eg.RW(gamma2=nz.K**2 / fs)))
                seg = min(max(seg20, int(round(args.min_fixes * t_fix * fs))), n_log)
                r = run_monte_carlo(
                    own,
                    nz,
                    fs=fs,
                    duration_s=seg / fs,
                    t_fix_s=t_fix,
                    fix_sigma=fix_sigma,
                    runs=args.control_runs,
                    groups=max(10, args.control_runs * seg // 4_000_000),
                    seed=args.seed,
                )
                lo_f, _, _ = r.fractions()
                cnt, se, nfix = r.above_with_error()
                ok = 0.5 <= r.mean_nees <= 1.3 and cnt <= 0.05
                rows.append(
                    f"| {kind} | {model} (control: own WN+RW, simulated) | {fs:g} | {t_fix:g} "
                    f"| - | {args.control_runs} x {seg / fs / 60:.0f} min | {nfix} "
                    f"| {r.mean_nees:.3f} | {100 * lo_f:.1f} % "
                    f"| {100 * cnt:.1f} ± {100 * se:.1f} % "
                    f"| {'yes' if ok else 'NO'} | {'yes' if ok or r.mean_nees < 0.5 else 'NO'} |"
                )
                print(rows[-1], flush=True)
    print(
        "\n| sensor | model fitted to unit 1 | filter Hz | T_fix s | errors from | segments "
        "| fix intervals per segment | mean NEES | below band | above band ± s.e. "
        "| NEES in [0.5, 1.3], <= 5 % above | not overconfident: <= 1.3, <= 5 % above |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    print(
        f"\ntotal {time.perf_counter() - t_all:.0f} s wall, {time.process_time() - c_all:.0f} s CPU"
    )


if __name__ == "__main__":
    main()
