"""Inertial navigation: KF-GINS ``imunoise`` and a ``sensor_msgs/Imu`` covariance block.

* KF-GINS (i2Nav-WHU/KF-GINS, ``dataset/kf-gins.yaml``): ``imunoise`` with ``arw``
  [deg/sqrt(hr)], ``vrw`` [m/s/sqrt(hr)], ``gbstd`` [deg/hr], ``abstd`` [mGal] per axis and one
  ``corrtime`` [hr]. KF-GINS models each bias as a first-order Gauss-Markov process with
  stationary std ``gbstd``/``abstd`` and correlation time ``corrtime`` (its process noise is
  ``2 std^2 / corrtime``). So ``arw``/``vrw`` = N in the datasheet display units (ARW, VRW of
  :data:`engine.units.DISPLAY`), ``gbstd``/``abstd`` = ``sigma_b`` of the projected
  Gauss-Markov bias and ``corrtime`` = its ``T_c``. KF-GINS takes **one** ``corrtime`` for
  every bias, so the file has one bias model: with the bound (the default), the ``T_c`` of
  the least total inflation over the file's channels (the sum of each channel's log
  geometric-mean ratio, searched over the channels' own ``T_c`` and a log grid between
  them), each channel's ``sigma_b`` then bounded at that ``T_c``; with ``--projection
  plain``/``fit``, the largest ``T_c`` with each channel's driving noise ``q = 2 sigma_b^2 /
  T_c`` kept (``sigma_b`` scaled by ``sqrt(T_c / T_c,own)``), which bounds each channel's GM
  spectrum at every frequency. (Pairing the largest ``T_c`` with each channel's own
  ``sigma_b`` lowers ``q``: the file's WV was 0.065-0.15 of the fitted WV at 160-5000 s on
  the ADIS16405 gyros.)
* ``sensor_msgs/Imu`` (ROS message definition): row-major 3x3 covariances (x, y, z) of the
  measurement in (rad/s)^2 and (m/s^2)^2; ``orientation_covariance[0] = -1`` when the message
  has no orientation. We write the per-sample variance of the white noise at the log's rate,
  ``sigma2_WN`` in SI (= ``N^2 fs``), on the diagonal (the other terms 0: axes independent).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from ..fit import GMWMResult
from ..units import DISPLAY
from .common import text_lines, yaml_float
from .noise import ImuNoise, noise_for
from .options import ExportOptions
from .projection import log_inflation_at_tc

__all__ = ["MGAL", "kfgins_noise", "kfgins_yaml", "ros_imu_yaml"]

MGAL = 1e-5  # m/s^2 in one milligal (1 Gal = 1 cm/s^2)
_HOUR = 3600.0  # s


def _flow(vals: list[float]) -> str:
    return "[" + ", ".join(yaml_float(v) for v in vals) + "]"


def _kfgins(
    fits: Mapping[str, GMWMResult], o: ExportOptions, allow_partial: bool = False
) -> tuple[ImuNoise, dict[str, float], float | None]:
    """The KF-GINS numbers, each channel's own ``T_c`` (s, by ``<sensor>_<axis>``) and, with
    the bound, the file's one ``T_c`` (s): the least total inflation over the channels, each
    channel bounded at it (a first pass without intervals gives the channels' own ``T_c``)."""
    bounded = o.projection == "bound"
    nz = noise_for(
        fits,
        "KF-GINS imunoise",
        dataclasses.replace(o, ci=None) if bounded else o,
        allow_partial=allow_partial,
        consumer="kf-gins",
    )
    nz.need("T_c", "the KF-GINS export", "fit a model with a GM term, e.g. GM+WN or GM+WN+RW")
    own = {
        f"{k}_{ax}": v
        for k in ("gyroscope", "accelerometer")
        if k in nz.values
        for ax, v in nz.values[k]["T_c"].items()
    }
    if not bounded:  # the largest T_c, each channel's driving noise kept: what the file writes
        return _at_one_tc(nz, max(own.values())), own, None
    tc = _least_total_tc(fits, o, sorted(set(own.values())))
    nz = noise_for(
        fits, "KF-GINS imunoise", o, allow_partial=allow_partial, consumer="kf-gins", tc=tc
    )
    return nz, own, tc


def _at_one_tc(nz: ImuNoise, tc: float) -> ImuNoise:
    """The unbounded KF-GINS numbers at the file's one ``T_c`` (s), each channel's driving
    noise ``2 sigma_b^2 / T_c`` kept: ``sigma_b`` x ``sqrt(tc / its own T_c)``, in the values
    and in the projections (:meth:`~engine.formats.Projection.at_tc_keeping_q`: what the
    preview shows is what the file writes)."""
    why = f"the file's one T_c = {tc:.6g} s (the largest), driving noise kept"
    values = {k: dict(q) for k, q in nz.values.items()}
    for d in values.values():
        d["sigma_gm"] = {ax: v * math.sqrt(tc / d["T_c"][ax]) for ax, v in d["sigma_gm"].items()}
        d["T_c"] = dict.fromkeys(d["T_c"], tc)
    projs = {ch: p.at_tc_keeping_q(tc, why) for ch, p in nz.projections.items()}
    return dataclasses.replace(nz, values=values, projections=projs)


def kfgins_noise(
    fits: Mapping[str, GMWMResult], o: ExportOptions, allow_partial: bool = False
) -> ImuNoise:
    """The KF-GINS file's numbers and projections (its record's
    :attr:`~engine.formats.Format.noise`): every channel's at the file's one ``T_c``, with the
    bound the least total inflation, without it the largest, each driving noise kept."""
    return _kfgins(fits, o, allow_partial)[0]


def kfgins_yaml(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """KF-GINS ``imunoise`` block (YAML): per-axis ``arw``, ``vrw``, ``gbstd``, ``abstd`` and
    one ``corrtime``. Needs a GM (or AR1) term in every channel's model."""
    nz, own, tc_bound = _kfgins(fits, o)
    ss = float(o.scale_factor_std_ppm or 1000.0)

    g, a = "gyroscope", "accelerometer"
    if tc_bound is not None:
        tc = tc_bound
        how = (
            f"one T_c = {tc:.6g} s for every bias (KF-GINS's one corrtime): the least total "
            "inflation over the channels; each gbstd/abstd bounds its channel at that T_c"
        )
    else:  # nz is at the largest T_c already (_at_one_tc)
        tc = max(own.values())
        how = (
            f"one T_c = {tc:.6g} s (the largest; KF-GINS's one corrtime), each channel's "
            "driving noise 2 sigma^2 / T_c kept (gbstd/abstd x sqrt(T_c / its own T_c))"
        )
    lines = [f"# {c}" for c in nz.header] + [f"# warning: {w}" for w in nz.warnings]
    lines += [
        f"# arw/vrw = N; gbstd/abstd = sigma_b of the Gauss-Markov bias; corrtime: {how}",
        "# (each channel's own T_c, s: " + ", ".join(f"{k} {v:.6g}" for k, v in own.items()) + ")",
        "imunoise:",
        f"  arw: {_flow(nz.xyz(g, 'N', DISPLAY[(g, 'N')].factor))}  # [deg/sqrt(hr)]",
        f"  vrw: {_flow(nz.xyz(a, 'N', DISPLAY[(a, 'N')].factor))}  # [m/s/sqrt(hr)]",
        f"  gbstd: {_flow(nz.xyz(g, 'sigma_gm', DISPLAY[(g, 'B')].factor))}  # [deg/hr]",
        f"  abstd: {_flow(nz.xyz(a, 'sigma_gm', 1.0 / MGAL))}  # [mGal]",
        f"  corrtime: {yaml_float(tc / _HOUR)}  # [hr]",
        f"  gsstd: {_flow([ss] * 3)}  # [ppm] scale-factor std: NOT estimated by GMWM (a "
        "placeholder: set it from your IMU's datasheet)",
        f"  asstd: {_flow([ss] * 3)}  # [ppm] scale-factor std: NOT estimated by GMWM (a "
        "placeholder: set it from your IMU's datasheet)",
        "  # KF-GINS requires gsstd/asstd. Its corrtime drives the Gauss-Markov model of the",
        "  # scale-factor states too (one corrtime for gyro/accel biases and scale factors).",
    ]
    return text_lines(lines)


def _least_total_tc(fits: Mapping[str, GMWMResult], o: ExportOptions, own: list[float]) -> float:
    """The one ``T_c`` (s) of least total inflation over the channels: the sum of each
    channel's log geometric-mean ratio (:attr:`Projection.inflation`), over the channels' own
    ``T_c`` and 9 log-spaced values between the smallest and the largest."""
    cands = sorted(set(own) | set(np.geomspace(min(own), max(own), 9).tolist()))
    units = o.units or {}
    total = np.zeros(len(cands))
    for ch, res in fits.items():
        total += log_inflation_at_tc(
            res,
            cands,
            fs_filter=o.filter_rate,
            horizon_s=o.horizon_s,
            band=o.band,
            confidence=o.confidence,
            channel=ch,
            unit=units.get(ch),
            data=o.data,
            tails=(o.tail_factors or {}).get(ch),
        )
    best, arg = math.inf, own[-1]
    for c, t in zip(cands, total.tolist(), strict=True):
        if t < best:
            best, arg = t, c
    return float(arg)


def ros_imu_yaml(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """``sensor_msgs/Imu`` covariance fields (YAML): diagonal per-sample WN variances in SI
    (``inflate**2`` applied), ``orientation_covariance[0] = -1``."""
    # one sensor is enough: the record says so (Format.partial)
    nz = noise_for(fits, "sensor_msgs/Imu covariances", o, consumer="ros-imu")
    lines = [f"# {c}" for c in nz.header] + [f"# warning: {w}" for w in nz.warnings]
    lines.append(
        f"# per-sample variance of the white noise at {nz.rate:g} Hz (the consumer's IMU rate), "
        "sigma2_WN = N^2 rate (SI), row-major 3x3, axes x y z (an axis not fitted gets the max "
        "over fitted ones); the white part only: no bound on the bias (the estimator's states)"
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
