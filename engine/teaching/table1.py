"""The setting of the GMWM paper's Monte Carlo (Table I, Fig. 1-2): the true models of the
STIM-300 gyroscope and accelerometer at 250 Hz, their datasheet units, and the regions a
typical slope-method user picks. Shared by :mod:`engine.teaching.study` (the runs) and
:mod:`engine.teaching.study_result` (the tables and plots)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..models import DR, PROCESS_TYPES, QN, RW, WN, Model
from ..units import DISPLAY, QUANTITIES, si_factor
from ..units import from_datasheet as units_from_datasheet
from ..units import to_datasheet as units_to_datasheet
from ..wv import default_levels

__all__ = [
    "TABLE_I",
    "STUDY_FS",
    "STUDY_N",
    "METHODS",
    "DEFAULT_METHODS",
    "PARAM_OF",
    "SENSOR_ID",
    "from_datasheet",
    "to_datasheet",
    "table1_model",
    "typical_regions",
]


STUDY_FS = 250.0


STUDY_N = (2_500_000, 6_300_000)


#: ``GMWM`` uses the R-default ``ci`` weights; ``GMWM-efficient`` the two-step efficient weights
#: ``Omega = V^-1`` with V implied by the first (``ci``) fit's model (the GMWM paper, Corollary 1).
METHODS = ("GMWM", "GMWM-efficient", "ARMAV", "ARMAV-unweighted", "AVSM", "AVSM-auto")


DEFAULT_METHODS = ("GMWM", "GMWM-efficient", "ARMAV", "AVSM")


SENSOR_ID = {"gyro": 1, "accel": 2}


#: Table I of the GMWM paper: per sensor, the signal unit and (code, symbol, value, unit).
TABLE_I: dict[str, dict[str, Any]] = {
    "gyro": {
        "unit": "deg/s",
        "label": "Gyro",
        "params": (
            (WN.code, "sigma", 1.57e-1, "deg/sqrt(h)"),
            (RW.code, "gamma", 1.34, "deg/h/sqrt(h)"),
        ),
    },
    "accel": {
        "unit": "m/s^2",
        "label": "Accel",
        "params": (
            (QN.code, "Q", 1.79e-6, "m/s"),
            (WN.code, "sigma", 4.70e-2, "m/s/sqrt(h)"),
            (RW.code, "gamma", 4.35e1, "m/s/h/sqrt(h)"),
            (DR.code, "omega", 4.14e1, "m/s/h^2"),
        ),
    },
}


#: Per Table I process, the unique name of its parameter in a one-of-a-kind model.
PARAM_OF = {
    c: f"{c}.{PROCESS_TYPES[c].param_names[0]}"
    for c in dict.fromkeys(code for s in TABLE_I.values() for code, *_ in s["params"])
}


# -------------------------------------------------------------------------------------------
# units
# -------------------------------------------------------------------------------------------
def _display_symbol(code: str) -> str | None:
    """Symbol of the hour-based display of a process (ARW/RRW/R) in :data:`engine.units.DISPLAY`;
    the same for gyroscopes and accelerometers (only the time unit changes)."""
    sym = QUANTITIES[code][0].symbol
    return sym if ("gyroscope", sym) in DISPLAY else None


def _display_factor(code: str, unit: str) -> float:
    """Factor from the native datasheet value (N, K, Q, R) of a ``unit`` signal to Table I's."""
    sym = _display_symbol(code)
    if sym is None:
        return 1.0  # Q is quoted in integrated units (u s)
    kind, f_si = si_factor(unit)
    return f_si * DISPLAY[(kind, sym)].factor


