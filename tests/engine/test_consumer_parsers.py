"""Each filter format read by its consumer's own parser, where it runs here.

* OpenCV-YAML files (``%YAML:1.0``: OpenVINS, ORB-SLAM3, VINS-Mono/Fusion) are read with
  OpenCV's ``cv2.FileStorage``, the parser those programs use (OpenVINS ``ov_core::YamlParser``,
  ORB-SLAM3 ``Settings``/``System``, VINS ``readParameters``: ``cv::FileStorage`` each); every
  key a consumer reads is present with its type (real, integer, string, matrix), and every
  number equals what a YAML parser reads from the same text.
* The gz-sim SDF ``<imu>`` element: its element names against sdformat's specification
  (``sdf/1.9/imu.sdf`` and ``sdf/1.6/noise.sdf`` of gazebosim/sdformat, listed below).
* YAML and JSON formats (Kalibr, Basalt, KF-GINS, ``sensor_msgs/Imu``, the JSON report) load
  and hold every key the consumer requires, with its shape; the autopilot parameter files and
  the Gazebo-classic plugin block hold the names their consumers read.
"""

from __future__ import annotations

import json
import math
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

import engine as eg
from engine.demo import demo_path
from engine.formats import FORMATS, export

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the test extra) is needed")

#: sdformat's ``<imu>`` children (sdf/1.9/imu.sdf): the noise blocks sit under these axes.
SDF_IMU_CHILDREN = {"orientation_reference_frame", "angular_velocity", "linear_acceleration"}
SDF_IMU_AXES = {"x", "y", "z"}
#: sdformat's ``<noise>`` element (sdf/1.6/noise.sdf, unchanged through 1.9): its children,
#: all ``double``, and the values of its required ``type`` attribute.
SDF_NOISE_CHILDREN = {
    "mean",
    "stddev",
    "bias_mean",
    "bias_stddev",
    "dynamic_bias_stddev",
    "dynamic_bias_correlation_time",
    "precision",
}
SDF_NOISE_TYPES = {"none", "gaussian", "gaussian_quantized"}

REAL, INT, STR, MAT3, MAT4 = "real", "int", "string", "3x3", "4x4"

#: Every key each OpenCV-YAML consumer reads, with the type its reader expects.
#: OpenVINS: VioManagerOptions (``parse_external("relative_config_imu", "imu0", ...)`` of the
#: four densities as double; ``update_rate`` double; ``model`` string; ``Tw``, ``R_IMUtoGYRO``,
#: ``Ta``, ``R_IMUtoACC``, ``Tg`` 3x3; ``rostopic`` in the ROS nodes). ORB-SLAM3: the settings
#: keys (``IMU.Frequency`` read as an integer by the legacy parser). VINS: ``acc_n`` ... double.
OPENCV_KEYS: dict[str, dict[str, str]] = {
    "openvins": {
        "imu0/T_i_b": MAT4,
        "imu0/accelerometer_noise_density": REAL,
        "imu0/accelerometer_random_walk": REAL,
        "imu0/gyroscope_noise_density": REAL,
        "imu0/gyroscope_random_walk": REAL,
        "imu0/rostopic": STR,
        "imu0/time_offset": REAL,
        "imu0/update_rate": REAL,
        "imu0/model": STR,
        "imu0/Tw": MAT3,
        "imu0/R_IMUtoGYRO": MAT3,
        "imu0/Ta": MAT3,
        "imu0/R_IMUtoACC": MAT3,
        "imu0/Tg": MAT3,
    },
    "orbslam3": {
        "IMU.NoiseGyro": REAL,
        "IMU.NoiseAcc": REAL,
        "IMU.GyroWalk": REAL,
        "IMU.AccWalk": REAL,
        "IMU.Frequency": INT,
    },
    "vins": {"acc_n": REAL, "gyr_n": REAL, "acc_w": REAL, "gyr_w": REAL},
}

