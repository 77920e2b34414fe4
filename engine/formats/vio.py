"""Visual-inertial estimators: OpenVINS ``kalibr_imu_chain.yaml``, Basalt calibration JSON,
ORB-SLAM3 settings and VINS-Mono/Fusion config keys.

OpenVINS, Basalt and ORB-SLAM3 take continuous-time densities in SI: the white-noise density
``N = sqrt(sigma2 / fs)`` and the random-walk density ``K = sqrt(gamma2 fs)`` of
:mod:`engine.units`, as gathered by :func:`~engine.formats.noise.imu_noise`; one number per
sensor gets the max over axes, Basalt one per axis. VINS-Mono/Fusion take per-sample standard
deviations at the IMU rate (``acc_n = N sqrt(fs)``, ``acc_w = K sqrt(fs)``). The sources of
each key's meaning (the projects' own example files and code): docs/methods.md,
"Visual-inertial formats"; every format's keys and units: docs/fit-to-filter.md.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from ..fit import GMWMResult
from .common import text_lines, yaml_float, yaml_str
from .noise import noise_for
from .options import ExportOptions

__all__ = ["openvins_yaml", "basalt_json", "orbslam3_yaml", "vins_yaml"]

_ND = {"gyroscope": "rad/s/sqrt(Hz)", "accelerometer": "m/s^2/sqrt(Hz)"}
_RW = {"gyroscope": "rad/s^2/sqrt(Hz)", "accelerometer": "m/s^3/sqrt(Hz)"}


def _eye(n: int, indent: str, zero: bool = False) -> list[str]:
    return [
        indent + "- [" + ", ".join("1.0" if i == j and not zero else "0.0" for j in range(n)) + "]"
        for i in range(n)
    ]


def openvins_yaml(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """OpenVINS ``kalibr_imu_chain.yaml`` (OpenCV ``%YAML:1.0``): the ``imu0`` block with
    identity ``T_i_b``/``Tw``/``R_IMUtoGYRO``/``Ta``/``R_IMUtoACC``, zero ``Tg``, the four Kalibr
    densities (max over axes, SI), ``rostopic``
    (:attr:`~engine.formats.ExportOptions.rostopic`), ``time_offset: 0.0``, ``update_rate``
    (the consumer's rate: ``filter_rate``, default the log's) and ``model: "kalibr"``."""
    nz = noise_for(fits, "OpenVINS kalibr_imu_chain.yaml", o, consumer="openvins")
    lines = ["%YAML:1.0", *(f"# {c}" for c in nz.header)]
    lines += [f"# warning: {w}" for w in nz.warnings]
    lines += ["", "imu0:", "  T_i_b:  # IMU to body: identity (not estimated by GMWM)"]
    lines += _eye(4, "    ")
    for kind in ("accelerometer", "gyroscope"):
        n, k = nz.conservative(kind, "N"), nz.conservative(kind, "K")
        lines.append(f"  {kind}_noise_density: {yaml_float(n)}  # [{_ND[kind]}] N, max over axes")
        lines.append(f"  {kind}_random_walk: {yaml_float(k)}  # [{_RW[kind]}] K, max over axes")
    lines += [
        f"  rostopic: {yaml_str(o.rostopic or '/imu0')}",
        "  time_offset: 0.0  # [s] (not estimated by GMWM)",
        f"  update_rate: {yaml_float(nz.rate)}  # [Hz] the consumer's IMU rate (densities "
        "do not depend on it)",
        '  model: "kalibr"',
        "  # intrinsics not estimated by GMWM: identity, and zero gravity sensitivity Tg",
    ]
    for name in ("Tw", "R_IMUtoGYRO", "Ta", "R_IMUtoACC", "Tg"):
        lines.append(f"  {name}:")
        lines += _eye(3, "    ", zero=name == "Tg")
    return text_lines(lines)


def basalt_json(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """Basalt calibration JSON fragment: ``value0`` with ``imu_update_rate`` [Hz] and per-axis
    (x, y, z) ``gyro_noise_std`` = N, ``accel_noise_std`` = N, ``gyro_bias_std`` = K,
    ``accel_bias_std`` = K in SI; an axis that was not fitted gets the max over the fitted
    axes. JSON has no comments: ``gmwm_export`` (a sibling of ``value0``, which Basalt does
    not read) holds the header and units. Merge ``value0``'s keys into the calib file."""
    nz = noise_for(fits, "Basalt calibration JSON", o, consumer="basalt")
    v0: dict[str, Any] = {"imu_update_rate": nz.rate}
    units: dict[str, str] = {"imu_update_rate": "Hz"}
    for kind, short in (("accelerometer", "accel"), ("gyroscope", "gyro")):
        for q, key, u in (("N", "noise_std", _ND[kind]), ("K", "bias_std", _RW[kind])):
            if q not in nz.values.get(kind, {}):
                continue
            d = nz.values[kind][q]
            v0[f"{short}_{key}"] = nz.xyz(kind, q)
            units[f"{short}_{key}"] = f"{u} per axis x, y, z" + (
                "" if all(a in d for a in "xyz") else " (missing axes: max over fitted ones)"
            )
    out = {"value0": v0, "gmwm_export": {"header": nz.header, "units": units}}
    if nz.warnings:
        out["gmwm_export"]["warnings"] = nz.warnings
    return json.dumps(out, indent=1, allow_nan=False) + "\n"


