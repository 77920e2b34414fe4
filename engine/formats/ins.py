"""Inertial navigation: KF-GINS ``imunoise`` and a ``sensor_msgs/Imu`` covariance block.

* KF-GINS (i2Nav-WHU/KF-GINS, ``dataset/kf-gins.yaml``): ``imunoise`` with ``arw``
  [deg/sqrt(hr)], ``vrw`` [m/s/sqrt(hr)], ``gbstd`` [deg/hr], ``abstd`` [mGal] per axis and one
  ``corrtime`` [hr]. KF-GINS models each bias as a first-order Gauss-Markov process with
  stationary std ``gbstd``/``abstd`` and correlation time ``corrtime`` (its process noise is
  ``2 std^2 / corrtime``). So ``arw``/``vrw`` = N in the datasheet display units (ARW, VRW of
  :data:`engine.units.DISPLAY`), ``gbstd``/``abstd`` = ``sigma_gm`` of the most persistent GM
  term and ``corrtime`` = its ``T_c`` (the largest over the channels: KF-GINS takes one).
* ``sensor_msgs/Imu`` (ROS message definition): row-major 3x3 covariances (x, y, z) of the
  measurement in (rad/s)^2 and (m/s^2)^2; ``orientation_covariance[0] = -1`` when the message
  has no orientation. We write the per-sample variance of the white noise at the log's rate,
  ``sigma2_WN`` in SI (= ``N^2 fs``), on the diagonal (the other terms 0: axes independent).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..fit import GMWMResult
from ..units import DISPLAY
from .common import text_lines, yaml_float
from .noise import noise_for

__all__ = ["MGAL", "kfgins_yaml", "ros_imu_yaml"]

MGAL = 1e-5  # m/s^2 in one milligal (1 Gal = 1 cm/s^2)
_HOUR = 3600.0  # s


def _flow(vals: list[float]) -> str:
    return "[" + ", ".join(yaml_float(v) for v in vals) + "]"


def kfgins_yaml(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    """KF-GINS ``imunoise`` block (YAML): per-axis ``arw``, ``vrw``, ``gbstd``, ``abstd`` and
    one ``corrtime``. Needs a GM (or AR1) term in every channel's model."""
    nz = noise_for(fits, "KF-GINS imunoise", kw, consumer="kf-gins")
    nz.need("T_c", "the KF-GINS export", "fit a model with a GM term, e.g. GM+WN or GM+WN+RW")
    ss = float(kw.get("scale_factor_std_ppm") or 1000.0)

    g, a = "gyroscope", "accelerometer"
    tcs = {f"{k}_{ax}": v for k in (g, a) for ax, v in nz.values[k]["T_c"].items()}
    lines = [f"# {c}" for c in nz.header] + [f"# warning: {w}" for w in nz.warnings]
    lines += [
        "# arw/vrw = N; gbstd/abstd = sigma_gm of the most persistent GM term; corrtime = its",
        "# T_c, the largest over the channels (per channel, s: "
        + ", ".join(f"{k} {v:.6g}" for k, v in tcs.items())
        + ")",
        "imunoise:",
        f"  arw: {_flow(nz.xyz(g, 'N', DISPLAY[(g, 'N')].factor))}  # [deg/sqrt(hr)]",
        f"  vrw: {_flow(nz.xyz(a, 'N', DISPLAY[(a, 'N')].factor))}  # [m/s/sqrt(hr)]",
        f"  gbstd: {_flow(nz.xyz(g, 'sigma_gm', DISPLAY[(g, 'B')].factor))}  # [deg/hr]",
        f"  abstd: {_flow(nz.xyz(a, 'sigma_gm', 1.0 / MGAL))}  # [mGal]",
        f"  corrtime: {yaml_float(max(tcs.values()) / _HOUR)}  # [hr]",
        f"  gsstd: {_flow([ss] * 3)}  # [ppm] scale-factor std: NOT estimated by GMWM (a "
        "placeholder: set it from your IMU's datasheet)",
        f"  asstd: {_flow([ss] * 3)}  # [ppm] scale-factor std: NOT estimated by GMWM (a "
        "placeholder: set it from your IMU's datasheet)",
        "  # KF-GINS requires gsstd/asstd. Its corrtime drives the Gauss-Markov model of the",
        "  # scale-factor states too (one corrtime for gyro/accel biases and scale factors).",
    ]
    return text_lines(lines)


def ros_imu_yaml(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    """``sensor_msgs/Imu`` covariance fields (YAML): diagonal per-sample WN variances in SI
    (``inflate**2`` applied), ``orientation_covariance[0] = -1``."""
    nz = noise_for(fits, "sensor_msgs/Imu covariances", kw, allow_partial=True, consumer="ros-imu")
    lines = [f"# {c}" for c in nz.header] + [f"# warning: {w}" for w in nz.warnings]
    lines.append(
        f"# per-sample variance of the white noise at {nz.fs:g} Hz, sigma2_WN = N^2 fs (SI), "
        "row-major 3x3, axes x y z (an axis not fitted gets the max over fitted ones)"
    )
    lines.append("orientation_covariance: " + _flow([-1.0] + [0.0] * 8) + "  # -1: no orientation")
    for field, kind, u in (
        ("angular_velocity_covariance", "gyroscope", "(rad/s)^2"),
        ("linear_acceleration_covariance", "accelerometer", "(m/s^2)^2"),
    ):
        if kind not in nz.values:
            lines.append(f"{field}: " + _flow([-1.0] + [0.0] * 8) + "  # -1: not fitted")
            continue
        diag = nz.xyz(kind, "sigma2")
        m = [diag[i] if i == j else 0.0 for i in range(3) for j in range(3)]
        lines.append(f"{field}: {_flow(m)}  # [{u}]")
    return text_lines(lines)
