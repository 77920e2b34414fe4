"""Engine benchmarks (issue: engine). Run: ``python tests/benchmarks/bench_engine.py [--n N]``.

Prints, for a series of N samples (default 6.3e6, the GMWM paper's longest simulation):

* WV of all levels: ours against ``allantools.oadev`` with octave taus, measured in the same
  run on the same data (ratio = allantools time / ours), with the BLAS pool limited to one
  thread as the ``gmwm`` command and the app run (and, for information, with the process's
  default pool), and the extra memory of ours (peak traced allocations / input size);
* GMWM fit of 2*GM+WN+RW: WV + fit in process, the ``gmwm fit`` command end to end on an
  NPY file (process start, imports, load, WV, fit, JSON), and a refit on the cached WV.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import engine as eg

TRUTH = (
    "GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.01, sigma2_gm=1e-4)+WN(sigma2=1e-2)+RW(gamma2=1e-10)"
)


def best_of(fn, repeat: int) -> tuple[float, float]:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times), statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=float, default=6.3e6)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    n = int(args.n)
    fs = 100.0
    x = eg.parse_model(TRUTH).simulate(n, fs=fs, rng=1)
    print(f"series: N = {n:,} samples of {TRUTH} at {fs:g} Hz")

    import allantools

    from engine._blas import blas_threads, set_blas_threads

    threads = blas_threads()
    any_min, any_med = best_of(lambda: eg.wavelet_variance(x, fs=fs), args.repeat)
    set_blas_threads(1)  # what the gmwm command and the app do (engine._blas)
    ours_min, ours_med = best_of(lambda: eg.wavelet_variance(x, fs=fs), args.repeat)
    ref_min, ref_med = best_of(
        lambda: allantools.oadev(x, rate=fs, data_type="freq", taus="octave"), args.repeat
    )
    wv = eg.wavelet_variance(x, fs=fs)
    tracemalloc.start()
    eg.wavelet_variance(x, fs=fs)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(f"\nWV of all levels (best / median of {args.repeat})")
    print(
        f"  ours, 1 BLAS thread  {ours_min * 1e3:8.1f} / {ours_med * 1e3:8.1f} ms "
        f"({wv.n_levels} levels; as the gmwm command and the app run)"
    )
    print(
        f"  ours, {threads} BLAS threads {any_min * 1e3:7.1f} / {any_med * 1e3:8.1f} ms "
        f"(the process's default pool: BLAS dot in 8192-sample chunks), "
        f"{ref_min / any_min:.2f}x (best)"
    )
    print(f"  allantools.oadev     {ref_min * 1e3:8.1f} / {ref_med * 1e3:8.1f} ms (octave taus)")
    print(
        f"  speed-up             {ref_min / ours_min:8.2f}x (best)  "
        f"{ref_med / ours_med:.2f}x (median)   target >= 4x"
    )
    print(
        f"  extra memory         {peak / x.nbytes:8.2f}x the input "
        f"({peak / 2**20:.1f} MiB for a {x.nbytes / 2**20:.1f} MiB series)   target <= 3x"
    )

    model = eg.parse_model("2*GM+WN+RW")
    tot_min, tot_med = best_of(
        lambda: eg.fit_gmwm(eg.wavelet_variance(x, fs=fs), model), args.repeat
    )
    refit_min, refit_med = best_of(lambda: eg.fit_gmwm(wv, model), 20)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "series.npy"
        np.save(path, x)
        cmd = [
            sys.executable,
            "-m",
            "engine.cli",
            "fit",
            str(path),
            "--model",
            "2*GM+WN+RW",
            "--fs",
            str(fs),
            "--json",
        ]
        cli_min, cli_med = best_of(lambda: subprocess.run(cmd, check=True, capture_output=True), 3)
        imp_min, _ = best_of(
            lambda: subprocess.run([sys.executable, "-c", "import engine.cli"], check=True), 3
        )
    res = eg.fit_gmwm(wv, model)
    print("\nGMWM fit of 2*GM+WN+RW (best / median)")
    print(f"  WV + fit in process  {tot_min * 1e3:8.1f} / {tot_med * 1e3:8.1f} ms   target < 1000")
    print(
        f"  gmwm fit command     {cli_min * 1e3:8.1f} / {cli_med * 1e3:8.1f} ms "
        f"(of which interpreter + imports {imp_min * 1e3:.0f} ms)"
    )
    print(
        f"  refit on cached WV   {refit_min * 1e3:8.2f} / {refit_med * 1e3:8.2f} ms   target < 30"
    )
    print(
        f"  objective {res.objective:.4g}; estimates: "
        + ", ".join(f"{k}={v:.3g}" for k, v in res.params.items())
    )


if __name__ == "__main__":
    main()