#: Keys (and shapes: 0 a scalar, 3 a 3-vector, 9 a 3x3 row-major list) of the YAML/JSON
#: consumers. Kalibr: ``kalibr_common/ConfigReader.py`` ImuParameters; Basalt:
#: ``calibration.hpp`` (``imu_update_rate``, the four 3-vectors); KF-GINS: ``kf_gins.cpp``
#: (``imunoise``: six 3-vectors and ``corrtime``); ``sensor_msgs/Imu``: the three covariances.
YAML_KEYS: dict[str, dict[str, int]] = {
    "kalibr": {
        "accelerometer_noise_density": 0,
        "accelerometer_random_walk": 0,
        "gyroscope_noise_density": 0,
        "gyroscope_random_walk": 0,
        "update_rate": 0,
    },
    "basalt": {
        "value0/imu_update_rate": 0,
        "value0/accel_noise_std": 3,
        "value0/gyro_noise_std": 3,
        "value0/accel_bias_std": 3,
        "value0/gyro_bias_std": 3,
    },
    "kf-gins": {
        "imunoise/arw": 3,
        "imunoise/vrw": 3,
        "imunoise/gbstd": 3,
        "imunoise/abstd": 3,
        "imunoise/gsstd": 3,
        "imunoise/asstd": 3,
        "imunoise/corrtime": 0,
    },
    "ros-imu": {
        "orientation_covariance": 9,
        "angular_velocity_covariance": 9,
        "linear_acceleration_covariance": 9,
    },
}

#: Parameter names the autopilots read (PX4 EKF2 and ArduPilot EKF3 parameter tables).
AUTOPILOT_NAMES = {
    "px4": {"EKF2_GYR_NOISE", "EKF2_ACC_NOISE", "EKF2_GYR_B_NOISE", "EKF2_ACC_B_NOISE"},
    "ardupilot": {"EK3_GYRO_P_NSE", "EK3_ACC_P_NSE", "EK3_GBIAS_P_NSE", "EK3_ABIAS_P_NSE"},
}


@pytest.fixture(scope="module")
def texts() -> dict[str, str]:
    """Every registered format's text for the demo log's six channels (GM+WN+RW)."""
    log = eg.load_log(demo_path())
    fits = {
        c: eg.fit_gmwm(eg.wavelet_variance(log[c], fs=log.fs, unit=log.units[c]), "GM+WN+RW")
        for c in log.names
    }
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # autopilot range warnings: tested elsewhere
        for name in FORMATS:
            out[name] = export(None, fits, name, ci=None, filter_rate=100.0)
    return out


def _cv_value(node) -> tuple[str, object]:
    """(type, value) of an OpenCV FileNode: real, int, string or an n x n matrix."""
    if node.isReal():
        return REAL, node.real()
    if node.isInt():
        return INT, int(node.real())
    if node.isString():
        return STR, node.string()
    if node.isSeq():
        rows = [node.at(i) for i in range(node.size())]
        assert all(r.isSeq() and r.size() == len(rows) for r in rows)
        assert all(r.at(j).isReal() for r in rows for j in range(r.size()))
        return f"{len(rows)}x{len(rows)}", [[r.at(j).real() for j in range(r.size())] for r in rows]
    return "other", None


def _walk(node, prefix: str = "") -> dict[str, object]:
    out = {}
    for k in node.keys():
        child = node.getNode(k)
        if child.isMap():
            out.update(_walk(child, f"{prefix}{k}/"))
        else:
            out[f"{prefix}{k}"] = child
    return out


@pytest.mark.slow  # every OpenCV-YAML export: 8 s of CPU
def test_every_opencv_yaml_format_is_covered(texts) -> None:
    assert {n for n, t in texts.items() if t.startswith("%YAML:1.0")} == set(OPENCV_KEYS)


@pytest.mark.parametrize("fmt", sorted(OPENCV_KEYS))
def test_opencv_filestorage_reads_every_key_with_its_type(texts, fmt, tmp_path: Path) -> None:
    path = tmp_path / f"{fmt}.yaml"
    path.write_text(texts[fmt])
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened(), f"OpenCV could not open the {fmt} export"
    try:
        nodes = _walk(fs.root())
        assert set(nodes) == set(OPENCV_KEYS[fmt])  # no key missing, none extra
        ref = yaml.safe_load(texts[fmt].split("\n", 1)[1])  # the same text, a YAML parser
        for key, want in OPENCV_KEYS[fmt].items():
            kind, value = _cv_value(nodes[key])
            assert kind == want, f"{fmt} {key}: OpenCV reads a {kind}, the consumer a {want}"
            y = ref
            for part in key.split("/"):
                y = y[part]
            assert value == y, (fmt, key)
            if want == REAL and not key.endswith("time_offset"):
                assert value > 0, (fmt, key)  # noise values and rates
        if fmt == "orbslam3":
            assert int(fs.getNode("IMU.Frequency").real()) == 100
    finally:
        fs.release()


