"""The bundled demo log (package data of engine.demo) is what data/make_demo.py makes, and its
truth is recoverable."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.demo import demo_path, demo_truth

DATA = Path(__file__).resolve().parents[2] / "data"  # the generator
DEMO = demo_path().parent  # the package data it writes


def load_generator():
    spec = importlib.util.spec_from_file_location("make_demo", DATA / "make_demo.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_committed_demo_is_reproduced_by_its_generator(tmp_path):
    gen = load_generator()
    path = gen.make(tmp_path)
    fresh, shipped = eg.load_log(path), eg.load_log(DEMO / "demo_imu.h5")
    assert fresh.names == shipped.names == list(gen.TRUTH)
    for ch in shipped.names:
        np.testing.assert_array_equal(fresh[ch], shipped[ch])
    assert json.loads((tmp_path / "demo_imu_truth.json").read_text()) == json.loads(
        (DEMO / "demo_imu_truth.json").read_text()
    )


def test_demo_is_package_data_found_by_importlib_resources():
    assert demo_path() == Path(eg.__file__).resolve().parent / "demo" / "demo_imu.h5"
    assert demo_truth() == json.loads((DEMO / "demo_imu_truth.json").read_text())
    assert demo_truth()["models"]["gyro_x"].startswith("GM(beta=0.01")
    # one copy of the binary log: the generator's folder holds only the script (and a README)
    assert not (DATA / "demo_imu.h5").exists() and not (DATA / "demo_imu_truth.json").exists()
    gen = load_generator()
    assert gen.OUT_DIR.resolve() == DEMO.resolve()


def test_demo_metadata_and_size():
    log = eg.load_log(DEMO / "demo_imu.h5")
    truth = json.loads((DEMO / "demo_imu_truth.json").read_text())
    assert log.fs == truth["fs_hz"] == 100.0 and log.n == truth["n_samples"]
    assert log.units == truth["units"]
    assert (DEMO / "demo_imu.h5").stat().st_size < 10 * 2**20


@pytest.mark.parametrize("channel", ["gyro_x", "accel_x", "accel_z"])
def test_demo_white_noise_is_recovered(channel):
    log = eg.load_log(DEMO / "demo_imu.h5", channel=channel)
    models = json.loads((DEMO / "demo_imu_truth.json").read_text())["models"]
    truth = eg.parse_model(models[channel])
    res = eg.fit_gmwm(eg.wavelet_variance(log[channel], fs=log.fs), truth.cleared())
    assert res.params["WN.sigma2"] == pytest.approx(truth.values()["WN.sigma2"], rel=0.05)
