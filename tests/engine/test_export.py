"""Exports (datasheet, Kalibr imu.yaml, JSON report, CSV curves), the export CLI and sessions."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine import session as sessions
from engine.cli import main
from engine.demo import demo_path
from engine.formats import (
    BI_FACTOR,
    ExportError,
    curves_csv,
    datasheet_csv,
    datasheet_table,
    datasheet_text,
    export,
    fit_report,
    kalibr_imu,
    kalibr_models,
    read_kalibr,
    si_factor,
    write_kalibr,
)
from engine.inference import param_intervals
from engine.io.log import channel_axis
from engine.units import allan_floor

FS = 100.0
N = 200_000
DEG = math.pi / 180
# per axis: unit, WN sigma2, RW gamma2 (per sample, in the log's unit)
TRUTH = {
    "gyro_x": ("deg/s", 1e-4, 1e-9),
    "gyro_y": ("deg/s", 2e-4, 4e-9),
    "gyro_z": ("deg/s", 1.5e-4, 2e-9),
    "accel_x": ("g", 1e-6, 1e-12),
    "accel_y": ("g", 2e-6, 3e-12),
    "accel_z": ("g", 1.5e-6, 2e-12),
}


@pytest.fixture(scope="module")
def six(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A six-axis log (deg/s, g) of WN + RW per axis."""
    chans = {
        c: (eg.WN(sigma2=s2) + eg.RW(gamma2=g2)).simulate(N, fs=FS, rng=i)
        for i, (c, (_, s2, g2)) in enumerate(TRUTH.items())
    }
    return eg.io.save_log(
        tmp_path_factory.mktemp("exp") / "six.h5",
        chans,
        FS,
        units={c: u for c, (u, _, _) in TRUTH.items()},
    )


@pytest.fixture(scope="module")
def fits(six: Path) -> dict[str, eg.GMWMResult]:
    log = eg.load_log(six)
    return {
        c: eg.fit_gmwm(eg.wavelet_variance(log[c], fs=log.fs, unit=log.units[c]), "WN+RW")
        for c in log.names
    }


# ----------------------------------------------------------------------------- units
@pytest.mark.parametrize(
    ("unit", "kind", "factor"),
    [
        ("deg/s", "gyroscope", DEG),
        ("°/s", "gyroscope", DEG),
        ("rad/s", "gyroscope", 1.0),
        ("rad / s", "gyroscope", 1.0),
        ("deg/h", "gyroscope", DEG / 3600),
        ("dps", "gyroscope", DEG),
        ("g", "accelerometer", 9.80665),
        ("mg", "accelerometer", 9.80665e-3),
        ("m/s^2", "accelerometer", 1.0),
        ("m/s²", "accelerometer", 1.0),
        ("m/s2", "accelerometer", 1.0),
        ("m s^-2", "accelerometer", 1.0),
    ],
)
def test_si_factor(unit: str, kind: str, factor: float) -> None:
    k, f = si_factor(unit)
    assert k == kind and f == pytest.approx(factor, rel=1e-15)


def test_unknown_units_are_clear_errors() -> None:
    with pytest.raises(ExportError, match=r"unknown unit 'furlong/s' of channel 'gyro_x'.*deg/s"):
        si_factor("furlong/s", "gyro_x")
    with pytest.raises(ExportError, match="unit of channel 'x' is unknown.*units="):
        si_factor("", "x")


def test_channel_axis() -> None:
    assert [channel_axis(c) for c in ("gyro_x", "accel_Z", "imu/acc[1]", "gx", "temp")] == [
        "x",
        "z",
        "y",
        "x",
        "temp",
    ]


# ----------------------------------------------------------------------------- datasheet
def _row(rows, channel: str, quantity: str, unit: str):
    hit = [r for r in rows if r.channel == channel and r.quantity == quantity and r.unit == unit]
    assert len(hit) == 1, (channel, quantity, unit, [(r.quantity, r.unit) for r in rows])
    return hit[0]


