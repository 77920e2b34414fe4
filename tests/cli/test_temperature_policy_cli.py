"""Every `gmwm` path that fits a log takes --temperature as `gmwm fit` does (one rule,
engine.inference.temperature.fit_log_temperature): the multivariate fit of several channels
(--channels) fits and takes out each channel's bias-temperature relation, and a log of a batch
folder resumed from an earlier run keeps what temperature did to it in its status."""

from __future__ import annotations

import json

import numpy as np
import pytest

import engine as eg
from engine.batch import BATCH_RECORD
from engine.cli import main
from engine.inference.temperature import fit_log_temperature
from engine.multivariate import MultiModel, fit_mgmwm
from engine.wv import wv_matrix

FS = 100.0
N = 100_000
SPEC = "WN(sigma2=1e-4)+RW(gamma2=1e-10)"  # (deg/s)^2
PLANTED = {"gyro_x": 2e-3, "gyro_y": -1e-3}  # deg/s per degC: 7.2 and -3.6 deg/h per degC


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def thermal(tmp_path_factory):
    """Two gyro channels with the planted sensitivities under a warm-up of 25 to 35 degC with
    a 2 degC cycle of 300 s, and the temperature beside them (HDF5, deg/s)."""
    path = tmp_path_factory.mktemp("tpolicy") / "thermal.h5"
    t = np.arange(N) / FS
    temp = 25 + 10 * (1 - np.exp(-t / 200)) + 2 * np.sin(2 * np.pi * t / 300)
    m = eg.parse_model(SPEC)
    chans = {
        c: m.simulate(N, fs=FS, rng=11 + k) + s * temp for k, (c, s) in enumerate(PLANTED.items())
    }
    chans["temperature"] = temp
    eg.io.save_log(
        path, chans, FS, units={"gyro_x": "deg/s", "gyro_y": "deg/s", "temperature": "degC"}
    )
    return path


def _rw(d, ch):
    return next(p["value"] for p in d["params"] if p["full_name"] == f"{ch}.RW.gamma2")


def _diag(d, k):
    return np.array([v[k][k] for v in d["wv_matrix"]["values"]])


def test_channels_fit_is_of_the_compensated_signals(thermal, capsys):
    """`gmwm fit --channels` with a temperature channel beside them: each channel's planted
    sensitivity is inside its 95 % interval (7.2 and -3.6 deg/h/degC; the interval covers the
    truth in 97.5 % of 200 logs, docs/qualify.md), said in one stderr line each; the WVs of the
    multivariate fit are those of the compensated signals (the single-channel fit's
    TemperatureFit.wv), and the RW, inflated 2.9x (gyro_y) and 7.3x (gyro_x) without
    compensation on this log, comes back within a factor 2 of the true 1e-10 (deg/s)^2. As the
    single-channel fit does, the fit of the raw signals comes beside it (JSON ``fit_raw``, the
    numbers of `--temperature none`, where it is null; the text's "without compensation: ...").
    Before, the raw signals were fitted and the JSON had no key ``temperature``; then no raw
    fit was given beside the compensated one."""
    chans = "gyro_x,gyro_y"
    code, out, err = run(capsys, "fit", thermal, "--model", "WN+RW", "--channels", chans, "--json")
    assert code == 0, err
    d = json.loads(out)
    lines = [ln for ln in err.splitlines() if "temperature sensitivity" in ln]
    assert [ln.split(":")[1].strip() for ln in lines] == ["gyro_x", "gyro_y"]
    log = eg.load_log(thermal)
    for k, (ch, c) in enumerate(PLANTED.items()):
        t = d["temperature"][ch]
        lo, hi = t["sensitivity_interval"]
        assert t["compensated"] is True and t["sensitivity_unit"] == "deg/h/degC"
        assert lo < c * 3600 < hi, (ch, lo, hi)
        want = fit_log_temperature(log, ch, "auto").wv.variance
        np.testing.assert_allclose(_diag(d, k), want, rtol=1e-12)
        raw = log.wavelet_variance(ch).variance
        assert not np.allclose(_diag(d, k), raw, rtol=1e-3)
    code, out, _ = run(
        capsys, "fit", thermal, "--model", "WN+RW", "--channels", chans, "--json",
        "--temperature", "none",
    )  # fmt: skip
    raw = json.loads(out)
    assert code == 0 and raw["temperature"] is None and raw["fit_raw"] is None
    for ch in PLANTED:
        assert 0.5e-10 < _rw(d, ch) < 2e-10, (ch, _rw(d, ch))
        assert _rw(raw, ch) > 2 * _rw(d, ch), (ch, _rw(raw, ch), _rw(d, ch))
    # as the single-channel fit: the raw signals' fit beside the compensated one
    assert [p["value"] for p in d["fit_raw"]["params"]] == [p["value"] for p in raw["params"]]
    # the readable text says the same, and names the compensated channels
    code, out, _ = run(capsys, "fit", thermal, "--model", "WN+RW", "--channels", chans)
    assert code == 0 and out.count("temperature sensitivity") == 2
    line = next(ln for ln in out.splitlines() if "without compensation" in ln)
    assert "the fit above is of the temperature-compensated gyro_x, gyro_y" in line
    assert f"gyro_x: WN(sigma2={raw['params'][0]['value']!r}" in line