def orbslam3_yaml(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """ORB-SLAM3 settings lines (``%YAML:1.0``): ``IMU.NoiseGyro``/``IMU.NoiseAcc`` = N,
    ``IMU.GyroWalk``/``IMU.AccWalk`` = K (max over axes, SI), ``IMU.Frequency`` [Hz] as an
    integer (the legacy settings parser reads it with ``(int)``; a non-integer rate is rounded
    with a warning)."""
    nz = noise_for(fits, "ORB-SLAM3 IMU settings", o, consumer="orbslam3")
    lines = ["%YAML:1.0", *(f"# {c}" for c in nz.header)]
    lines += [f"# warning: {w}" for w in nz.warnings]
    freq = round(nz.rate)
    if abs(freq - nz.rate) > 1e-9 * nz.rate:
        lines.append(
            f"# warning: the IMU rate {nz.rate!r} Hz is not an integer; IMU.Frequency is an "
            f"integer in ORB-SLAM3: written as {freq}"
        )
    g, a = "gyroscope", "accelerometer"
    lines += [
        f"IMU.NoiseGyro: {yaml_float(nz.conservative(g, 'N'))}  # [{_ND[g]}] N",
        f"IMU.NoiseAcc: {yaml_float(nz.conservative(a, 'N'))}  # [{_ND[a]}] N",
        f"IMU.GyroWalk: {yaml_float(nz.conservative(g, 'K'))}  # [{_RW[g]}] K",
        f"IMU.AccWalk: {yaml_float(nz.conservative(a, 'K'))}  # [{_RW[a]}] K",
        f"IMU.Frequency: {freq}  # [Hz] an integer (ORB-SLAM3's legacy parser)",
    ]
    return text_lines(lines)


def vins_yaml(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """VINS-Mono/Fusion IMU keys (``%YAML:1.0``): per-sample (discrete) standard deviations at
    the consumer's IMU rate ``fs`` (``filter_rate``, default the log's), ``acc_n``/``gyr_n`` =
    ``N sqrt(fs)`` and ``acc_w``/``gyr_w`` = ``K sqrt(fs)`` (max over axes, SI; module
    docstring), stated in the file."""
    nz = noise_for(fits, "VINS-Mono/Fusion IMU parameters", o, consumer="vins")
    r = math.sqrt(nz.rate)
    lines = ["%YAML:1.0", *(f"# {c}" for c in nz.header)]
    lines += [f"# warning: {w}" for w in nz.warnings]
    lines.append(
        f"# convention: VINS uses these as per-sample (discrete) standard deviations at the IMU "
        f"rate (integration_base.h): acc_n = N sqrt(fs), acc_w = K sqrt(fs) with fs = "
        f"{nz.rate:g} Hz (x{r:.4g} the Kalibr densities); re-export with --filter-rate HZ if "
        "your IMU rate differs"
    )
    g, a = "gyroscope", "accelerometer"
    lines += [
        f"acc_n: {yaml_float(nz.conservative(a, 'N') * r)}  # [m/s^2] accelerometer N sqrt(fs)",
        f"gyr_n: {yaml_float(nz.conservative(g, 'N') * r)}  # [rad/s] gyroscope N sqrt(fs)",
        f"acc_w: {yaml_float(nz.conservative(a, 'K') * r)}  # [m/s^3] accelerometer K sqrt(fs)",
        f"gyr_w: {yaml_float(nz.conservative(g, 'K') * r)}  # [rad/s^2] gyroscope K sqrt(fs)",
    ]
    return text_lines(lines)