def to_datasheet(code: str, value: float, fs: float, unit: str = "deg/s") -> float:
    """Table I datasheet value of a per-sample parameter (signal in deg/s or m/s^2).

    The native value of :func:`engine.units.to_datasheet` (``N = sqrt(sigma2 dt)``,
    ``K = sqrt(gamma2 / dt)``, ``Q = sqrt(q2) dt``, ``R = omega / dt``) in the display unit of
    :data:`engine.units.DISPLAY` (``60 N`` per sqrt(h), ``216000 K`` per h per sqrt(h),
    ``3600^2 R`` per h^2; Q in u s). deg/s and m/s^2 give the same factors (only hours enter).

    Parameters
    ----------
    code, value, fs
        The process (WN, RW, QN or DR), its per-sample value and the sampling frequency (Hz),
        as for :func:`engine.units.to_datasheet`.
    unit : str
        Signal unit (``"deg/s"`` or ``"m/s^2"``).
    """
    return units_to_datasheet(code, value, fs) * _display_factor(code, unit)


def from_datasheet(code: str, value: float, fs: float, unit: str = "deg/s") -> float:
    """Per-sample parameter from a Table I datasheet value (inverse of :func:`to_datasheet`)."""
    return units_from_datasheet(code, value / _display_factor(code, unit), fs)


def table1_model(sensor: str, fs: float = STUDY_FS) -> Model:
    """The true model of Table I for ``"gyro"`` (WN + RW, deg/s) or ``"accel"``
    (QN + WN + RW + DR, m/s^2), with per-sample parameters at ``fs``."""
    if sensor not in TABLE_I:
        raise ValueError(f"unknown sensor {sensor!r}: use 'gyro' or 'accel'")
    return Model(
        tuple(
            PROCESS_TYPES[c](from_datasheet(c, v, fs, TABLE_I[sensor]["unit"]))
            for c, _, v, _ in TABLE_I[sensor]["params"]
        )
    )


# -------------------------------------------------------------------------------------------
# the slope method's regions
# -------------------------------------------------------------------------------------------
def typical_regions(sensor: str, n: int, fs: float = STUDY_FS) -> dict[str, tuple[float, float]]:
    """Averaging-time regions (s) that a typical user picks on the octave ADEV plot.

    Chosen by looking at the Allan deviation of one simulated log, as a user does, without
    knowledge of where the processes overlap:

    * gyroscope: WN over the straight -1/2 part, from the first point up to 10 s (well before
      the minimum, near 700 s; for short logs at most up to the sixth point from the end);
      RW over the last three points, where the curve turns up.
    * accelerometer (the model says QN, WN, RW and DR): QN (slope -1) over the first two
      points (4 and 8 ms; on the plot the curve has slope -1/2 there: the QN is hidden under
      the WN); WN over 15 ms to 1.1 s; RW over 30 to 300 s, the straight +1/2 part after the
      minimum (near 7 s); DR (slope +1) over the last two points, where the curve steepens.
      For short logs the RW region stops before the DR points (at least one point kept).

    Parameters
    ----------
    sensor : {"gyro", "accel"}
    n : int
        Log length (samples); the octave averaging times are ``2^k``, ``k < floor(log2(n-1))``.
    fs : float
        Sampling frequency (Hz).
    """
    tau = 2.0 ** np.arange(default_levels(n)) / fs
    if tau.size < 6:
        raise ValueError(f"a log of {n} samples is too short for the slope method's regions")
    if sensor == "gyro":
        wn_hi = min(10.0, float(tau[-6]))
        return {WN.code: (float(tau[0]), wn_hi), RW.code: (float(tau[-3]), float(tau[-1]))}
    if sensor == "accel":
        dr = (float(tau[-2]), float(tau[-1]))
        rw_pts = tau[(tau >= 30.0) & (tau <= 300.0) & (tau < dr[0])]
        if rw_pts.size == 0:
            rw_pts = tau[-3:-2]
        return {
            QN.code: (float(tau[0]), float(tau[1])),
            WN.code: (0.015, 1.1),
            RW.code: (float(rw_pts[0]), float(rw_pts[-1])),
            DR.code: dr,
        }
    raise ValueError(f"unknown sensor {sensor!r}: use 'gyro' or 'accel'")
