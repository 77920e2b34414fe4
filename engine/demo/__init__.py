"""The bundled demo log: a simulated six-axis MEMS IMU with known latent models.

The files are package data of ``engine`` (shipped in the wheel, read with
:mod:`importlib.resources`): ``demo_imu.h5`` (100 Hz, 200,000 float32 samples of gyro_x..z in
deg/s and accel_x..z in m/s^2) and ``demo_imu_truth.json`` (the true per-sample models, offsets
and units). ``python data/make_demo.py`` in a checkout regenerates both, bit for bit.

>>> import engine as eg
>>> from engine.demo import demo_path, demo_truth
>>> log = eg.load_log(demo_path())                     # doctest: +SKIP
>>> demo_truth()["models"]["gyro_x"]                   # doctest: +SKIP
"""

from __future__ import annotations

import atexit
import contextlib
import json
from importlib.resources import as_file, files
from pathlib import Path
from typing import Any

__all__ = ["DEMO_LOG", "DEMO_TRUTH", "demo_dir", "demo_path", "demo_truth"]

#: File names of the demo log and of its truth, inside this package.
DEMO_LOG = "demo_imu.h5"
DEMO_TRUTH = "demo_imu_truth.json"

_EXTRACTED = contextlib.ExitStack()
atexit.register(_EXTRACTED.close)


def _file(name: str) -> Path:
    res = files(__name__) / name
    if isinstance(res, Path):  # a normal install or a checkout: the file itself
        return res
    # a zipped install: extract once to a temporary file kept until exit (h5py needs a path)
    return _EXTRACTED.enter_context(as_file(res))


def demo_path() -> Path:
    """Path of the bundled demo log ``demo_imu.h5`` (an HDF5 file for :func:`engine.load_log`).

    Returns
    -------
    Path
        The file inside the installed package (or a temporary copy for zipped installs).
    """
    return _file(DEMO_LOG)


def demo_dir() -> Path:
    """The folder that holds the demo log (the app allows server paths inside it)."""
    return demo_path().parent


def demo_truth() -> dict[str, Any]:
    """The demo's truth: ``fs_hz``, ``n_samples``, ``seed``, ``units``, ``offsets`` and
    ``models`` (one model string with per-sample values per channel, see docs/conventions.md)."""
    return json.loads((files(__name__) / DEMO_TRUTH).read_text(encoding="utf-8"))
