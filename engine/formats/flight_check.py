"""A vehicle's EKF noise parameters against its own log's still segments.

The parameters a PX4 (``EKF2_GYR_NOISE``, ``EKF2_ACC_NOISE``, ``EKF2_GYR_B_NOISE``,
``EKF2_ACC_B_NOISE``) or ArduPilot (``EK3_GYRO_P_NSE``, ``EK3_ACC_P_NSE``,
``EK3_GBIAS_P_NSE``, ``EK3_ABIAS_P_NSE``) vehicle flew with are compared with the values
:func:`engine.formats.autopilot.autopilot_params` derives from GMWM fits of the log's still
segments (the same conversion as ``gmwm export --format px4|ardupilot``: density x
sqrt(filter rate), max over axes). The ratio flown / measured says:

* below 1: **too small**, the EKF trusts the sensor more than its still noise allows (it is
  overconfident even before vibration adds to the noise in flight);
* above :data:`TOO_LARGE` (10): **too large**, the EKF discounts the sensor (slow to follow
  it, slow to learn its bias);
* between: consistent, with that margin for vibration in flight.

The parameters come from a parameter file (:func:`read_params_file`: QGroundControl
``.params``, Mission Planner ``.param``) or from the log itself (ULog ``P`` messages,
DataFlash ``PARM``: ``ImuLog.meta["params"]``). (``gmwm check``'s reading of PX4 ``.params``
files for other checks is another module's; this one only compares noise parameters.)
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..fit import GMWMResult
from ..units import ExportError
from .autopilot import RANGES, autopilot_params
from .options import ExportOptions

__all__ = [
    "TOO_LARGE",
    "ParamVerdict",
    "FlightParamCheck",
    "read_params_file",
    "check_flight_params",
]

#: Ratio flown / measured above which a parameter is called too large.
TOO_LARGE = 10.0
#: Default filter rates (Hz): PX4 EKF2_PREDICT_US = 10 000 us; ArduPilot EKF3 12 ms steps.
DEFAULT_RATE = {"EKF2_": 100.0, "EK3_": 83.0}


@dataclass(frozen=True)
class ParamVerdict:
    """One parameter: flown value, measured value, ratio and verdict."""

    name: str
    unit: str
    flown: float
    measured: float
    ratio: float
    verdict: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return dict(self.__dict__)


@dataclass(frozen=True)
class FlightParamCheck:
    """The verdicts of :func:`check_flight_params`."""

    autopilot: str
    filter_rate: float
    rows: tuple[ParamVerdict, ...]
    notes: tuple[str, ...] = ()

    def table(self) -> str:
        """Readable table with units."""
        lines = [
            f"{self.autopilot} noise parameters flown vs the log's still segments "
            f"(filter rate {self.filter_rate:g} Hz)",
            f"  {'parameter':<18} {'flown':>12} {'measured':>12} {'ratio':>8}  verdict",
        ]
        for r in self.rows:
            lines.append(
                f"  {r.name:<18} {r.flown:>12.4g} {r.measured:>12.4g} {r.ratio:>8.3g}  "
                f"{r.verdict} [{r.unit}]"
            )
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "autopilot": self.autopilot,
            "filter_rate": self.filter_rate,
            "params": [r.to_dict() for r in self.rows],
            "notes": list(self.notes),
        }


def read_params_file(path: str | Path) -> dict[str, float]:
    """Parameters from a QGroundControl ``.params`` file (``vid<TAB>cid<TAB>NAME<TAB>VALUE
    <TAB>type``) or a Mission Planner ``.param`` file (``NAME,VALUE`` or ``NAME VALUE``);
    ``#`` starts a comment.

    Raises
    ------
    ExportError
        An unreadable file, or one with no ``NAME VALUE`` line (the message names the file).
    """
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ExportError(f"cannot read the parameter file '{path}' ({exc})") from None
    out: dict[str, float] = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        fields = [f for f in re.split(r"[\t,; ]+", line) if f]
        if len(fields) >= 5 and fields[0].isdigit():  # QGC: vid cid name value type
            fields = fields[2:4]
        if len(fields) >= 2 and re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", fields[0]):
            try:
                out[fields[0]] = float(fields[1])
            except ValueError:
                continue
    if not out:
        raise ExportError(
            f"the parameter file '{path}' has no NAME VALUE line: give a QGroundControl "
            ".params or a Mission Planner .param file"
        )
    return out


def check_flight_params(
    fits: Mapping[str, GMWMResult],
    params: Mapping[str, float],
    *,
    filter_rate: float | None = None,
) -> FlightParamCheck:
    """Compare a vehicle's EKF noise parameters with GMWM fits of its still segments.

    Parameters
    ----------
    fits : mapping of channel name to GMWMResult
        Fits of the gyroscope and accelerometer channels (WN+RW or richer), e.g. of
        ``load_log(flight, segments="auto")``.
    params : mapping of str to float
        The vehicle's parameters (``EKF2_*`` for PX4, ``EK3_*`` for ArduPilot).
    filter_rate : float, optional
        The EKF's prediction rate (Hz). Default: ``1e6 / EKF2_PREDICT_US`` when the PX4
        parameters hold it, else 100 Hz (PX4) or 83 Hz (ArduPilot EKF3).

    Returns
    -------
    FlightParamCheck

    Raises
    ------
    ExportError
        No EKF2/EK3 noise parameter in ``params``; the errors of the export's conversion.
    """
    prefix = next(
        (p for p in ("EKF2_", "EK3_") if any(k.startswith(p) and k in RANGES for k in params)),
        None,
    )
    if prefix is None:
        names = ", ".join(k for k in RANGES)
        raise ExportError(
            f"no EKF noise parameter among the {len(params)} given (looked for {names}): "
            "give the vehicle's .params/.param file"
        )
    notes: list[str] = []
    if filter_rate is None:
        us = params.get("EKF2_PREDICT_US")
        filter_rate = 1e6 / us if prefix == "EKF2_" and us else DEFAULT_RATE[prefix]
        notes.append(f"filter rate {filter_rate:g} Hz (pass filter_rate= if it differs)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        measured, _, warn = autopilot_params(fits, prefix, ExportOptions(filter_rate=filter_rate))
    notes += [str(w.message) for w in caught if str(w.message) not in warn] + list(warn)
    rows = []
    for name, value in measured.items():
        if name not in params:
            continue
        flown = float(params[name])
        ratio = flown / value if value > 0 else math.inf
        if ratio < 1:
            verdict = f"too small: the EKF trusts the sensor {1 / ratio:.3g}x more than its noise"
        elif ratio > TOO_LARGE:
            verdict = f"too large: {ratio:.3g}x the still noise (the EKF discounts the sensor)"
        else:
            verdict = f"consistent: {ratio:.3g}x the still noise (margin for vibration)"
        rows.append(ParamVerdict(name, RANGES[name][2], flown, value, ratio, verdict))
    autopilot = "PX4 EKF2" if prefix == "EKF2_" else "ArduPilot EKF3"
    return FlightParamCheck(autopilot, float(filter_rate), tuple(rows), tuple(notes))
