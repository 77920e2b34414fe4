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
  it is written as 0 with a comment. PX4-classic (PX4-SITL_gazebo) loads the same plugin as
  ``libgazebo_imu_plugin.so`` and reads ``gyroscopeRandomWalk``/``accelerometerRandomWalk``;
  RotorS (``librotors_gazebo_imu_plugin.so``) reads ``gyroscopeBiasRandomWalk`` and
  ``accelerometerRandomWalk`` (older releases ``accelerometerBiasRandomWalk``). The element
  names PX4-classic's file name and carries every spelling (each plugin ignores the others).
* gz-sim (gz-sensors ``GaussianNoiseModel``, SDF ``<noise type="gaussian">``): per sample
  white noise ``stddev`` = ``N sqrt(update_rate)`` and a Gauss-Markov ``dynamic_bias`` with
  ``dynamic_bias_correlation_time`` = T_c and ``dynamic_bias_stddev`` = sqrt(q) (the RotorS
  convention: stationary variance ``dynamic_bias_stddev^2 T_c / 2``); ``bias_mean`` and
  ``bias_stddev`` (turn-on bias) 0, not identified by one static log.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ..fit import GMWMResult
from .common import text_lines
from .noise import noise_for
from .options import ExportOptions

__all__ = ["matlab_m", "gazebo_xml", "gz_sim_sdf", "GAZEBO_KEYS"]

#: RotorS/PX4-classic plugin element names per quantity (every spelling a plugin reads).
GAZEBO_KEYS = {
    "NoiseDensity": ("NoiseDensity",),
    "RandomWalk": ("RandomWalk", "BiasRandomWalk"),
    "BiasCorrelationTime": ("BiasCorrelationTime",),
    "TurnOnBiasSigma": ("TurnOnBiasSigma",),
}


def matlab_m(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """A runnable MATLAB script: ``gyroparams``/``accelparams`` with per-axis (x, y, z)
    ``NoiseDensity`` = N, ``RandomWalk`` = K, ``BiasInstability`` = B (SI), and an
    ``imuSensor`` at the log's rate (an axis not fitted gets the max over fitted ones)."""
    # one sensor is enough: the record says so (Format.partial)
    nz = noise_for(fits, "MATLAB gyroparams/accelparams", o, consumer="matlab")
    lines = [f"% {c}" for c in nz.header] + [f"% warning: {w}" for w in nz.warnings]
    lines.append(f"fs = {nz.rate!r};  % Hz, the IMU rate (the log's unless --filter-rate)")
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


def gazebo_xml(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """RotorS ``gazebo_imu_plugin`` noise parameters (an SDF ``<plugin>`` element): per sensor
    ``*NoiseDensity`` = N, ``*RandomWalk`` = sqrt(q), ``*BiasCorrelationTime`` = T_c of the
    most persistent GM term, ``*TurnOnBiasSigma`` = 0 (not identified); max over axes. Needs a
    GM (or AR1) term in every channel's model."""
    nz = noise_for(fits, "Gazebo/RotorS IMU plugin", o, consumer="gazebo")
    nz.need("T_c", "the Gazebo/RotorS export", "fit a model with a GM term, e.g. GM+WN or GM+WN+RW")
    lines = ["<!--", *(f"  {c.replace('--', '-')}" for c in nz.header)]
    lines += [f"  warning: {w.replace('--', '-')}" for w in nz.warnings]
    lines += [
        "  Gauss-Markov bias: RandomWalk = sqrt(2 beta sigma2_gm), BiasCorrelationTime = 1/beta",
        "  of the projected GM bias, one per sensor triad: the max over axes of each (a GM of",
        "  driving density sqrt(q) and time T_c has a PSD q / (1/T_c^2 + w^2) that grows with",
        "  both, so the triad's bias bounds each axis's at every frequency);",
        "  TurnOnBiasSigma is not identified by one static log",
        "  (set it from several runs or the datasheet). Add robotNamespace, linkName, imuTopic.",
        "  File name: PX4-classic's libgazebo_imu_plugin.so; for RotorS use",
        "  librotors_gazebo_imu_plugin.so. Both spellings of the random walk are written",
        "  (PX4-classic: *RandomWalk; RotorS: gyroscopeBiasRandomWalk, accelerometerRandomWalk).",
        "-->",
        '<plugin filename="libgazebo_imu_plugin.so" name="rotors_gazebo_imu_plugin">',
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
            for spelling in GAZEBO_KEYS[key]:
                lines.append(f"  <{name}{spelling}>{v!r}</{name}{spelling}>  <!-- [{unit}] -->")
    lines.append("</plugin>")
    return text_lines(lines)


def gz_sim_sdf(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """gz-sim IMU sensor noise: an SDF ``<imu>`` element with ``<angular_velocity>`` and
    ``<linear_acceleration>``, per axis x, y, z a ``<noise type="gaussian">`` with ``mean`` 0,
    ``stddev`` = N sqrt(fs), ``bias_mean``/``bias_stddev`` 0, ``dynamic_bias_stddev`` =
    sqrt(q) and ``dynamic_bias_correlation_time`` = T_c of the projected Gauss-Markov bias
    (module docstring). The sensor's ``<update_rate>`` must be the log's rate ``fs``."""
    nz = noise_for(fits, "gz-sim IMU <noise>", o, consumer="gz-sim")
    nz.need("T_c", "the gz-sim export", "fit a model with a GM term, e.g. GM+WN or GM+WN+RW")
    r = math.sqrt(nz.rate)
    lines = ["<!--", *(f"  {c.replace('--', '-')}" for c in nz.header)]
    lines += [f"  warning: {w.replace('--', '-')}" for w in nz.warnings]
    lines += [
        f'  Put this <imu> inside <sensor type="imu"> with <update_rate>{nz.rate:g}</update_rate>:',
        "  stddev = N sqrt(update_rate) (per sample);",
        "  dynamic_bias_stddev = sqrt(2 sigma_b^2 / T_c) (gz-sensors' GaussianNoiseModel:",
        "  stationary bias variance dynamic_bias_stddev^2 T_c / 2);",
        "  bias_mean/bias_stddev (turn-on bias) are not identified by one static log: 0.",
        "-->",
        "<imu>",
    ]
    for tag, kind, u in (
        ("angular_velocity", "gyroscope", "rad/s"),
        ("linear_acceleration", "accelerometer", "m/s^2"),
    ):
        if kind not in nz.values:
            continue
        lines.append(f"  <{tag}>")
        sd, dyn, tc = nz.xyz(kind, "N", r), nz.xyz(kind, "sqrt(q)"), nz.xyz(kind, "T_c")
        for i, ax in enumerate("xyz"):
            lines += [
                f"    <{ax}>",
                '      <noise type="gaussian">',
                "        <mean>0.0</mean>",
                f"        <stddev>{sd[i]!r}</stddev>  <!-- [{u}] N sqrt(fs) -->",
                "        <bias_mean>0.0</bias_mean>",
                "        <bias_stddev>0.0</bias_stddev>",
                f"        <dynamic_bias_stddev>{dyn[i]!r}</dynamic_bias_stddev>"
                f"  <!-- [{u}/sqrt(s)] -->",
                f"        <dynamic_bias_correlation_time>{tc[i]!r}</dynamic_bias_correlation_time>"
                "  <!-- [s] -->",
                "      </noise>",
                f"    </{ax}>",
            ]
        lines.append(f"  </{tag}>")
    lines.append("</imu>")
    return text_lines(lines)
