"""Generate the bundled demo log ``engine/demo/demo_imu.h5`` and its truth ``demo_imu_truth.json``.

Both are package data of ``engine`` (shipped in the wheel; ``engine.demo.demo_path()`` finds
them), written into ``engine/demo/`` of this checkout.

A realistic six-axis MEMS IMU at 100 Hz for about 33 minutes (200,000 samples per channel,
stored as float32 like most IMU outputs):

* gyroscopes (deg/s): white noise + rate random walk + two Gauss-Markov terms + a turn-on bias;
* accelerometers (m/s^2): quantization + white noise + random walk + drift, gravity on z.

Deterministic: a fixed seed per channel. Run ``python data/make_demo.py`` from the repository
root; the tests check that the committed files are what this script makes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import engine as eg
from engine.io import save_log

FS = 100.0
N = 200_000
SEED = 20261121
HERE = Path(__file__).resolve().parent
#: Where the demo is written: the package data folder of ``engine.demo``.
OUT_DIR = HERE.parent / "engine" / "demo"

# Per-sample parameters (docs/conventions.md): gyro ARW about 0.3 deg/sqrt(h),
# RRW about 10 deg/h/sqrt(h)
TRUTH = {
    "gyro_x": "GM(beta=0.01, sigma2_gm=9e-6)+GM(beta=0.5, sigma2_gm=1.6e-5)"
    "+WN(sigma2=2.5e-3)+RW(gamma2=2.1e-11)",
    "gyro_y": "GM(beta=0.02, sigma2_gm=6e-6)+GM(beta=0.8, sigma2_gm=2.0e-5)"
    "+WN(sigma2=3.0e-3)+RW(gamma2=1.5e-11)",
    "gyro_z": "GM(beta=0.005, sigma2_gm=1.2e-5)+GM(beta=0.3, sigma2_gm=1.2e-5)"
    "+WN(sigma2=2.0e-3)+RW(gamma2=3.0e-11)",
    "accel_x": "QN(q2=2e-5)+WN(sigma2=7e-5)+RW(gamma2=1e-10)+DR(omega=5e-8)",
    "accel_y": "QN(q2=1.5e-5)+WN(sigma2=8e-5)+RW(gamma2=1.5e-10)+DR(omega=4e-8)",
    "accel_z": "QN(q2=3e-5)+WN(sigma2=1.0e-4)+RW(gamma2=2e-10)+DR(omega=6e-8)",
}
OFFSET = {
    "gyro_x": 0.31,
    "gyro_y": -0.18,
    "gyro_z": 0.07,
    "accel_x": 0.012,
    "accel_y": -0.031,
    "accel_z": -9.80665,
}
UNITS = {c: ("deg/s" if c.startswith("gyro") else "m/s^2") for c in TRUTH}


def make(out_dir: Path = OUT_DIR) -> Path:
    """Simulate the six channels and write the HDF5 log and the JSON truth; returns the log path."""
    channels = {}
    for i, (name, spec) in enumerate(TRUTH.items()):
        model = eg.parse_model(spec)
        x = model.simulate(N, fs=FS, rng=np.random.default_rng([SEED, i])) + OFFSET[name]
        channels[name] = x.astype(np.float32)
    path = out_dir / "demo_imu.h5"
    save_log(
        path,
        channels,
        FS,
        units=UNITS,
        attrs={
            "sensor": "simulated six-axis MEMS IMU (gmwm-app demo)",
            "description": "Static log simulated by data/make_demo.py with known latent models; "
            "true per-sample parameters in the attribute true_models (JSON).",
            "true_models": json.dumps(TRUTH),
            "seed": SEED,
        },
    )
    truth = {
        "fs_hz": FS,
        "n_samples": N,
        "seed": SEED,
        "units": UNITS,
        "offsets": OFFSET,
        "models": TRUTH,
    }
    (out_dir / "demo_imu_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return path


if __name__ == "__main__":
    print(f"wrote {make()}")
