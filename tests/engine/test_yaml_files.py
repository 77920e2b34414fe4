"""YAML files as their writers write them: the full syntax (flow maps, comments, anchors, quoted
keys, block style, ``1e-05``), OpenCV's ``%YAML:1.0`` files with ``!!opencv-matrix`` entries
(checked against ``cv2.FileStorage``, the parser VINS and ORB-SLAM3 use), every YAML writer's
own output read back, and a one-line error for a file that is not YAML."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

import engine as eg
from engine._yaml import read_yaml_mapping
from engine.cli import main
from engine.errors import DatasheetError, ExportError
from engine.formats import FORMATS, export, read_kalibr
from engine.formats.readers import read_check_file, read_filter_noise

#: A Kalibr imu.yaml in the full YAML syntax: a quoted key, an anchor and its alias, a flow map
#: over two lines, block mappings, comments after values and on their own lines, numbers with
#: and without a dot or an exponent sign.
KALIBR_FULL = """\
# IMU noise model (allan_variance_ros style)
"gyroscope_noise_density": &gn 1.6e-04   # rad/s/sqrt(Hz)
gyroscope_random_walk: 1e-05
accelerometer_noise_density: 2.0E-3
accelerometer_random_walk: 3.0e-4
gyroscope_noise_density_per_axis: {x: *gn,
                                   y: 1.5e-4, 'z': 1.7e-04}
rostopic: '/imu0'   # quoted: a '#' inside quotes is no comment
update_rate: 200
note: |
  a block scalar: key: value # not parsed
T_i_b:
  - [1.0, 0.0]
  - [0.0, 1.0]