def test_datasheet_formulas(fits) -> None:
    ivs = {"gyro_x": param_intervals(fits["gyro_x"])}
    rows = datasheet_table(fits, intervals=ivs)
    g, a = fits["gyro_x"], fits["accel_y"]
    s2, g2 = g.params["WN.sigma2"], g.params["RW.gamma2"]
    n_deg = math.sqrt(s2 / FS)
    assert _row(rows, "gyro_x", "white noise density", "deg/s/sqrt(Hz)").value == pytest.approx(
        n_deg, rel=1e-14
    )
    arw = _row(rows, "gyro_x", "angle random walk", "deg/sqrt(h)")
    assert arw.value == pytest.approx(60 * n_deg, rel=1e-14)
    lo, hi = next((iv.low, iv.high) for iv in ivs["gyro_x"] if iv.name == "WN.sigma2")
    assert (arw.low, arw.high) == pytest.approx(
        (60 * math.sqrt(lo / FS), 60 * math.sqrt(hi / FS)), rel=1e-12
    )
    k_deg = math.sqrt(g2 * FS)
    assert _row(rows, "gyro_x", "rate random walk", "deg/h/sqrt(h)").value == pytest.approx(
        216000 * k_deg, rel=1e-14
    )
    assert _row(rows, "gyro_x", "rate random walk (SI)", "rad/s^2/sqrt(Hz)").value == pytest.approx(
        k_deg * DEG, rel=1e-14
    )
    n_g = math.sqrt(a.params["WN.sigma2"] / FS)
    assert _row(rows, "accel_y", "velocity random walk", "m/s/sqrt(h)").value == pytest.approx(
        60 * 9.80665 * n_g, rel=1e-14
    )
    assert _row(
        rows, "accel_y", "acceleration random walk", "m/s/h/sqrt(h)"
    ).value == pytest.approx(216000 * 9.80665 * math.sqrt(a.params["RW.gamma2"] * FS), rel=1e-14)
    text = datasheet_text(rows)
    assert "angle random walk" in text and "deg/h/sqrt(h)" in text
    back = list(csv.DictReader(io.StringIO(datasheet_csv(rows))))
    assert len(back) == len(rows) and float(back[0]["value"]) == rows[0].value


def test_bias_instability_floor_of_wn_rw() -> None:
    """WN + RW: AVAR(T) ~ N^2/T + K^2 T/3, minimum 2 N K / sqrt(3) at T = sqrt(3) N / K."""
    s2, g2, fs = 1e-4, 1e-10, 200.0
    model = eg.WN(sigma2=s2) + eg.RW(gamma2=g2)
    wv = eg.WaveletVariance.from_arrays(model.wv(2.0 ** np.arange(1, 25), fs), n=2**25, fs=fs)
    res = eg.fit_gmwm(wv, "WN+RW")
    n, k = math.sqrt(s2 / fs), math.sqrt(g2 * fs)
    fl = allan_floor(res.model, res.fs, res.wv.n_levels)
    assert fl["adev_min"] == pytest.approx(math.sqrt(2 * n * k / math.sqrt(3)), rel=2e-3)
    assert fl["T_s"] == pytest.approx(math.sqrt(3) * n / k, rel=0.05)
    assert fl["bias_instability"] == pytest.approx(fl["adev_min"] / 0.6643, rel=1e-4)
    assert BI_FACTOR == pytest.approx(0.664, abs=5e-4) and not fl["at_edge"]
    wn_only = eg.fit_gmwm(
        eg.WaveletVariance.from_arrays(eg.WN(sigma2=1.0).wv(2.0 ** np.arange(1, 12)), n=4096), "WN"
    )
    assert allan_floor(wn_only.model, wn_only.fs, wn_only.wv.n_levels)["at_edge"]
    rows = datasheet_table(wn_only)
    assert "upper bound" in rows[-1].note or "upper bound" in rows[-2].note


