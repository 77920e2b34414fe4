"""Streaming WV benchmark. Run: ``python tests/benchmarks/bench_stream.py``.

Writes a log of ``--n`` samples (default 1e8: 800 MB as float64) to a ``.npy`` or HDF5 file in
the temporary directory, in chunks (the generator itself holds a few MB), then computes the
classical Haar WV of every level with :func:`engine.wv.wavelet_variance_stream` in a fresh
subprocess and reports its wall time and peak resident memory (``resource.getrusage``
``ru_maxrss`` of that subprocess, which includes the interpreter and the imports, and on
Linux also whatever the parent held when it forked, so it is an upper bound; the value right
after the imports and the kernel's ``VmHWM`` of the subprocess's own address space are shown
too). The file is deleted afterwards.

Target: peak RSS < 500 MB for 1e8 samples. With ``--check`` a second subprocess computes the
in-memory WV (needs about 2.5x the file size in RAM) and prints the largest relative
difference (target < 1e-9).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
import engine as eg
from engine.wv import wavelet_variance_stream
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
mode, path, dataset, block = sys.argv[1], sys.argv[2], sys.argv[3] or None, int(sys.argv[4])
t = time.perf_counter()
c0 = time.process_time()
if mode == "stream":
    wv = wavelet_variance_stream(path, dataset=dataset, fs=100.0, block=block)
else:
    if path.endswith(".npy"):
        x = np.load(path)
    else:
        import h5py
        with h5py.File(path, "r") as f:
            x = f[dataset][...]
    wv = eg.wavelet_variance(x, fs=100.0)
el = time.perf_counter() - t
cpu = time.process_time() - c0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
hwm = next((int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")), 0)
print(json.dumps({{"seconds": el, "cpu_seconds": cpu, "peak_rss_mb": peak / 1024,
                  "base_rss_mb": base / 1024, "vmhwm_mb": hwm / 1024, "levels": wv.n_levels,
                  "variance": wv.variance.tolist()}}))
"""


def write_log(path: Path, n: int, dtype: str, fmt: str, chunk: int = 1 << 20) -> None:
    """WN + RW + an offset, written chunk by chunk (bounded memory)."""
    rng = np.random.default_rng(7)
    carry = 0.0

    def chunks():
        nonlocal carry
        for a in range(0, n, chunk):
            k = min(chunk, n - a)
            rw = carry + np.cumsum(rng.normal(0.0, 1e-4, k))
            carry = float(rw[-1])
            yield a, (9.81 + rng.normal(0.0, 0.01, k) + rw).astype(dtype)

    if fmt == "npy":
        with open(path, "wb") as fh:
            np.lib.format.write_array_header_2_0(
                fh,
                {
                    "descr": np.lib.format.dtype_to_descr(np.dtype(dtype)),
                    "fortran_order": False,
                    "shape": (n,),
                },
            )
            for _, x in chunks():
                fh.write(x.tobytes())
    else:
        import h5py

        with h5py.File(path, "w") as f:
            ds = f.create_dataset("gyro_x", shape=(n,), dtype=dtype, chunks=(1 << 16,))
            f.attrs["fs_hz"] = 100.0
            for a, x in chunks():
                ds[a : a + x.size] = x


def run(mode: str, path: Path, dataset: str, block: int) -> dict:
    code = CHILD.format(root=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", code, mode, str(path), dataset, str(block)],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=float, default=1e8, help="samples (1e8)")
    ap.add_argument("--dtype", default="float64", choices=["float64", "float32"])
    ap.add_argument("--format", default="npy", choices=["npy", "h5"])
    ap.add_argument("--block", type=int, default=1 << 19, help="block length (2^19)")
    ap.add_argument(
        "--check", action="store_true", help="also compute the in-memory WV and compare (needs RAM)"
    )
    ap.add_argument("--dir", default=tempfile.gettempdir(), help="where to write the log")
    args = ap.parse_args()
    n = int(args.n)
    path = Path(args.dir) / f"gmwm_bench_stream_{os.getpid()}.{args.format}"
    dataset = "gyro_x" if args.format == "h5" else ""
    try:
        t = time.perf_counter()
        write_log(path, n, args.dtype, args.format)
        size = path.stat().st_size
        print(
            f"log: {n:,} samples of {args.dtype} in {args.format} ({size / 1e6:,.0f} MB), "
            f"written in {time.perf_counter() - t:.1f} s"
        )
        s = run("stream", path, dataset, args.block)
        print(
            f"streamed WV: {s['levels']} levels in {s['seconds']:.1f} s wall, "
            f"{s['cpu_seconds']:.1f} s CPU ({n / s['seconds'] / 1e6:.1f} M samples/s); "
            f"peak RSS {s['peak_rss_mb']:.0f} MB "
            f"(ru_maxrss; at start, after the imports: {s['base_rss_mb']:.0f} MB), "
            f"VmHWM {s['vmhwm_mb']:.0f} MB; block {args.block}"
        )
        verdict = "OK" if s["peak_rss_mb"] < 500 else "OVER"
        print(f"target peak RSS < 500 MB: {verdict}")
        if args.check:
            m = run("memory", path, dataset, args.block)
            rel = np.max(np.abs(np.array(s["variance"]) / np.array(m["variance"]) - 1))
            print(
                f"in-memory WV: {m['seconds']:.1f} s wall, {m['cpu_seconds']:.1f} s CPU, "
                f"peak RSS {m['peak_rss_mb']:.0f} MB; "
                f"largest relative difference {rel:.2e} (target < 1e-9)"
            )
    finally:
        path.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
