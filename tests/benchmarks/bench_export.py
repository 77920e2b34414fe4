"""Export speed: CPU time of ``eg.export`` per format for the six demo channels.

Run: ``python tests/benchmarks/bench_export.py [--model 2*GM+WN+RW] [--repeat 3] [--log PATH]``.

The six channels of the bundled demo (200,000 samples at 100 Hz each; ``--log``: another
log, e.g. ``../shared/data/adis16405_imu1.h5``) are fitted once; then every format of
:data:`engine.formats.FORMATS` is exported from those fits (PX4 and ArduPilot at a filter rate
of 100 Hz), each the best of ``--repeat`` CPU times (``time.process_time``; the fits' cached
interval covariances and projections and the log's tail factors cleared before each repeat:
a cold export, as the first one of an app session or a ``gmwm export``; the fit is not timed,
and the formats that share a consumer do not share its projections); the first row is the
log's tail factors alone (``engine.formats.tails.log_tail_factors``, cold), which every
filter format's time includes. The
reference, measured in the same run between the formats, is a bare NumPy Haar WV of the same
six channels (one cumulative sum per channel and the level loop of docs/conventions.md), so
the ratios can be read on a loaded machine. The target is at most 0.5 s of CPU per format on
a quiet machine; the table says each format's ratio, and the target as a ratio at the
reference measured here. Before/after: run it on the old and the new tree back to back.
"""

from __future__ import annotations

import argparse
import time
import weakref

import numpy as np

import engine as eg
from engine.demo import demo_path
from engine.formats import FORMATS
from engine.formats import projection as _projection
from engine.formats import tails as _tails


def numpy_wv(x: np.ndarray) -> np.ndarray:
    """The Haar WV of all levels from one cumulative sum (the reference's work)."""
    s = np.concatenate([[0.0], np.cumsum(x - x.mean())])
    n, out, j = x.size, [], 1
    while 2**j < n:
        m = 2 ** (j - 1)
        w = (s[2 * m :] - 2 * s[m:-m] + s[: -2 * m]) / 2**j
        out.append(float(np.mean(w * w)))
        j += 1
    return np.array(out)


def cpu(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        _projection._COV = weakref.WeakKeyDictionary()  # noqa: SLF001 (a cold export)
        _tails._LOG_TAILS = weakref.WeakKeyDictionary()  # noqa: SLF001
        _projection._PROJECTIONS = weakref.WeakKeyDictionary()  # noqa: SLF001
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="2*GM+WN+RW")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--log", default=None, help="a log to export (default: the demo)")
    args = ap.parse_args()
    log = eg.load_log(args.log or demo_path())
    xs = [np.asarray(log[ch], float) for ch in log.names]
    fits = {ch: eg.fit_gmwm(log.wavelet_variance(ch), args.model) for ch in log.names}
    eg.export(None, fits, "gazebo", log=log)  # imports (scipy.optimize) outside the timings
    refs = []

    def ref() -> float:
        r = cpu(lambda: [numpy_wv(x) for x in xs], args.repeat)
        refs.append(r)
        return r

    rows = []
    r0 = ref()
    t = cpu(lambda: _tails.log_tail_factors(log, log.names), args.repeat)
    rows.append(("(the log's tail factors alone, part of every filter format's time)", t, t / r0))
    for name, f in FORMATS.items():
        kw = {"filter_rate": 100.0} if f.needs_filter_rate else {}
        r0 = ref()
        t = cpu(lambda name=name, kw=kw: eg.export(None, fits, name, log=log, **kw), args.repeat)
        rows.append((name, t, t / r0))
    r = float(np.median(refs))
    print(
        f"{'demo' if args.log is None else args.log}: {len(xs)} channels x {xs[0].size:,} "
        f"samples at {log.fs:g} Hz, model "
        f"{args.model}; best of {args.repeat} CPU times; reference (NumPy Haar WV of the six "
        f"channels) median {r * 1e3:.1f} ms (range {min(refs) * 1e3:.1f}-"
        f"{max(refs) * 1e3:.1f} ms); target 0.5 s = x{0.5 / r:.1f} the reference here"
    )
    print("| format | CPU s | / reference | <= 0.5 s |")
    print("|---|---|---|---|")
    for name, t, q in rows:
        ok = "-" if name.startswith("(") else "yes" if t <= 0.5 else "NO"
        print(f"| {name} | {t:.3f} | {q:.2f} | {ok} |")


if __name__ == "__main__":
    main()