def test_datasheet_gm_qn_dr_ar1_rows() -> None:
    m = eg.parse_model("GM(beta=0.1, sigma2_gm=4e-4)+QN(q2=1e-6)+WN(sigma2=1e-4)+DR(omega=1e-7)")
    wv = eg.WaveletVariance.from_arrays(
        m.wv(2.0 ** np.arange(1, 18), 50.0), n=2**18, fs=50.0, unit="rad/s"
    )
    res = eg.fit_gmwm(wv, m)  # starts at the truth; values need not be exact here
    rows = datasheet_table({"gyro_z": res})
    gm = res.model.processes[0]
    tc = _row(rows, "gyro_z", "correlation time", "s")
    assert tc.value == pytest.approx(1 / gm.beta)
    q = _row(rows, "gyro_z", "driving-noise PSD", "(rad/s)^2/s")
    assert q.value == pytest.approx(2 * gm.beta * gm.sigma2_gm)
    assert _row(
        rows, "gyro_z", "driving-noise density (SI)", "rad/s^2/sqrt(Hz)"
    ).value == pytest.approx(math.sqrt(q.value))
    qn = res.model.processes[1]
    assert _row(rows, "gyro_z", "quantization", "rad").value == pytest.approx(
        math.sqrt(qn.q2) / 50.0
    )
    dr = res.model.processes[3]
    assert _row(rows, "gyro_z", "rate ramp", "rad/s^2").value == pytest.approx(abs(dr.omega) * 50)
    ar = eg.fit_gmwm(
        eg.WaveletVariance.from_arrays(
            eg.AR1(phi=0.99, sigma2=1e-4).wv(2.0 ** np.arange(1, 14)), n=2**14, fs=10.0
        ),
        "AR1",
    )
    rows = datasheet_table(ar)
    phi = ar.model.processes[0].phi
    assert _row(rows, "x", "correlation time", "s").value == pytest.approx(-0.1 / math.log(phi))
    assert any(r.quantity == "units" and "no SI rows" in r.note for r in rows)


# ----------------------------------------------------------------------------- Kalibr
def test_kalibr_values_and_yaml(fits) -> None:
    k = kalibr_imu(fits, source="six.h5", rostopic="/imu0")
    n = {
        c: math.sqrt(r.params["WN.sigma2"] / FS) * (DEG if c.startswith("g") else 9.80665)
        for c, r in fits.items()
    }
    assert k.update_rate == FS
    assert k.per_axis["gyroscope_noise_density"] == {
        "x": pytest.approx(n["gyro_x"], rel=1e-15),
        "y": pytest.approx(n["gyro_y"], rel=1e-15),
        "z": pytest.approx(n["gyro_z"], rel=1e-15),
    }
    worst = max(("gyro_x", "gyro_y", "gyro_z"), key=n.get)
    assert k.values["gyroscope_noise_density"] == n[worst]
    assert k.chosen["gyroscope_noise_density"] == worst
    kr = {
        c: math.sqrt(fits[c].params["RW.gamma2"] * FS) * 9.80665
        for c in ("accel_x", "accel_y", "accel_z")
    }
    assert k.values["accelerometer_random_walk"] == pytest.approx(max(kr.values()), rel=1e-15)
    text = k.to_yaml()
    assert f"# from {worst}" in text and "max over axes" in text and "update_rate: 100.0" in text
    assert "e-" in text and not any(tok.startswith("1e") for tok in text.split())
    yaml = pytest.importorskip("yaml")  # Kalibr reads the file with PyYAML (YAML 1.1)
    y = yaml.safe_load(text)
    for key in (
        "gyroscope_noise_density",
        "gyroscope_random_walk",
        "accelerometer_noise_density",
        "accelerometer_random_walk",
        "update_rate",
    ):
        assert isinstance(y[key], float)
    assert y == read_kalibr(text)


def test_kalibr_round_trip_simulate_refit(fits, tmp_path: Path) -> None:
    """Export -> parse -> simulate the sensor from the file -> refit: the file's numbers back,
    within Monte Carlo tolerance (observed spread over 6 seeds x 6 axes: N 0.4 %, K 12 %)."""
    path = write_kalibr(tmp_path / "imu.yaml", fits)
    d = read_kalibr(path)
    models = kalibr_models(path, per_axis=True)
    assert set(models) == {f"{s}_{a}" for s in ("gyroscope", "accelerometer") for a in "xyz"}
    # exact conversion: the SI model is the fitted one times the unit factor squared
    for ch, res in fits.items():
        f = DEG if ch.startswith("gyro") else 9.80665
        m = models[f"{'gyroscope' if ch.startswith('gyro') else 'accelerometer'}_{ch[-1]}"]
        vals = m.values()
        assert vals["WN.sigma2"] == pytest.approx(res.params["WN.sigma2"] * f * f, rel=1e-12)
        assert vals["RW.gamma2"] == pytest.approx(res.params["RW.gamma2"] * f * f, rel=1e-12)
    for i, (name, m) in enumerate(sorted(models.items())):
        x = m.simulate(N, fs=d["update_rate"], rng=500 + i)
        r = eg.fit_gmwm(eg.wavelet_variance(x, fs=d["update_rate"]), "WN+RW")
        sensor, ax = name.split("_")
        n_hat = math.sqrt(r.params["WN.sigma2"] / d["update_rate"])
        k_hat = math.sqrt(r.params["RW.gamma2"] * d["update_rate"])
        assert n_hat == pytest.approx(d[f"{sensor}_noise_density_per_axis"][ax], rel=0.02)
        assert k_hat == pytest.approx(d[f"{sensor}_random_walk_per_axis"][ax], rel=0.3)
    cons = kalibr_models(path)
    assert cons["gyroscope"].values()["WN.sigma2"] == pytest.approx(
        d["gyroscope_noise_density"] ** 2 * FS, rel=1e-15
    )


