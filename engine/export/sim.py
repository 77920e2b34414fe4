"""Simulators: a runnable MATLAB ``gyroparams``/``accelparams``/``imuSensor`` snippet and the
Gazebo/RotorS IMU plugin (``gazebo_imu_plugin``) parameters.

* MATLAB (Navigation/Sensor Fusion Toolbox, ``gyroparams``/``accelparams`` reference pages):
  ``NoiseDensity`` [(rad/s)/sqrt(Hz), (m/s^2)/sqrt(Hz)], ``RandomWalk`` [(rad/s)*sqrt(Hz),
  (m/s^2)*sqrt(Hz)], ``BiasInstability`` [rad/s, m/s^2], per axis. The toolbox's example
  "Inertial Sensor Noise Analysis Using Allan Variance" sets them to the Allan-variance N
  (``N^2/T``), K (``K^2 T/3``) and B (floor ``0.664 B``): here N and K of the fitted WN and RW
  and B the model's Allan floor / ``BI_FACTOR`` (:func:`engine.units.allan_floor`), in SI.
* RotorS (ethz-asl/rotors_simulator, ``gazebo_imu_plugin.h``/``.cpp``): noise density
  [rad/s/sqrt(Hz)] (two-sided), bias random walk [rad/s/s/sqrt(Hz)], bias correlation time
  [s], turn-on bias sigma [rad/s] (accelerometer alike in m/s^2). The plugin's bias is a
  Gauss-Markov process ``b_k = exp(-dt/tau) b_{k-1} + sigma_b sqrt(tau/2 (1 - exp(-2dt/tau)))
  w_k`` whose stationary variance is ``sigma_b^2 tau / 2``: so ``RandomWalk = sqrt(2 beta
  sigma2_gm) = sqrt(q)`` and ``BiasCorrelationTime = T_c`` of GMWM's most persistent GM term
  (not a slope read-off). The turn-on bias (run-to-run) is not identified by one static log:
  it is written as 0 with a comment.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..fit import GMWMResult
from .common import text_lines
from .noise import noise_for

__all__ = ["matlab_m", "gazebo_xml"]


def matlab_m(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    """A runnable MATLAB script: ``gyroparams``/``accelparams`` with per-axis (x, y, z)
    ``NoiseDensity`` = N, ``RandomWalk`` = K, ``BiasInstability`` = B (SI), and an
    ``imuSensor`` at the log's rate (an axis not fitted gets the max over fitted ones)."""
    nz = noise_for(fits, "MATLAB gyroparams/accelparams", kw, allow_partial=True)
    lines = [f"% {c}" for c in nz.header] + [f"% warning: {w}" for w in nz.warnings]
    lines.append(f"fs = {nz.fs!r};  % Hz, the log's sampling rate")
    ctor = {
        "gyroscope": ("gyro", "gyroparams", "rad/s"),
        "accelerometer": ("accel", "accelparams", "m/s^2"),
    }
    made = []
    for kind, (var, fn, u) in ctor.items():
        if kind not in nz.values:
            continue
        made.append((kind, var))

        def row(q: str, kind: str = kind) -> str:
            return "[" + " ".join(repr(v) for v in nz.xyz(kind, q)) + "]"

        lines += [
            f"{var} = {fn}( ...",
            f"    'NoiseDensity', {row('N')}, ...  ({u})/sqrt(Hz): N per axis x y z",
            f"    'RandomWalk', {row('K')}, ...  ({u})*sqrt(Hz): K per axis",
            f"    'BiasInstability', {row('B')});  % {u}: Allan floor / 0.664 per axis",
        ]
    args = ", ".join(
        f"'{'Gyroscope' if k == 'gyroscope' else 'Accelerometer'}', {v}" for k, v in made
    )
    lines.append(f"imu = imuSensor('accel-gyro', 'SampleRate', fs, {args});")
    return text_lines(lines)


def gazebo_xml(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    """RotorS ``gazebo_imu_plugin`` noise parameters (an SDF ``<plugin>`` element): per sensor
    ``*NoiseDensity`` = N, ``*RandomWalk`` = sqrt(q), ``*BiasCorrelationTime`` = T_c of the
    most persistent GM term, ``*TurnOnBiasSigma`` = 0 (not identified); max over axes. Needs a
    GM (or AR1) term in every channel's model."""
    nz = noise_for(fits, "Gazebo/RotorS IMU plugin", kw)
    nz.need("T_c", "the Gazebo/RotorS export", "fit a model with a GM term, e.g. GM+WN or GM+WN+RW")
    lines = ["<!--", *(f"  {c.replace('--', '-')}" for c in nz.header)]
    lines += [f"  warning: {w.replace('--', '-')}" for w in nz.warnings]
    lines += [
        "  Gauss-Markov bias: RandomWalk = sqrt(2 beta sigma2_gm), BiasCorrelationTime = 1/beta",
        "  of the GM term (max over axes); TurnOnBiasSigma is not identified by one static log",
        "  (set it from several runs or the datasheet). Add robotNamespace, linkName, imuTopic.",
        "-->",
        '<plugin filename="librotors_gazebo_imu_plugin.so" name="rotors_gazebo_imu_plugin">',
    ]
    for kind, name, u in (
        ("gyroscope", "gyroscope", "rad/s"),
        ("accelerometer", "accelerometer", "m/s^2"),
    ):
        rows = (
            ("NoiseDensity", nz.conservative(kind, "N"), f"{u}/sqrt(Hz)"),
            ("RandomWalk", nz.conservative(kind, "sqrt(q)"), f"{u}/s/sqrt(Hz)"),
            ("BiasCorrelationTime", nz.conservative(kind, "T_c"), "s"),
            ("TurnOnBiasSigma", 0.0, u),
        )
        for key, v, unit in rows:
            lines.append(f"  <{name}{key}>{v!r}</{name}{key}>  <!-- [{unit}] -->")
    lines.append("</plugin>")
    return text_lines(lines)
