"""Datasheet conversions (CONVENTIONS, Units) and the processes' unconstrained transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

import engine as eg


def rows(model, fs, unit):
    return {
        (r["label"], r["quantity"]): (r["value"], r["unit"])
        for r in eg.datasheet(eg.parse_model(model), fs, unit)
    }


def test_gyro_white_noise_and_random_walk_in_datasheet_units():
    fs = 200.0
    d = rows("WN(sigma2=4e-4)+RW(gamma2=1e-12)", fs, "deg/s")
    n = math.sqrt(4e-4 / fs)  # (deg/s)/sqrt(Hz)
    assert d[("WN", "white noise density N")] == (pytest.approx(n), "deg/s/sqrt(Hz)")
    assert d[("WN", "angle random walk")] == (pytest.approx(60 * n), "deg/sqrt(h)")
    k = math.sqrt(1e-12 * fs)  # (deg/s)/sqrt(s)
    assert d[("RW", "rate random walk K")][0] == pytest.approx(k)
    assert d[("RW", "rate random walk")] == (pytest.approx(216000 * k), "deg/h/sqrt(h)")


def test_rad_per_second_converts_to_degrees():
    d = rows("WN(sigma2=1e-6)", 100.0, "rad/s")
    n = math.sqrt(1e-6 / 100.0)
    assert d[("WN", "angle random walk")][0] == pytest.approx(60 * n * 180 / math.pi)


def test_accelerometer_quantization_drift_and_vrw():
    fs = 50.0
    d = rows("QN(q2=1e-6)+WN(sigma2=1e-4)+DR(omega=-2e-7)", fs, "m/s^2")
    assert d[("QN", "quantization Q")] == (pytest.approx(1e-3 / fs), "m/s^2*s")
    assert d[("DR", "rate ramp R")] == (pytest.approx(2e-7 * fs), "m/s^2/s")
    assert d[("WN", "velocity random walk")] == (
        pytest.approx(60 * math.sqrt(1e-4 / fs)),
        "m/s/sqrt(h)",
    )


def test_gm_correlation_time_and_psd():
    d = rows("GM(beta=0.25, sigma2_gm=9e-6)", 100.0, "deg/s")
    assert d[("GM", "correlation time 1/beta")] == (pytest.approx(4.0), "s")
    assert d[("GM", "stationary std sqrt(sigma2_gm)")][0] == pytest.approx(3e-3)
    assert d[("GM", "driving-noise PSD q = 2 beta sigma2_gm")][0] == pytest.approx(4.5e-6)


def test_allan_variance_shape_of_white_noise_matches_n_squared_over_t():
    """AV(T) = N^2 / T with N the white-noise density: AV = 2 WV at T = tau/2 samples."""
    fs, s2 = 100.0, 2.5e-3
    tau = 2.0 ** np.arange(1, 12)
    wv = eg.WN(sigma2=s2).wv(tau, fs)
    t_s = tau / 2 / fs
    n2 = s2 / fs
    np.testing.assert_allclose(2 * wv, n2 / t_s)


def test_param_units():
    assert eg.param_unit("WN", "sigma2", "deg/s") == "(deg/s)^2"
    assert eg.param_unit("GM", "sigma2_gm", "g") == "g^2"
    assert eg.param_unit("GM", "beta", "g") == "1/s"
    assert eg.param_unit("DR", "omega", "m/s^2") == "m/s^2 per sample"


@pytest.mark.parametrize(
    "proc",
    [
        eg.WN(sigma2=2e-3),
        eg.QN(q2=1e-7),
        eg.RW(gamma2=1e-12),
        eg.DR(omega=-3e-6),
        eg.AR1(phi=-0.3, sigma2=0.5),
        eg.AR1(phi=0.999, sigma2=1e-4),
        eg.GM(beta=0.02, sigma2_gm=4e-5),
    ],
    ids=repr,
)
def test_unconstrained_round_trip_and_bounds(proc):
    u = proc.to_unconstrained()
    assert np.all(np.isfinite(u))
    back = proc.from_unconstrained(u)
    np.testing.assert_allclose(back.values, proc.values, rtol=1e-12)
    # any real vector maps inside the bounds
    for z in (np.full(u.size, -30.0), np.full(u.size, 30.0), np.zeros(u.size)):
        q = proc.from_unconstrained(z)
        for name, v in zip(q.param_names, q.values, strict=True):
            lo, hi = proc.bounds()[name]
            assert lo <= v <= hi