def test_kalibr_errors_and_fallbacks(fits) -> None:
    gyro = {c: r for c, r in fits.items() if c.startswith("gyro")}
    with pytest.raises(ExportError, match=r"only gyroscope.*allow_partial=True\)"):
        kalibr_imu(gyro)  # the engine names its argument; the CLI says --partial (test_cli)
    part = kalibr_imu(gyro, allow_partial=True)
    assert "accelerometer_noise_density" not in part.values
    with pytest.raises(ExportError, match="unknown unit 'furlong'"):
        kalibr_imu(fits, units={"gyro_x": "furlong"})
    wv = fits["gyro_x"].wv
    with pytest.raises(ExportError, match="no WN term"):
        kalibr_imu({**fits, "gyro_x": eg.fit_gmwm(wv, "RW")})
    with pytest.raises(ExportError, match="neither RW nor GM"):
        kalibr_imu({**fits, "gyro_x": eg.fit_gmwm(wv, "WN")})
    gm = kalibr_imu({**fits, "gyro_x": eg.fit_gmwm(wv, "GM+WN")})
    assert gm.warnings and "driving noise" in gm.sources["gyroscope_random_walk[x]"]
    with pytest.raises(ExportError, match="two gyroscope channels map to axis 'x'"):
        kalibr_imu({"gyro_x": fits["gyro_x"], "gx": fits["gyro_x"], **fits})
    slow = eg.fit_gmwm(
        eg.WaveletVariance.from_arrays(wv.variance, n=wv.n, fs=50.0, unit="deg/s"), "WN+RW"
    )
    with pytest.raises(ExportError, match="different sampling frequencies"):
        kalibr_imu({**fits, "gyro_x": slow})
    with pytest.raises(ExportError, match="update_rate"):
        kalibr_models("gyroscope_noise_density: 1.0e-3\n")
    with pytest.raises(ExportError, match="not a non-negative number"):
        kalibr_models(
            "update_rate: 100\ngyroscope_noise_density: abc\ngyroscope_random_walk: 1.0\n"
        )
    with pytest.raises(ExportError, match="not 'key: value'"):
        read_kalibr("update_rate 100\n")


def test_read_kalibr_original_layout() -> None:
    text = (
        "#Accelerometers\naccelerometer_noise_density: 1.86e-03   #Noise density\n"
        "accelerometer_random_walk: 4.33e-04\n\n#Gyroscopes\n"
        "gyroscope_noise_density: 1.87e-04\ngyroscope_random_walk: 2.66e-05\n"
        "rostopic: /imu0\nupdate_rate: 200.0\nT_i_b:\n  - [1.0, 0.0]\n  - [0.0, 1.0]\n"
    )
    d = read_kalibr(text)
    assert d["gyroscope_random_walk"] == 2.66e-05 and d["rostopic"] == "/imu0"
    m = kalibr_models(d)
    assert m["accelerometer"].values()["RW.gamma2"] == pytest.approx(4.33e-04**2 / 200)


