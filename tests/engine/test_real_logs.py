"""The real static IMU logs of ../shared/data load and fit (read in place, never copied)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

import engine as eg

pytestmark = pytest.mark.real_data


@pytest.fixture(scope="module")
def shared(real_data: Path) -> Path:
    return real_data


@pytest.fixture(scope="module")
def adis_gyro_x_wv(shared):
    log = eg.load_log(shared / "adis16405_imu1.h5", channel="gyro_x")
    assert log.fs == 100.0 and log.n == 1_000_000 and log.units["gyro_x"] == "deg/s"
    return eg.wavelet_variance(log["gyro_x"], fs=log.fs, unit="deg/s")


def test_adis_gyro_gm_model_fits_far_better_than_slope_method_model(adis_gyro_x_wv):
    good = eg.fit_gmwm(adis_gyro_x_wv, "2*GM+WN+RW")
    bad = eg.fit_gmwm(adis_gyro_x_wv, "WN+QN+RW+DR")
    assert good.converged
    assert good.objective < bad.objective / 20, (good.objective, bad.objective)
    # the slow GM: correlation time of about 100 s
    assert 30 < 1 / good.params["GM_1.beta"] < 300
    # the implied WV follows the empirical one within 10 % up to 2^13 samples (82 s), and
    # stays inside the 95 % interval at the long scales where the intervals are wide
    ratio = adis_gyro_x_wv.variance / good.implied
    assert np.all(np.abs(ratio[:13] - 1) < 0.1), ratio
    inside = (adis_gyro_x_wv.ci_low <= good.implied) & (good.implied <= adis_gyro_x_wv.ci_high)
    assert np.all(inside[6:]), inside


def test_adis_wv_matches_allan_identity_on_real_data(shared, adis_gyro_x_wv):
    with h5py.File(shared / "adis16405_imu1.h5") as f:
        x = f["gyro_x"][:200_000]
    wv = eg.wavelet_variance(x, levels=6)
    c = np.concatenate([[0.0], np.cumsum(x - x.mean())])
    for j in range(1, 7):
        m = 2 ** (j - 1)
        avg = (c[m:] - c[:-m]) / m
        assert wv.variance[j - 1] == pytest.approx(
            0.25 * np.mean((avg[m:] - avg[:-m]) ** 2), rel=1e-9
        )


def test_every_adis_replicate_and_channel_loads(shared):
    for k in range(1, 7):
        log = eg.load_log(shared / f"adis16405_imu{k}.h5")
        assert log.names == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
        assert log.fs == 100.0 and log.n == 1_000_000


def test_robust_wv_tames_the_contaminated_mtig_gyro(shared):
    log = eg.load_log(shared / "mtig_cont_imu1.h5")
    x = log["gyro_x"]
    wv = eg.wavelet_variance(x, fs=log.fs, robust=True, levels=10)
    # heavy tails inflate the classical WV at the short scales, not at the long ones
    assert wv.classical.variance[0] > 2 * wv.variance[0]
    assert wv.classical.variance[-1] == pytest.approx(wv.variance[-1], rel=0.1)
    res = eg.fit_gmwm(wv, "GM+WN")
    assert res.converged and np.isfinite(res.objective)


@pytest.mark.parametrize(
    "name",
    ["navchip_wv_av.h5", "ln200_wv_av.h5", "imar_wv_av.h5", "kvh1750_wv_av.h5", "mtig_imu6_wv.h5"],
)
def test_wv_summaries_load_and_fit(shared, name):
    log = eg.load_log(shared / "derived" / name)
    assert log.is_summary and not log.channels
    ch = log.names[0]
    wv = log.wv[ch]
    with h5py.File(shared / "derived" / name) as f:
        np.testing.assert_array_equal(wv.variance, f[f"wv/{ch}/variance"][:])
        np.testing.assert_array_equal(wv.ci_high, f[f"wv/{ch}/ci_high"][:])
        assert wv.fs == f.attrs["fs_hz"] and wv.n == f.attrs["n_samples"]
    lin = eg.fit_gmwm(wv, "QN+WN+RW")
    gm = eg.fit_gmwm(wv, "GM+QN+WN+RW")
    assert gm.objective <= lin.objective * (1 + 1e-9)  # a larger nested model never fits worse


def test_navchip_summary_wv_agrees_with_eta3_of_its_own_values(shared):
    """The stored intervals follow the eta3 of docs/conventions.md with J = floor(log2 N) - 1
    levels."""
    log = eg.load_log(shared / "derived" / "navchip_wv_av.h5")
    wv = log.wv["gyro_x"]
    assert wv.n_levels == int(np.floor(np.log2(wv.n))) - 1
    ours = eg.WaveletVariance.from_arrays(wv.variance, n=wv.n, fs=wv.fs)
    np.testing.assert_allclose(ours.ci_low, wv.ci_low, rtol=1e-6)
    np.testing.assert_allclose(ours.ci_high, wv.ci_high, rtol=1e-6)
