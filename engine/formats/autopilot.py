"""Autopilot EKF parameter files: PX4 EKF2 (QGroundControl ``.params``) and ArduPilot EKF3
(Mission Planner ``.param``).

Both filters predict at a filter rate ``f_f`` (Hz) from IMU data summed over ``dt_f = 1/f_f``
and take the noise as a standard deviation per filter step:

* PX4 ``src/modules/ekf2/EKF/covariance.cpp``: delta-angle variance ``(dt_f EKF2_GYR_NOISE)^2``
  and gyro-bias process variance ``(dt_f^2 EKF2_GYR_B_NOISE)^2`` on the delta-angle bias
  state, i.e. ``(dt_f EKF2_GYR_B_NOISE)^2`` on the rate bias;
* ArduPilot ``libraries/AP_NavEKF3/AP_NavEKF3_core.cpp`` (CovariancePrediction): the same forms
  with ``EK3_GYRO_P_NSE``, ``EK3_ACC_P_NSE``, ``EK3_GBIAS_P_NSE``, ``EK3_ABIAS_P_NSE``.

A white noise of density N averaged over ``dt_f`` has std ``N sqrt(f_f)``; a random walk of
density K grows by variance ``K^2 dt_f`` per step, i.e. std ``(K sqrt(f_f)) dt_f``. So::

    *_NOISE / *_P_NSE       = N sqrt(f_f)   [rad/s, m/s^2]
    *_B_NOISE / *BIAS_P_NSE = K sqrt(f_f)   [rad/s^2, m/s^3]

with N and K the SI densities of :mod:`engine.units` (max over axes: one number per sensor).
Each value is checked against the parameter's documented range (PX4 parameter reference and
ArduPilot full parameter list, :data:`RANGES`); a value outside gets a warning (in the file and
as a Python warning): the ground station flags it, and the EKF then runs with a noise the
autopilot's developers did not tune for. ArduPilot's EKF3 steps once per 12 ms of IMU data
(``EKF_TARGET_DT``, about 80-83 Hz), not at the 400 Hz loop rate: give that as the filter
rate. The PX4 file's vehicle (system) id is ``vehicle_id`` (default 1): QGroundControl loads
only the lines of the connected vehicle's id.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping

from ..fit import GMWMResult
from ..units import ExportError
from .common import text_lines
from .noise import noise_for
from .options import ExportOptions

__all__ = ["RANGES", "autopilot_params", "px4_params", "ardupilot_params"]

#: name -> (sensor kind, quantity N or K, unit, documented min, documented max). Ranges as
#: the PX4 parameter reference (docs.px4.io, "Parameter Reference") and ArduPilot's
#: "Complete Parameter List" give them.
RANGES: dict[str, tuple[str, str, str, float, float]] = {
    "EKF2_GYR_NOISE": ("gyroscope", "N", "rad/s", 0.0001, 0.1),
    "EKF2_ACC_NOISE": ("accelerometer", "N", "m/s^2", 0.01, 1.0),
    "EKF2_GYR_B_NOISE": ("gyroscope", "K", "rad/s^2", 0.0, 0.01),
    "EKF2_ACC_B_NOISE": ("accelerometer", "K", "m/s^3", 0.0, 0.01),
    "EK3_GYRO_P_NSE": ("gyroscope", "N", "rad/s", 0.0001, 0.1),
    "EK3_ACC_P_NSE": ("accelerometer", "N", "m/s^2", 0.01, 1.0),
    "EK3_GBIAS_P_NSE": ("gyroscope", "K", "rad/s^2", 0.00001, 0.001),
    "EK3_ABIAS_P_NSE": ("accelerometer", "K", "m/s^3", 0.00001, 0.02),
}


def autopilot_params(
    fits: Mapping[str, GMWMResult], prefix: str, o: ExportOptions
) -> tuple[dict[str, float], list[str], list[str]]:
    """The parameters of one autopilot (``prefix`` ``"EKF2_"`` or ``"EK3_"``).

    Returns
    -------
    (values, header, warnings)
        ``values`` by parameter name (``density x sqrt(filter_rate) x inflate``); header
        comment lines; range warnings (also issued as :class:`UserWarning`).

    Raises
    ------
    ExportError
        No ``filter_rate``, or the errors of :func:`~engine.formats.noise.imu_noise`.
    """
    if o.filter_rate is None:  # engine.export refuses it first (the record's needs_filter_rate)
        raise ExportError(f"the {prefix.rstrip('_')} export needs the EKF's filter rate in Hz")
    fr = float(o.filter_rate)
    label = f"{'PX4 EKF2' if prefix == 'EKF2_' else 'ArduPilot EKF3'} parameters"
    nz = noise_for(fits, label, o, consumer="px4" if prefix == "EKF2_" else "ardupilot")
    header = [
        *nz.header,
        f"filter rate {fr!r} Hz: value = density x sqrt(filter rate) (N in rad/s/sqrt(Hz) "
        "or m/s^2/sqrt(Hz); K in rad/s^2/sqrt(Hz) or m/s^3/sqrt(Hz)), max over axes",
    ]
    if prefix == "EKF2_":
        header.append(
            f"assumes EKF2 predicts at {fr:g} Hz: EKF2_PREDICT_US = {1e6 / fr:.6g} us (PX4's "
            "default 10000 us, 100 Hz): set it to that value, or re-export with "
            "--filter-rate 1e6/EKF2_PREDICT_US"
        )
    if prefix == "EK3_":
        header.append(
            "EKF3 predicts once per 12 ms of IMU data (about 80-83 Hz), not at the 400 Hz "
            "loop rate: export with --filter-rate 83 unless your EKF3 runs otherwise"
        )
    values: dict[str, float] = {}
    warn: list[str] = list(nz.warnings)
    for name, (kind, q, unit, lo, hi) in RANGES.items():
        if not name.startswith(prefix):
            continue
        v = nz.conservative(kind, q) * math.sqrt(fr)
        values[name] = v
        if not lo <= v <= hi:
            msg = (
                f"{name} = {v:.6g} {unit} is outside its documented range [{lo:g}, {hi:g}] "
                "(the ground station flags it; the EKF runs with it untuned): check the filter "
                "rate and units"
            )
            warn.append(msg)
            warnings.warn(msg, UserWarning, stacklevel=3)
    return values, header, warn


def px4_params(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """PX4 EKF2 noise parameters as a QGroundControl ``.params`` file (``#`` comments, then
    ``vehicle-id<TAB>component-id<TAB>name<TAB>value<TAB>type`` with type 9 = float); the
    vehicle id is :attr:`~engine.formats.ExportOptions.vehicle_id`."""
    vid = o.vehicle_id
    values, header, warn = autopilot_params(fits, "EKF2_", o)
    lines = [f"# {c}" for c in header] + [f"# warning: {w}" for w in warn]
    lines.append("#")
    lines.append("# Vehicle-Id Component-Id Name Value Type")
    rows = []  # tab-separated, of our names and numbers only: written as they are
    for name, v in values.items():
        rows.append(f"# {name} [{RANGES[name][2]}]")
        rows.append(f"{vid}\t1\t{name}\t{v!r}\t9")
    return text_lines(lines) + "\n".join(rows) + "\n"


def ardupilot_params(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """ArduPilot EKF3 noise parameters as a ``.param`` file (``NAME,VALUE`` lines, ``#``
    comments)."""
    values, header, warn = autopilot_params(fits, "EK3_", o)
    lines = [f"# {c}" for c in header] + [f"# warning: {w}" for w in warn]
    for name, v in values.items():
        lines.append(f"# {name} [{RANGES[name][2]}]")
        lines.append(f"{name},{v!r}")
    return text_lines(lines)