# ----------------------------------------------------------------------------- report, CSV
def test_json_report(fits, six: Path) -> None:
    log = eg.load_log(six)
    ivs = {"gyro_x": param_intervals(fits["gyro_x"])}
    rep = fit_report(fits, intervals=ivs, log=log)
    text = json.dumps(rep, allow_nan=False)
    back = json.loads(text)
    assert back["schema"] == "gmwm-report/1" and set(back["channels"]) == set(TRUTH)
    gx = back["channels"]["gyro_x"]
    assert gx["sensor"] == "gyroscope" and gx["axis"] == "x" and gx["unit"] == "deg/s"
    assert gx["intervals"][0]["name"] == "WN.sigma2" and gx["datasheet"]
    assert gx["fit"]["params"][0]["value"] == fits["gyro_x"].params["WN.sigma2"]
    assert back["channels"]["gyro_y"]["intervals"] is None
    assert back["log"]["fs"] == FS and back["kalibr"]["update_rate"] == FS


def test_curves_csv(fits) -> None:
    text = curves_csv(fits)
    rows = list(csv.DictReader(io.StringIO(text)))
    # the documented header (curves_csv's docstring): the WV columns, one column per process of
    # the model (WN+RW here), the unit
    header = "channel level tau_samples tau_s wv ci_low ci_high implied WN RW wv_unit"
    assert list(rows[0]) == header.split()
    assert len(rows) == sum(r.wv.n_levels for r in fits.values())
    r0 = fits["gyro_x"]
    first = rows[0]
    assert float(first["wv"]) == r0.wv.variance[0]  # 17 digits: exact
    assert float(first["implied"]) == pytest.approx(
        float(first["WN"]) + float(first["RW"]), rel=1e-14
    )
    assert first["wv_unit"] == "(deg/s)^2"
    mixed = {"a": r0, "b": eg.fit_gmwm(r0.wv, "QN+WN")}
    rows = list(csv.DictReader(io.StringIO(curves_csv(mixed))))
    assert "QN" in rows[0] and rows[0]["QN"] == "" and rows[-1]["RW"] == ""


def test_export_dispatch(fits, tmp_path: Path) -> None:
    for fmt in ("kalibr", "json", "csv", "datasheet", "datasheet-csv"):
        text = export(tmp_path / f"o.{fmt}", fits, fmt)
        assert (tmp_path / f"o.{fmt}").read_text() == text and text
    with pytest.raises(ExportError, match="unknown export format"):
        export(None, fits, "xml")


# ----------------------------------------------------------------------------- CLI
def export_wn_rw(log: Path, *args: str) -> int:
    """Exit code of ``gmwm export LOG --model WN+RW ARGS...``."""
    return main(["export", str(log), "--model", "WN+RW", *args])


