"""Logs the tests write: those the served-app load test and its loop benchmark open
(:func:`write_log`: ``tests/app/test_server_load.py``, ``tests/benchmarks/bench_loop.py``), and
a gyro triad with a warm-up's bias wander (:func:`write_wander_triad`: the log check's tests in
the CLI and the app)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

import engine as eg


def write_log(path: Path, seed: int, n: int = 20_000, fs: float = 100.0) -> Path:
    """Write an HDF5 log of ``n`` samples at ``fs`` Hz: white noise of 1e-3 (1 + seed) (1 + i)
    deg/s on channel i plus a random walk of 1e-5 deg/s per sample; returns ``path``."""
    rng = np.random.default_rng(seed)
    with h5py.File(path, "w") as f:
        for i, name in enumerate(("gyro_x", "gyro_y")):
            sigma = 1e-3 * (1 + seed) * (1 + i)
            x = rng.normal(0, sigma, n) + np.cumsum(rng.normal(0, 1e-5, n))
            f.create_dataset(name, data=x).attrs["units"] = "deg/s"
        f.attrs["fs_hz"] = fs
    return path


def write_wander_triad(path: Path, n: int = 200_000, fs: float = 100.0) -> dict[str, np.ndarray]:
    """Write an HDF5 gyro triad (deg/s) of ``n`` samples at ``fs`` Hz: white noise of 0.1 plus
    a random walk whose innovation variance is 8 times larger in the first 300 s (1e-8 after);
    returns its channels."""
    rng = np.random.default_rng(3)
    g = np.full(n, 1e-8)
    g[: int(300 * fs)] *= 8.0
    chans = {
        f"gyro_{a}": rng.normal(scale=0.1, size=n) + np.cumsum(rng.normal(size=n) * np.sqrt(g))
        for a in "xyz"
    }
    eg.io.save_log(path, chans, fs, units=dict.fromkeys(chans, "deg/s"))
    return chans