def test_gz_sim_sdf_names_are_sdformat_elements(texts) -> None:
    imu = ET.fromstring(texts["gz-sim"])  # a comment, then one <imu> element
    assert imu.tag == "imu"
    assert {e.tag for e in imu} <= SDF_IMU_CHILDREN
    assert {e.tag for e in imu} == {"angular_velocity", "linear_acceleration"}
    for block in imu:
        assert {e.tag for e in block} == SDF_IMU_AXES
        for axis in block:
            (noise,) = list(axis)
            assert noise.tag == "noise" and noise.get("type") in SDF_NOISE_TYPES
            names = {e.tag for e in noise}
            assert names <= SDF_NOISE_CHILDREN, names - SDF_NOISE_CHILDREN
            for e in noise:  # every child is a double
                assert math.isfinite(float(e.text)), (block.tag, axis.tag, e.tag)
            assert float(noise.find("stddev").text) > 0  # sdformat: min 0.0
            assert float(noise.find("dynamic_bias_stddev").text) > 0
            assert float(noise.find("dynamic_bias_correlation_time").text) > 0


@pytest.mark.parametrize("fmt", sorted(YAML_KEYS))
def test_yaml_and_json_formats_have_every_consumer_key(texts, fmt) -> None:
    text = texts[fmt]
    d = json.loads(text) if FORMATS[fmt].suffix == ".json" else yaml.safe_load(text)
    for key, shape in YAML_KEYS[fmt].items():
        v = d
        for part in key.split("/"):
            assert isinstance(v, dict) and part in v, f"{fmt}: no {key}"
            v = v[part]
        if shape == 0:
            assert isinstance(v, float) and v > 0, (fmt, key, v)
        else:
            assert isinstance(v, list) and len(v) == shape, (fmt, key, v)
            assert all(isinstance(x, float) for x in v), (fmt, key, v)
    if fmt == "kalibr":
        assert isinstance(d["rostopic"], str) and d["rostopic"].startswith("/")
    if fmt == "ros-imu":  # the covariances' diagonals positive, orientation "unknown" (-1)
        for key in ("angular_velocity_covariance", "linear_acceleration_covariance"):
            assert min(d[key][0], d[key][4], d[key][8]) > 0
        assert d["orientation_covariance"][0] == -1.0


def test_json_report_loads_with_its_projections(texts) -> None:
    d = json.loads(texts["json"])
    assert d["schema"] == "gmwm-report/1"
    for ch, c in d["channels"].items():
        p = c["projections"]["WN+RW"]
        assert p["params"]["N"]["value"] > 0 and p["params"]["K"]["value"] > 0, ch


def test_autopilot_files_and_gazebo_plugin_names(texts) -> None:
    rows = [ln.split("\t") for ln in texts["px4"].splitlines() if ln and not ln.startswith("#")]
    assert {r[2] for r in rows} == AUTOPILOT_NAMES["px4"]
    assert all(len(r) == 5 and r[4] == "9" and float(r[3]) > 0 for r in rows)  # 9: float
    rows = [ln.split(",") for ln in texts["ardupilot"].splitlines() if ln and ln[0] != "#"]
    assert {r[0] for r in rows} == AUTOPILOT_NAMES["ardupilot"]
    assert all(len(r) == 2 and float(r[1]) > 0 for r in rows)
    gz = texts["gazebo"]
    plugin = ET.fromstring(gz[gz.index("<plugin") :])
    assert plugin.get("filename") == "libgazebo_imu_plugin.so"  # what PX4-classic loads
    names = {e.tag for e in plugin}
    for kind in ("gyroscope", "accelerometer"):
        for q in ("NoiseDensity", "RandomWalk", "BiasCorrelationTime", "TurnOnBiasSigma"):
            assert f"{kind}{q}" in names, (kind, q)
    assert "gyroscopeBiasRandomWalk" in names  # RotorS's spelling