def test_cli_export(six: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "imu.yaml"
    assert export_wn_rw(six, "--format", "kalibr", "-o", str(out), "--rostopic", "/imu/data") == 0
    assert "wrote kalibr export of 6 channel(s)" in capsys.readouterr().out
    d = read_kalibr(out)
    assert d["rostopic"] == "/imu/data" and d["update_rate"] == FS
    args = ["--model-for", "gyro_x=GM+WN+RW", "--channels", "gyro_x,accel_x", "--format", "json"]
    assert export_wn_rw(six, *args, "-o", "-", "--ci", "asymptotic") == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["channels"]["gyro_x"]["fit"]["model"] == "GM+WN+RW"
    assert rep["channels"]["accel_x"]["intervals"]
    assert export_wn_rw(six, "--format", "csv", "-o", str(tmp_path / "c.csv"), "--json") == 0
    assert json.loads(capsys.readouterr().out)["format"] == "csv"
    bad = [
        (["--channels", "gyro_x"], "only gyroscope"),
        (["--model-for", "mag=WN"], "unknown channel"),
        (["--model-for", "nonsense"], "CH=SPEC"),
        (["--units", "gyro_x=furlong"], "furlong"),
        (["--model", "WN+XX"], "unknown process"),
    ]
    for extra, frag in bad:
        assert export_wn_rw(six, "-o", "-", *extra) == 2, extra
        err = capsys.readouterr().err
        assert frag in err and err.count("\n") == 1, (extra, err)


def test_cli_export_counts_with_scale(tmp_path: Path, capsys) -> None:
    rng = np.random.default_rng(3)
    counts = {
        c: np.round(rng.normal(0, 40, 50_000)).astype(np.int16)
        for c in ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
    }
    p = eg.io.save_log(tmp_path / "counts.h5", counts, 100.0)
    argv = [
        "export",
        str(p),
        "--model",
        "WN+RW",
        "-o",
        "-",
        "--scale",
        "gyro_x=0.05,gyro_y=0.05,gyro_z=0.05,accel_x=0.00333,accel_y=0.00333,accel_z=0.00333",
        "--units",
        "gyro_x=deg/s,gyro_y=deg/s,gyro_z=deg/s,accel_x=g,accel_y=g,accel_z=g",
    ]
    assert main(argv) == 0
    d = read_kalibr(capsys.readouterr().out)
    n = math.sqrt(np.var(counts["gyro_x"] * 0.05) / 100.0) * DEG
    assert d["gyroscope_noise_density_per_axis"]["x"] == pytest.approx(n, rel=0.05)


# ----------------------------------------------------------------------------- sessions
def test_session_round_trip(fits, six: Path, tmp_path: Path) -> None:
    ivs = {"gyro_x": param_intervals(fits["gyro_x"])}
    robust = eg.wavelet_variance(eg.load_log(six)["gyro_y"], fs=FS, robust=True, unit="deg/s")
    p = sessions.save_session(
        tmp_path / "s.json",
        data_path=six,
        load={"segment": (0, 5000)},
        models={"gyro_x": "WN+RW", "gyro_y": eg.parse_model("GM+WN")},
        wvs={"gyro_y": robust},
        fits=fits,
        intervals=ivs,
        app={"channel": "gyro_x", "log_axes": True},
    )
    s = sessions.load_session(p)
    assert s.data_path == str(six) and s.load == {"segment": (0, 5000)}
    assert s.models == {"gyro_x": "WN+RW", "gyro_y": "GM+WN"} and s.app["log_axes"] is True
    for c, r in fits.items():
        got = s.fits[c]
        assert got.params == r.params and got.objective == r.objective
        np.testing.assert_array_equal(got.implied, r.implied)
        np.testing.assert_array_equal(got.wv.variance, r.wv.variance)
        np.testing.assert_array_equal(got.omega, r.omega)
        assert got.summary() == r.summary().replace(
            f"{1e3 * r.elapsed_s:.1f} ms", f"{1e3 * got.elapsed_s:.1f} ms"
        )
    np.testing.assert_array_equal(s.wvs["gyro_y"].variance, robust.variance)
    np.testing.assert_array_equal(s.wvs["gyro_y"].classical.variance, robust.classical.variance)
    assert [iv.to_dict() for iv in s.intervals["gyro_x"]] == [iv.to_dict() for iv in ivs["gyro_x"]]
    assert s.data_changed() is None and s.reload_log().n == 5000
    text = sessions.session_to_json(
        data_path=six, fits={"gyro_z": fits["gyro_z"]}, fingerprint=False
    )
    up = sessions.session_from_json(text.encode())  # an uploaded file, no path on the server
    assert up.fits["gyro_z"].params == fits["gyro_z"].params and up.fingerprint is None
    assert (
        sessions.result_from_dict(sessions.result_to_dict(fits["gyro_z"])).params
        == fits["gyro_z"].params
    )
    assert sessions.result_from_dict(fits["gyro_z"].to_dict()).params == fits["gyro_z"].params


def test_session_detects_changed_data_and_bad_files(fits, tmp_path: Path) -> None:
    data = tmp_path / "d.csv"
    data.write_text("x\n" + "\n".join(str(v) for v in range(10)))
    fp = sessions.file_fingerprint(data)
    p = sessions.save_session(tmp_path / "s.json", data_path=data, fits={"x": fits["gyro_x"]})
    data.write_text("x\n" + "\n".join(str(v) for v in range(11)))
    s = sessions.load_session(p)
    assert (
        "changed size" in s.data_changed() and fp["size"] != sessions.file_fingerprint(data)["size"]
    )
    with pytest.raises(sessions.SessionError, match="changed"):
        s.reload_log()
    assert s.reload_log(check=False).n == 11
    with pytest.raises(sessions.SessionError, match="not load_log arguments"):
        sessions.save_session(tmp_path / "x.json", data_path=data, load={"nonsense": 1})
    with pytest.raises(sessions.SessionError, match="JSON"):
        sessions.save_session(tmp_path / "x.json", data_path=data, app={"f": object()})
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(sessions.SessionError, match="cannot read"):
        sessions.load_session(tmp_path / "bad.json")
    (tmp_path / "other.json").write_text('{"schema": "other"}')
    with pytest.raises(sessions.SessionError, match="not a GMWM session"):
        sessions.load_session(tmp_path / "other.json")
    doc = json.loads(p.read_text())
    doc["channels"]["x"]["fit"]["model_values"] = "WN+RW"
    (tmp_path / "unset.json").write_text(json.dumps(doc))
    with pytest.raises(sessions.SessionError, match="channel 'x'.*unset values"):
        sessions.load_session(tmp_path / "unset.json")


# ---------------------------------------------- one datasheet table for fit and export
DEMO = demo_path()  # the bundled demo log (package data: always there)


@pytest.mark.parametrize(
    "channel, spec",
    [("gyro_x", "2*GM+WN+RW"), ("accel_x", "QN+WN+RW+DR")],
)
def test_fit_and_export_datasheet_print_the_same_names_and_units(capsys, channel, spec):
    """`gmwm fit` (text and JSON) and `gmwm export --format datasheet` name and unit
    every quantity of every process alike (accel RW K: m/s^3/sqrt(Hz); gyro K:
    deg/s^2/sqrt(Hz); QN: m/s), with equal values."""
    assert main(["fit", str(DEMO), "--channel", channel, "--model", spec, "--json"]) == 0
    fit_rows = json.loads(capsys.readouterr().out)["datasheet"]
    assert main(["fit", str(DEMO), "--channel", channel, "--model", spec]) == 0
    fit_text = capsys.readouterr().out
    argv = ["export", str(DEMO), "--model", spec, "--channels", channel]
    assert main([*argv, "--format", "datasheet-csv", "-o", "-"]) == 0
    exp_rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert main([*argv, "--format", "datasheet", "-o", "-"]) == 0
    exp_text = capsys.readouterr().out

    def key(r):
        return (r["process"], r["quantity"], r["symbol"], r["unit"])

    exp = {key(r): float(r["value"]) for r in exp_rows if r["value"]}
    got = {key(r): r["value"] for r in fit_rows if r["value"] is not None}
    assert set(got) == set(exp) and len(got) == len(fit_rows) - sum(
        r["value"] is None for r in fit_rows
    )
    for k, v in got.items():
        assert v == pytest.approx(exp[k], rel=1e-9), k
    codes = {r["process"].split("_")[0] for r in fit_rows}
    procs = {p.code for p in eg.parse_model(spec).processes}
    assert procs <= codes and "model" in codes  # every process, and the Allan floor
    for p, q, sym, unit in got:  # the text outputs print the same rows
        assert any(
            ln.split()[:1] == [p] and f" {q} " in ln and f" {sym} " in ln and ln.endswith(unit)
            for ln in fit_text.splitlines()
        ), (p, q, sym, unit)
        assert any(
            ln.split()[1:2] == [p] and f" {q} " in ln and ln.endswith(f"  {unit}")
            for ln in exp_text.splitlines()
        ), (p, q, unit)
    units = {(sym, unit) for _p, _q, sym, unit in got}
    if channel == "accel_x":
        assert {("K", "m/s^3/sqrt(Hz)"), ("Q", "m/s"), ("R", "m/s^3")} <= units
    else:
        assert {("K", "deg/s^2/sqrt(Hz)"), ("N", "deg/s/sqrt(Hz)"), ("T_c", "s")} <= units


def test_engine_export_is_the_function_after_importing_the_package(fits) -> None:
    """``engine.export`` is the function, also once the formats package is imported."""
    import engine.formats

    assert eg.export is engine.formats.export and callable(eg.export)
    text = eg.export(None, {"gyro_x": fits["gyro_x"]}, "datasheet-csv")
    assert text == engine.formats.export(None, {"gyro_x": fits["gyro_x"]}, "datasheet-csv")
    assert text.splitlines()[0].startswith("channel,process,quantity,symbol,value")
    assert {"kalibr", "json", "csv", "datasheet", "datasheet-csv"} <= set(engine.formats.FORMATS)
    assert engine.formats.FORMATS["kalibr"].reader is engine.formats.read_kalibr
