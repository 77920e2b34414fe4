"""``gmwm batch ... -o DIR --export FORMAT``: one filter file for the whole fleet.

The file is ``DIR/fleet.<suffix>``: per axis the largest N and K of the units' own default
exports (``engine.batch.export_fleet``; tests/engine/test_fleet_file.py checks its bound), and
``gmwm check`` reads it back. A format it cannot write for a fleet (a Gauss-Markov bias, a
report) and ``--export`` without ``-o`` are refused in one line before any fit.
"""

from __future__ import annotations

import pytest
import yaml

import engine as eg
from engine.cli import main
from engine.formats import FORMATS


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.real_data
def test_batch_writes_the_fleet_file_and_check_reads_it(real_data, tmp_path, capsys):
    logs = [str(real_data / f"adis16405_imu{i}.h5") for i in (1, 4)]
    out = tmp_path / "fleet"
    code, text, err = run(
        capsys, "batch", *logs, "--model", "WN+RW", "--channels", "gyro_x,accel_x",
        "-o", str(out), "--export", "kalibr", "--quiet",
    )  # fmt: skip
    assert code == 0, err
    assert f"the fleet kalibr file {out / 'fleet.yaml'}" in text
    fleet = yaml.safe_load((out / "fleet.yaml").read_text())
    own = []
    for path in logs:
        log = eg.load_log(path)
        fits = {ch: eg.fit_gmwm(log.wavelet_variance(ch), "WN+RW") for ch in ("gyro_x", "accel_x")}
        own.append(yaml.safe_load(eg.export(None, fits, "kalibr", log=log)))
    for key in (
        "gyroscope_noise_density",
        "gyroscope_random_walk",
        "accelerometer_noise_density",
        "accelerometer_random_walk",
    ):
        assert fleet[key] == pytest.approx(max(o[key] for o in own), rel=1e-9), key
    # unit 4 sets the accelerometer random walk (x1.9 unit 1's)
    assert fleet["accelerometer_random_walk"] == pytest.approx(
        own[1]["accelerometer_random_walk"], rel=1e-9
    )
    code, text, err = run(
        capsys, "check", logs[0], "--channel", "accel_x",
        "--datasheet-file", str(out / "fleet.yaml"),
    )  # fmt: skip
    assert code == 0, err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--export", "kalibr"], "--export FORMAT writes the fleet file into -o DIR"),
        (["-o", "DIR", "--export", "kf-gins"], "--export takes a filter format whose bias"),
        (["-o", "DIR", "--export", "json"], "--export takes a filter format whose bias"),
    ],
)
def test_batch_export_refuses_before_any_fit(tmp_path, capsys, extra, message):
    extra = [str(tmp_path / "out") if a == "DIR" else a for a in extra]
    code, _, err = run(
        capsys, "batch", str(tmp_path / "missing.h5"), "--model", "WN+RW",
        "--report" if "-o" not in extra else "--quiet",
        *([str(tmp_path / "r.html")] if "-o" not in extra else []), *extra,
    )  # fmt: skip
    assert code == 2
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "out" / "summary.json").exists()


def test_batch_export_reads_the_logs_without_the_warmup_it_dropped(tmp_path, capsys):
    """``--drop-warmup`` fits each log after its warm-up; the fleet file's tail factors read
    that signal too (engine.batch.LogFit.prepared). Two simulated units, gyro_x with a
    warm-up of 10 white-noise SDs (1e-2 rad/s, 60 s) on a white noise of N = 1e-4
    rad/s/sqrt(Hz): the file's gyroscope density is the planted one within 3 % (the raw
    logs' tails made it x1.36; tests/engine/test_fleet_file.py)."""
    import numpy as np

    n, fs = 2**17, 100.0
    t = np.arange(n) / fs
    paths = []
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        gyro = eg.parse_model("WN(1e-6) + RW(1e-12)").simulate(n, rng=rng)
        accel = eg.parse_model("WN(1e-4) + RW(1e-9)").simulate(n, rng=rng)
        path = tmp_path / f"unit{seed}.h5"
        eg.io.save_log(
            path, {"gyro_x": gyro + 1e-2 * np.exp(-t / 60.0), "accel_x": accel}, fs,
            units={"gyro_x": "rad/s", "accel_x": "m/s^2"},
        )  # fmt: skip
        paths.append(str(path))
    out = tmp_path / "fleet"
    code, _, err = run(
        capsys, "batch", *paths, "--model", "WN+RW", "--channels", "gyro_x,accel_x",
        "--drop-warmup", "-o", str(out), "--export", "kalibr", "--quiet",
    )  # fmt: skip
    assert code == 0, err
    fleet = yaml.safe_load((out / "fleet.yaml").read_text())
    assert fleet["gyroscope_noise_density"] == pytest.approx(1e-4, rel=0.03)


def test_the_help_lists_the_formats_whose_record_takes_a_fleet(capsys):
    # gmwm batch --export's help reads Format.fleet_file (gmwm export's per-format list too:
    # tests/engine/test_format_records.py)
    fleet = [n for n, f in FORMATS.items() if f.fleet_file]
    assert "kalibr" in fleet and "gazebo" not in fleet
    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"overconfident ({', '.join(fleet)}; docs/filters.md" in text