"""


def test_kalibr_file_in_the_full_syntax_is_read() -> None:
    d = read_kalibr(KALIBR_FULL)
    assert d["gyroscope_noise_density"] == 1.6e-4  # a quoted key and an anchor
    assert d["gyroscope_random_walk"] == 1e-5  # no dot: a float, as in YAML 1.2 and OpenCV
    assert d["accelerometer_noise_density"] == 2.0e-3
    assert d["gyroscope_noise_density_per_axis"] == {"x": 1.6e-4, "y": 1.5e-4, "z": 1.7e-4}
    assert d["rostopic"] == "/imu0" and d["update_rate"] == 200
    assert d["note"] == "a block scalar: key: value # not parsed\n"
    assert d["T_i_b"] == [[1.0, 0.0], [0.0, 1.0]]
    m = eg.formats.kalibr_models(d)
    # N^2 fs = WN.sigma2 and K^2 / fs = RW.gamma2 (docs/conventions.md): the file's numbers
    assert m["gyroscope"].values()["WN.sigma2"] == pytest.approx(1.6e-4**2 * 200, rel=1e-15)
    assert m["gyroscope"].values()["RW.gamma2"] == pytest.approx(1e-5**2 / 200, rel=1e-15)


def test_kalibr_imu_chain_block_counts_as_top_level() -> None:
    chain = (
        "%YAML:1.0\nimu0:\n  T_i_b:\n    - [1.0, 0.0, 0.0, 0.0]\n"
        "  accelerometer_noise_density: 2.0000e-03\n  accelerometer_random_walk: 3.0000e-03\n"
        "  gyroscope_noise_density: 1.6968e-04\n  gyroscope_random_walk: 1.9393e-05\n"
        "  model: calibrated\n  rostopic: /imu0\n  update_rate: 200.0\n"
        "imu1:\n  gyroscope_noise_density: 9.0\n"
    )
    d = read_kalibr(chain)
    assert d["gyroscope_noise_density"] == 1.6968e-4 and d["update_rate"] == 200.0  # imu0's
    assert d["imu1"] == {"gyroscope_noise_density": 9.0}


@pytest.mark.parametrize("header", ["%YAML:1.0", "%YAML 1.2\n---"])
def test_opencv_file_with_matrices_reads_as_filestorage_reads_it(header, tmp_path) -> None:
    cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the test extra)")
    path = tmp_path / "vins.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)  # OpenCV writes the file
    fs.write("acc_n", 0.08)
    fs.write("gyr_w", 4.0e-5)
    fs.write("imu_topic", "/imu0")
    fs.write("freq", 200)
    rot = np.arange(9.0).reshape(3, 3) / 7.0
    fs.write("extrinsicRotation", rot)
    fs.write("extrinsicTranslation", np.array([[1.5e-4], [-2.0], [3.0]]))
    fs.release()
    text = path.read_text()
    first, rest = text.split("\n", 1)
    assert first.startswith("%YAML")  # 1.2 in OpenCV >= 4.x, 1.0 in the files users keep
    text = header + "\n" + rest.removeprefix("---\n")
    path.write_text(text)
    d = read_yaml_mapping(text, str(path))
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)  # the consumers' own parser
    try:
        assert fs.isOpened()
        assert d["acc_n"] == fs.getNode("acc_n").real() == 0.08
        assert d["gyr_w"] == fs.getNode("gyr_w").real() == 4.0e-5
        assert d["imu_topic"] == fs.getNode("imu_topic").string() == "/imu0"
        assert d["freq"] == int(fs.getNode("freq").real()) == 200
        np.testing.assert_array_equal(d["extrinsicRotation"], fs.getNode("extrinsicRotation").mat())
        np.testing.assert_array_equal(d["extrinsicRotation"], rot)  # rows of the matrix
        assert d["extrinsicTranslation"] == [1.5e-4, -2.0, 3.0]  # a vector: flat
    finally:
        fs.release()
    fn = read_filter_noise(text, fs=200.0)  # gmwm check reads it as a VINS file
    assert fn.fmt == "vins"
    assert fn.values["accelerometer"]["*"]["N"] == pytest.approx(0.08 / math.sqrt(200.0), 1e-15)
    assert fn.values["gyroscope"]["*"]["K"] == pytest.approx(4.0e-5 / math.sqrt(200.0), 1e-15)


def test_hand_written_settings_in_the_full_syntax_are_read() -> None:
    # ORB-SLAM3 keys quoted, a flow map, a value given through an alias; KF-GINS with a flow
    # map and integers; sensor_msgs/Imu covariances over two lines
    orb = (
        '%YAML:1.0\n"IMU.NoiseGyro": &ng 1.7e-4\nCamera1: {fx: 458.654, fy: 457.296}\n'
        "IMU.NoiseAcc: 2.0e-3\nIMU.GyroWalk: *ng\nIMU.AccWalk: 3e-03\nIMU.Frequency: 200\n"
    )
    fn = read_filter_noise(orb)
    assert fn.fmt == "orbslam3" and fn.rate == 200.0
    assert fn.values["gyroscope"]["*"] == {"N": 1.7e-4, "K": 1.7e-4}
    assert fn.values["accelerometer"]["*"] == {"N": 2.0e-3, "K": 3e-3}
    gins = (
        "imunoise: {arw: [1, 1, 1], vrw: [2, 2, 2], gbstd: [10, 10, 10],\n"
        "  abstd: [50, 50, 50], corrtime: 1}\n"
    )
    fn = read_filter_noise(gins)
    assert fn.fmt == "kf-gins"
    assert fn.values["gyroscope"]["x"]["T_c"] == 3600.0  # corrtime 1 h, an integer
    assert fn.values["gyroscope"]["y"]["sigma_b"] == pytest.approx(10 * math.pi / 180 / 3600)
    ros = "angular_velocity_covariance: [4.0e-6, 0, 0, 0, 4.0e-6, 0,\n  0, 0, 4.0e-6]\n"
    fn = read_filter_noise(ros, fs=100.0)
    assert fn.fmt == "ros-imu"
    assert fn.values["gyroscope"]["z"]["N"] == pytest.approx(math.sqrt(4.0e-6 / 100.0), 1e-15)


@pytest.fixture(scope="module")
def yaml_texts() -> dict[str, str]:
    """Every registered YAML format's text for the demo log's six channels (WN+RW)."""
    log = eg.load_log(eg.demo_path())
    fits = {c: eg.fit_gmwm(log.wavelet_variance(c), "WN+RW") for c in log.names}
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, f in FORMATS.items():
            if f.suffix in (".yaml", ".yml"):
                out[name] = export(None, fits, name, ci=None, filter_rate=100.0)
    return out


def test_every_yaml_writer_reads_back(yaml_texts) -> None:
    assert {"kalibr", "vins", "orbslam3", "kf-gins", "ros-imu"} <= set(yaml_texts)
    for name, text in yaml_texts.items():
        d = read_yaml_mapping(text, name)
        body = text.split("\n", 1)[1] if text.startswith("%YAML:1.0") else text
        assert d == yaml.safe_load(body), name  # a YAML parser reads the same numbers
        if FORMATS[name].is_filter:
            # gmwm check knows it (OpenVINS's file is a Kalibr imu chain: the Kalibr reader's)
            assert read_filter_noise(text, fs=100.0).fmt == {"openvins": "kalibr"}.get(name, name)
    k = read_kalibr(yaml_texts["kalibr"])
    assert k == yaml.safe_load(yaml_texts["kalibr"]) and k["update_rate"] == 100.0


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("gyroscope_noise_density: [1.0e-3, 2\n", "line 2"),
        ("gyroscope_noise_density: 1: 2\n", "line 1"),
        ("\tgyroscope_noise_density: 1.0\n", "line 1"),
        ("%YAML:1.0\nacc_n: 0.1\ngyr_n: {\n", "line 4"),
    ],
)
def test_a_file_that_is_not_yaml_is_a_one_line_error(text, where) -> None:
    with pytest.raises(ExportError, match="is not YAML at " + where) as e:
        read_kalibr(text)
    assert "\n" not in str(e.value) and "fix the file" in str(e.value)
    with pytest.raises(ExportError, match="not 'key: value'"):
        read_kalibr("- 1.0e-3\n- 2.0e-3\n")


def test_gmwm_check_names_a_yaml_file_it_cannot_parse(tmp_path, capsys) -> None:
    bad = tmp_path / "imu.yaml"
    bad.write_text("gyroscope_noise_density: 1.6e-04\ngyroscope_random_walk: [1.0e-5\n")
    with pytest.raises(DatasheetError, match=r"imu\.yaml.*is not YAML at line 3"):
        read_check_file(bad, channel="gyro_x", kind="gyroscope", fs=100.0)
    argv = ["check", str(eg.demo_path()), "--channel", "gyro_x", "--datasheet-file", str(bad)]
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and "is not YAML at line 3" in err


def test_pyyaml_is_a_declared_dependency() -> None:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

    deps = tomllib.loads(Path(__file__).parents[2].joinpath("pyproject.toml").read_text())
    assert any(
        d.replace(" ", "").lower().startswith("pyyaml>=6") for d in deps["project"]["dependencies"]
    )


@pytest.mark.real_data
def test_a_restyled_kalibr_file_checks_the_real_log_as_the_original(real_data, tmp_path, capsys):
    # the Kalibr file of adis16405_imu1's WN+RW fits, and the same mapping as one YAML flow map
    # with comments (as another tool or a person may write it): gmwm check reads both to the
    # same datasheet and gives the same verdicts against the log
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    fits = {c: eg.fit_gmwm(log.wavelet_variance(c), "WN+RW") for c in log.names}
    text = export(None, fits, "kalibr", ci=None)
    original = tmp_path / "imu.yaml"
    original.write_text(text)
    restyled = tmp_path / "imu_flow.yaml"
    restyled.write_text(
        "# the same noise model, one flow mapping\n"
        + yaml.safe_dump(yaml.safe_load(text), default_flow_style=True, width=60)
    )
    assert restyled.read_text().count("\n") > 3 and "{" in restyled.read_text()
    out = {}
    for path in (original, restyled):
        argv = ["check", str(log.source), "--channel", "gyro_x", "--datasheet-file", str(path)]
        assert main([*argv, "--json"]) == 0, capsys.readouterr().err
        out[path.name] = json.loads(capsys.readouterr().out)
    a, b = out["imu.yaml"], out["imu_flow.yaml"]
    assert a["datasheet"]["values"] == b["datasheet"]["values"]
    assert a["verdict"] == b["verdict"] and a["summary"] == b["summary"]
    # the datasheet read is the file's gyro_x values as PyYAML reads them (SI)
    ref = yaml.safe_load(text)
    assert a["datasheet"]["values"]["N"][0] == ref["gyroscope_noise_density_per_axis"]["x"]
    assert a["datasheet"]["values"]["K"][0] == ref["gyroscope_random_walk_per_axis"]["x"]
