"""The logs the served-app load test and its loop benchmark open (``tests/app/test_server_load.py``,
``tests/benchmarks/bench_loop.py``): two gyro channels whose white-noise level differs per file,
so that a session showing another session's log shows it in the fit."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np


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