def test_channels_fit_follows_auto_and_a_named_channel(thermal, capsys, tmp_path):
    """The same rule as the single-channel fit: with ``auto`` a channel whose sensitivity the
    data cannot tell from 0 is left raw (a flat gyro_z next to a planted gyro_x), a channel
    named is always compensated; the decision is TemperatureFit.applied's."""
    log = eg.load_log(thermal)
    rng = np.random.default_rng(4)
    flat = eg.parse_model(SPEC).simulate(N, fs=FS, rng=rng)
    eg.io.save_log(
        tmp_path / "z.h5",
        {"gyro_x": log["gyro_x"], "gyro_z": flat, "temperature": log["temperature"]},
        FS,
        units={"gyro_x": "deg/s", "gyro_z": "deg/s", "temperature": "degC"},
    )
    argv = ["fit", tmp_path / "z.h5", "--model", "WN+RW", "--channels", "gyro_x,gyro_z", "--json"]
    code, out, err = run(capsys, *argv)
    d = json.loads(out)
    assert code == 0 and d["temperature"]["gyro_x"]["compensated"] is True
    z = d["temperature"]["gyro_z"]
    assert z["compensated"] is False and z["p_value"] > 0.05, z
    assert "not compensated (name it, --temperature temperature" in err
    np.testing.assert_allclose(_diag(d, 1), eg.wavelet_variance(flat, fs=FS).variance, rtol=1e-12)
    code, out, _ = run(capsys, *argv, "--temperature", "temperature")
    named = json.loads(out)
    assert code == 0 and named["temperature"]["gyro_z"]["compensated"] is True
    assert named["temperature"]["gyro_z"]["sensitivity"] == z["sensitivity"]
    assert not np.allclose(_diag(named, 1), _diag(d, 1), rtol=1e-6)


def test_batch_folder_resumed_keeps_the_temperature_status(thermal, capsys, tmp_path):
    """A second `gmwm batch -o DIR` resumes the log (not fitted again) and its status still
    says what temperature did (sensitivity, compensated, p-value, its stderr line); before, a
    resumed log's status had ``temperature: null``. A folder recorded before the status was
    kept (no ``temperature`` in its record) is fitted again, not resumed without it."""
    argv = ["batch", thermal, "--model", "WN+RW", "-o", tmp_path / "b", "--quiet", "--json"]
    code, out, err1 = run(capsys, *argv, "--workers", "1")
    assert code == 0
    (first,) = json.loads(out)["logs"]
    assert not first["resumed"] and set(first["temperature"]) == set(PLANTED)
    code, out, err2 = run(capsys, *argv, "--workers", "1")
    (again,) = json.loads(out)["logs"]
    assert code == 0 and again["resumed"]
    assert again["temperature"] == first["temperature"]
    assert again["temperature"]["gyro_x"]["compensated"] is True
    lines = [ln for ln in err2.splitlines() if "temperature sensitivity" in ln]
    assert lines == [ln for ln in err1.splitlines() if "temperature sensitivity" in ln]
    assert len(lines) == 2
    rec_path = tmp_path / "b" / BATCH_RECORD
    rec = json.loads(rec_path.read_text())
    for unit in rec["units"].values():
        del unit["temperature"]
    rec_path.write_text(json.dumps(rec))
    code, out, _ = run(capsys, *argv, "--workers", "1")
    (old,) = json.loads(out)["logs"]
    assert code == 0 and not old["resumed"] and old["temperature"] == first["temperature"]


def test_channels_fit_of_a_real_log_without_temperature_is_unchanged(capsys, real_data):
    """ADIS16405 imu1 has no temperature channel: `gmwm fit --channels` fits the raw signals
    exactly as before (the same numbers as wv_matrix + fit_mgmwm of the log, bit for bit), says
    nothing of temperature and its JSON ``temperature`` is null."""
    path = real_data / "adis16405_imu1.h5"
    chans = ["gyro_x", "gyro_y"]
    code, out, err = run(
        capsys, "fit", path, "--model", "WN+RW", "--channels", ",".join(chans), "--json"
    )
    assert code == 0 and "temperature" not in err
    d = json.loads(out)
    assert d["temperature"] is None
    log = eg.load_log(path)
    want = fit_mgmwm(wv_matrix(log, channels=chans), MultiModel(chans, "WN+RW"), weights="ci")
    assert [p["value"] for p in d["params"]] == [float(v) for v in want.params.values()]
