"""(N, k) arrays of several axes: wavelet_variance and fit_gmwm give one result per column,
and load_log reads a 3-axis dataset as three channels."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

import engine as eg


def test_wv_of_three_axes_is_one_per_column() -> None:
    x = np.random.default_rng(0).normal(size=(4000, 3)) * [1.0, 2.0, 3.0]
    wvs = eg.wavelet_variance(x, fs=100.0, levels=8)
    assert isinstance(wvs, list) and len(wvs) == 3
    for k in range(3):
        ref = eg.wavelet_variance(x[:, k], fs=100.0, levels=8)
        np.testing.assert_array_equal(wvs[k].variance, ref.variance)
    # white noise sigma_k^2 / 2 at level 1, sigma = 1, 2, 3 (n = 4000: +-5 % at 2 sigma)
    np.testing.assert_allclose([w.variance[0] for w in wvs], [0.5, 2.0, 4.5], rtol=0.1)


def test_fit_of_three_axes_is_one_per_column() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=(20000, 3)) * np.sqrt([1e-2, 4e-2, 9e-2])
    fits = eg.fit_gmwm(x, "WN", fs=100.0)
    assert isinstance(fits, list) and len(fits) == 3
    got = [f.params["WN.sigma2"] for f in fits]
    # sigma2 from n = 20000 samples: relative std sqrt(2/n) = 1 %; 4 sigma band
    np.testing.assert_allclose(got, [1e-2, 4e-2, 9e-2], rtol=0.04)
    assert fits[1].params == eg.fit_gmwm(x[:, 1], "WN", fs=100.0).params


def test_transposed_and_single_column_arrays() -> None:
    x = np.random.default_rng(2).normal(size=(3, 500))
    with pytest.raises(ValueError, match=r"more columns than rows.*x\.T"):
        eg.wavelet_variance(x)
    one = eg.wavelet_variance(x[:1].T)  # (N, 1): one WV, as before
    assert isinstance(one, eg.WaveletVariance)


def test_load_log_of_a_three_axis_dataset(tmp_path: Path) -> None:
    x = np.random.default_rng(3).normal(size=(1000, 3))
    with h5py.File(tmp_path / "imu.h5", "w") as f:
        f["gyro"] = x
        f.attrs["fs_hz"] = 200.0
    log = eg.load_log(tmp_path / "imu.h5")
    assert log.n == 1000 and len(log.names) == 3 and log.fs == 200.0
    for k, name in enumerate(log.names):
        np.testing.assert_array_equal(log[name], x[:, k])
    np.save(tmp_path / "imu.npy", x)
    assert len(eg.load_log(tmp_path / "imu.npy", fs=200.0).names) == 3
