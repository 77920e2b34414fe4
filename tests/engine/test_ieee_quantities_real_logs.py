"""Real-log acceptance of the IEEE quantities (engine/fit/ieee.py) on the six ADIS16405 units
and the MTi-G log of ../shared/data: the reported ARW against the Allan deviation read at
T = 1 s, and the bias instability in both conventions beside each other."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

import engine as eg

pytestmark = [pytest.mark.real_data, pytest.mark.slow]  # six units fitted: 14 s of CPU

ADIS = [f"adis16405_imu{k}.h5" for k in range(1, 7)]
MTIG = "mtig_cont_imu1.h5"
#: The structures the report selects on these gyros today (2*GM+QN, with a GM faster than one
#: sample and QN at 0) and the white-noise twin a fixed selection reports.
MODELS = ("2*GM+QN", "GM+WN+QN+RW")


@pytest.fixture(scope="module")
def gyro_fits(real_data: Path) -> dict[tuple[str, str], tuple[float, dict[str, eg.GMWMResult]]]:
    """Per (file, gyro channel): the overlapping ADEV at exactly T = 1 s (fs samples) from
    the raw series, and the fits of :data:`MODELS`."""
    out = {}
    for name in [*ADIS, MTIG]:
        log = eg.load_log(real_data / name)
        for ch in (c for c in log.names if c.startswith("gyro")):
            adev1 = float(eg.allan_variance(log[ch], fs=log.fs, taus=[int(log.fs)]).adev[0])
            wv = log.wavelet_variance(ch)
            out[(name, ch)] = (adev1, {m: eg.fit_gmwm(wv, m) for m in MODELS})
    return out


def test_reported_arw_is_the_allan_deviation_at_one_second(gyro_fits):
    """Every gyro channel's ARW is within a factor 1.25 of ADEV(1 s) (x 60 in deg/sqrt(h)),
    whatever the fitted structure: the white noise carried by a GM faster than one sample
    counts. Before: the 2*GM+QN fits reported no ARW at all (WN absent). Measured: ratio
    1.007-1.172 on the 18 ADIS gyros, 0.975 on the MTi-G."""
    assert len(gyro_fits) == 19
    ratios = []
    for (name, ch), (adev1, fits) in gyro_fits.items():
        for m, res in fits.items():
            n = res.ieee.get("N")
            assert n is not None, (name, ch, m)
            assert n.native_unit.endswith("/sqrt(Hz)")
            r = n.native / adev1
            ratios.append(r)
            assert 1 / 1.25 <= r <= 1.25, (name, ch, m, r)
            if res.wv.unit == "deg/s":  # the datasheet unit: x 60
                assert n.datasheet_unit == "deg/sqrt(h)"
                assert n.datasheet_value == pytest.approx(60.0 * n.native, rel=1e-12)
                assert n.low < n.value < n.high
    assert len(ratios) == 19 * len(MODELS)


def test_adis_bias_instability_in_both_conventions(gyro_fits):
    """Beside the IEEE 952 B (floor / 0.664) every ADIS gyro reports the Allan-deviation
    minimum with its averaging time, from the model and from the data. The datasheet's
    in-run bias stability (ADEV minimum) is 25.2 deg/h; measured on the 18 gyros: data
    minimum 15.5-33.7 deg/h, model minimum (GM+WN+QN+RW) about 20-30 deg/h, so B is
    1.5x larger (30-45 deg/h), the difference seen on these logs."""
    data_min = []
    for (name, _ch), (_adev1, fits) in gyro_fits.items():
        if name == MTIG:
            continue
        t = fits["GM+WN+QN+RW"].ieee
        b, amin, adata = t["B"], t["ADEV_min"], t["ADEV_data"]
        assert b.datasheet_unit == amin.datasheet_unit == adata.datasheet_unit == "deg/h"
        assert b.datasheet_value == pytest.approx(amin.datasheet_value / eg.units.BI_FACTOR)
        assert math.isfinite(amin.tau_s) and 1.0 < amin.tau_s < 5000.0
        assert math.isfinite(adata.tau_s) and adata.low < adata.value < adata.high
        assert 12.0 < amin.datasheet_value < 36.0, (name, amin.datasheet_value)
        data_min.append(adata.datasheet_value)
    assert len(data_min) == 18
    assert 10.0 < min(data_min) and max(data_min) < 40.0
    # the datasheet's 25.2 deg/h lies inside the spread of the units' measured minima
    assert min(data_min) < 25.2 < max(data_min)
