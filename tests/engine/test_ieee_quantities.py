"""The IEEE quantities of a fit (engine/fit/ieee.py): N with its disguised share, B in both
conventions, K, Q, R, their intervals and units; checked by hand calculations, the model's own
Allan variance and Monte Carlo (the real logs: tests/engine/test_ieee_quantities_real_logs.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

import engine as eg
from engine.fit.ieee import ieee_table, white_share
from engine.units import BI_FACTOR

FS = 100.0


@dataclass
class _Stub:
    """A fit with a model set by hand (the table reads model, wv, omega, at_bound, fs)."""

    model: eg.Model
    wv: eg.WaveletVariance
    omega: np.ndarray
    at_bound: list[str]
    param_records: tuple = ()

    @property
    def fs(self) -> float:
        return self.wv.fs


def _stub(model: eg.Model, unit: str, n: int = 2**16) -> _Stub:
    x = model.simulate(n, rng=np.random.default_rng(0), fs=FS)
    wv = eg.wavelet_variance(x, fs=FS, unit=unit)
    return _Stub(model, wv, np.diag(1.0 / (wv.ci_high - wv.ci_low) ** 2), [])


def test_gyro_factors_against_a_hand_calculation():
    # WN sigma2 = 0.1 (deg/s)^2 at 100 Hz: N = sqrt(0.1 / 100) = 0.0316228 deg/s/sqrt(Hz);
    # 1/sqrt(s) = sqrt(3600)/sqrt(h) = 60/sqrt(h), so ARW = 60 x 0.0316228 = 1.897367 deg/sqrt(h).
    # RW gamma2 = 1e-8 (deg/s)^2: K = sqrt(1e-8 x 100) = 1e-3 deg/s/sqrt(s);
    # deg/s -> deg/h is x 3600 and 1/sqrt(s) -> 1/sqrt(h) x 60: RRW = 216 deg/h/sqrt(h).
    t = ieee_table(_stub(eg.WN(sigma2=0.1) + eg.RW(gamma2=1e-8), "deg/s"))
    deg = math.pi / 180.0
    assert t["N"].datasheet_value == pytest.approx(1.8973666, rel=1e-7)
    assert t["N"].datasheet_unit == "deg/sqrt(h)"
    assert t["N"].value == pytest.approx(0.0316228 * deg, rel=1e-6)
    assert t["N"].unit == "rad/s/sqrt(Hz)"
    assert t["N"].native == pytest.approx(0.0316228, rel=1e-6)
    assert t["K"].datasheet_value == pytest.approx(216.0, rel=1e-9)
    assert t["K"].datasheet_unit == "deg/h/sqrt(h)"
    assert t["K"].value == pytest.approx(1e-3 * deg, rel=1e-9)
    # the Allan floor of N^2/T + K^2 T/3 is at T = sqrt(3) N / K = 54.8 s, where
    # ADEV^2 = 2 N K / sqrt(3) = 3.6515e-5 (deg/s)^2: ADEV = 6.0428e-3 deg/s = 21.754 deg/h,
    # B = 21.754 / 0.6643 = 32.75 deg/h (the grid of 16 points per octave: within 1 %)
    assert t["ADEV_min"].datasheet_value == pytest.approx(21.754, rel=1e-2)
    assert t["ADEV_min"].tau_s == pytest.approx(54.8, rel=0.05)
    assert t["B"].datasheet_value == pytest.approx(21.754 / 0.66428, rel=1e-2)
    assert t["B"].datasheet_value * BI_FACTOR == pytest.approx(t["ADEV_min"].datasheet_value)
    assert t["B"].datasheet_unit == t["ADEV_min"].datasheet_unit == "deg/h"
    assert "Q" not in t and "R" not in t


def test_accelerometer_factors_against_a_hand_calculation():
    # sigma2 = 4e-6 g^2 at 100 Hz: N = sqrt(4e-6 / 100) = 2e-4 g/sqrt(Hz)
    # = 2e-4 x 9.80665 = 1.96133e-3 m/s^2/sqrt(Hz); VRW = x 60 = 0.11768 m/s/sqrt(h).
    # QN q2 = 1e-6 g^2: Q = sqrt(q2) / fs = 1e-5 g s = 9.80665e-5 m/s.
    # DR omega = 1e-7 g per sample: R = 1e-5 g/s = 9.80665e-5 m/s^3 = x 3600^2 m/s/h^2 = 1270.94.
    t = ieee_table(_stub(eg.QN(q2=1e-6) + eg.WN(sigma2=4e-6) + eg.DR(omega=1e-7), "g"))
    assert t["N"].value == pytest.approx(1.96133e-3, rel=1e-5)
    assert t["N"].datasheet_value == pytest.approx(0.1176798, rel=1e-6)
    assert (t["N"].name, t["N"].datasheet_unit) == ("velocity random walk", "m/s/sqrt(h)")
    assert t["Q"].value == pytest.approx(9.80665e-5, rel=1e-9)
    assert t["Q"].unit == "m/s"
    assert t["R"].value == pytest.approx(9.80665e-5, rel=1e-9)
    assert t["R"].datasheet_value == pytest.approx(1270.94184, rel=1e-6)
    assert t["R"].datasheet_unit == "m/s/h^2"
    # bias instability in mg: ADEV [g] x 1000
    assert t["ADEV_min"].datasheet_value == pytest.approx(1e3 * t["ADEV_min"].native, rel=1e-9)
    assert t["ADEV_min"].datasheet_unit == "mg"


def test_unknown_unit_keeps_the_signal_unit():
    t = ieee_table(_stub(eg.WN(sigma2=0.1) + eg.RW(gamma2=1e-8), ""))
    assert t.kind == ""
    assert t["N"].unit == t["N"].datasheet_unit == "u/sqrt(Hz)"
    assert t["N"].value == pytest.approx(math.sqrt(0.1 / FS))


def test_white_noise_in_disguise_counts_in_n():
    # GM beta = 200 /s at 100 Hz: phi = exp(-2) = 0.135335, correlation time 0.5 samples;
    # its white-noise equivalent is S(0) = sigma2_gm (1 + phi) / (1 - phi)
    # = 0.05 x 1.135335 / 0.864665 = 0.0656517 (deg/s)^2, added to WN's 0.02.
    model = eg.GM(beta=200.0, sigma2_gm=0.05) + eg.WN(sigma2=0.02)
    s2, src = white_share(model, FS)
    assert s2 == pytest.approx(0.02 + 0.0656517, rel=1e-6)
    assert src == ("GM", "WN")
    t = ieee_table(_stub(model, "deg/s"))
    n = t["N"].native
    assert n == pytest.approx(math.sqrt(0.0856517 / FS), rel=1e-6)
    assert "GM" in t["N"].note
    # the model's own Allan variance at T = 10 s (WV at 2000 samples) is N^2 / T
    avar = 2.0 * model.wv(np.array([2000.0]), FS)[0]
    assert math.sqrt(avar * 10.0) == pytest.approx(n, rel=2e-3)
    # a GM slower than one sample is not white noise: no N without WN
    slow = eg.GM(beta=0.5, sigma2_gm=0.05) + eg.RW(gamma2=1e-8)
    assert white_share(slow, FS) == (pytest.approx(math.nan, nan_ok=True), ())
    assert "N" not in ieee_table(_stub(slow, "deg/s"))


def test_a_wn_at_zero_beside_a_disguised_gm_still_gives_n_with_interval():
    # the ADIS case: WN fitted at 0, the noise density carried by a sub-sample GM
    model = eg.GM(beta=200.0, sigma2_gm=0.05) + eg.WN(sigma2=0.02) + eg.RW(gamma2=1e-8)
    x = model.simulate(2**16, rng=np.random.default_rng(3), fs=FS)
    res = eg.fit_gmwm(eg.wavelet_variance(x, fs=FS, unit="deg/s"), "GM+WN+RW")
    n = res.ieee["N"]
    true_n = math.sqrt((0.02 + 0.0656517) / FS) * 60.0  # deg/sqrt(h)
    assert n.has_interval and n.datasheet_low < n.datasheet_value < n.datasheet_high
    assert n.datasheet_value == pytest.approx(true_n, rel=0.02)


def test_fit_carries_the_table_in_json_and_summary():
    spec = eg.inference.parse_datasheet("arw=0.3 deg/sqrt(h), rrw=3 deg/h/sqrt(h)")
    x = spec.model(FS, "deg/s").simulate(2**15, rng=np.random.default_rng(1), fs=FS)
    res = eg.fit_gmwm(eg.wavelet_variance(x, fs=FS, unit="deg/s"), "WN+RW")
    d = res.to_dict()["ieee"]
    assert list(d) == ["N", "B", "ADEV_min", "ADEV_data", "K"]
    for e in d.values():
        assert {"value", "low", "high", "unit", "datasheet_value", "datasheet_unit"} <= set(e)
    assert d["N"]["datasheet_unit"] == "deg/sqrt(h)"
    assert d["N"]["datasheet_value"] == pytest.approx(0.3, rel=0.03)
    assert d["ADEV_data"]["interval"].startswith("chi-square")
    assert "angle random walk" in str(res.summary())


def test_adev_data_is_the_empirical_minimum_with_its_wv_interval():
    x = eg.WN(sigma2=0.1).simulate(2**14, rng=np.random.default_rng(5), fs=FS)
    wv = eg.wavelet_variance(x, fs=FS, unit="deg/s")
    res = eg.fit_gmwm(wv, "WN")
    q = res.ieee["ADEV_data"]
    j = int(np.argmin(wv.variance))
    assert q.native == pytest.approx(math.sqrt(2 * wv.variance[j]))
    assert q.tau_s == pytest.approx(wv.tau_s[j] / 2)
    deg = math.pi / 180
    assert q.low == pytest.approx(math.sqrt(2 * wv.ci_low[j]) * deg)
    assert q.high == pytest.approx(math.sqrt(2 * wv.ci_high[j]) * deg)


def test_n_and_k_intervals_cover_the_truth_monte_carlo():
    # 200 WN+RW logs of 2^14 samples at 100 Hz: the 95 % delta-method intervals of N and K
    # cover the truth in 95 % of them; the binomial 99.9 % band for 200 draws at p = 0.95 is
    # [0.895, 0.99] (so a correct interval fails this test once in about a thousand runs).
    true = eg.WN(sigma2=0.1) + eg.RW(gamma2=1e-6)
    n_true, k_true = math.sqrt(0.1 / FS), math.sqrt(1e-6 * FS)
    rng = np.random.default_rng(2024)
    hit_n = hit_k = 0
    reps = 200
    for _ in range(reps):
        x = true.simulate(2**14, rng=rng, fs=FS)
        t = eg.fit_gmwm(eg.wavelet_variance(x, fs=FS, unit="deg/s"), "WN+RW").ieee
        hit_n += t["N"].low <= n_true * math.pi / 180 <= t["N"].high
        hit_k += t["K"].low <= k_true * math.pi / 180 <= t["K"].high
    assert 0.895 <= hit_n / reps <= 0.99, hit_n
    assert 0.895 <= hit_k / reps <= 0.99, hit_k


@pytest.fixture(scope="module")
def gyro_log(tmp_path_factory):
    """A deg/s gyroscope log whose white noise comes through a sensor filter (a GM of 0.5
    samples: ARW sqrt(0.0656517 / 100) x 60 = 1.537 deg/sqrt(h)) plus a random walk."""
    from engine.io import save_log

    path = tmp_path_factory.mktemp("ieee") / "gyro.h5"
    m = eg.GM(beta=200.0, sigma2_gm=0.05) + eg.RW(gamma2=1e-8)
    save_log(path, {"gyro_x": m.simulate(2**15, fs=FS, rng=7)}, FS, units={"gyro_x": "deg/s"})
    return path


ARW_TRUE = math.sqrt(0.0656517 / FS) * 60.0


def test_cli_fit_select_report_json_carry_ieee(gyro_log, tmp_path, capsys):
    import json

    from engine.cli import main

    keys = {"value", "low", "high", "unit", "datasheet_value", "datasheet_unit"}
    assert main(["fit", str(gyro_log), "--model", "GM+QN", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    n = d["ieee"]["N"]
    assert keys <= set(n) and n["datasheet_unit"] == "deg/sqrt(h)"
    assert n["datasheet_value"] == pytest.approx(ARW_TRUE, rel=0.05)
    assert main(["select", str(gyro_log), "--models", "GM+QN,GM+WN+RW", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    # the IEEE quantities of the model the command selects (the one a user can act on: a
    # disguised GM is folded into WN there, docs/selection.md), not of the first row as such
    assert d["ieee_model"] == d["selected"]["model"]
    assert d["ieee"]["N"]["datasheet_value"] == pytest.approx(ARW_TRUE, rel=0.05)
    out = tmp_path / "r.html"
    assert main(["report", str(gyro_log), "-o", str(out), "--model", "GM+RW", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    e = d["channels"]["gyro_x"]["ieee"]
    assert keys <= set(e["N"]) and e["N"]["datasheet_value"] == pytest.approx(ARW_TRUE, rel=0.05)
    assert {"B", "ADEV_min", "ADEV_data", "K"} <= set(e)
    page = out.read_text()
    # the report's IEEE table and the -1/2 guide through N (no WN term in the model)
    assert '<table class="ieee" data-channel="gyro_x">' in page
    assert "angle random walk" in page and "WN slope -0.5: N = " in page


def test_a_minimum_at_the_edge_is_only_an_upper_bound():
    # white noise alone: the ADEV falls at every averaging time, its minimum is at the longest
    t = ieee_table(_stub(eg.parse_model("WN(sigma2=0.1)"), "deg/s"))
    for key in ("B", "ADEV_min", "ADEV_data"):
        assert t[key].upper_bound, key
    assert "no floor" in t["B"].note
    # with a random walk the floor is inside the scales
    t = ieee_table(_stub(eg.WN(sigma2=0.1) + eg.RW(gamma2=1e-8), "deg/s"))
    assert not t["B"].upper_bound and not t["ADEV_min"].upper_bound
