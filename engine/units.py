"""Units of the model parameters and their datasheet (IEEE / Allan-variance) equivalents.

With ``dt = 1/fs`` and signal unit ``u`` (CONVENTIONS, "Units and datasheet conversions"):

* white noise density ``N = sqrt(sigma2 dt)`` [u/sqrt(Hz)]; angle (velocity) random walk
  in deg/sqrt(h) (m/s/sqrt(h)) is ``60 N`` with N in deg/s/sqrt(Hz) (m/s^2/sqrt(Hz));
* rate random walk ``K = sqrt(gamma2 / dt)`` [u/sqrt(s)]; in deg/h/sqrt(h) multiply a
  deg/s/sqrt(s) value by 216000;
* quantization ``Q = sqrt(q2) dt`` [u s];
* drift (rate ramp) ``R = omega / dt`` [u/s];
* GM correlation time ``1/beta`` [s], driving-noise PSD ``q = 2 beta sigma2_gm`` [u^2/s].
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from .models import Model

__all__ = ["param_unit", "datasheet", "squared"]

RAD2DEG = 180.0 / math.pi
_GYRO = {"deg/s": 1.0, "rad/s": RAD2DEG, "deg/h": 1.0 / 3600.0}
_ACCEL = {"m/s^2": 1.0, "m/s2": 1.0, "g": 9.80665, "mg": 9.80665e-3}


def squared(unit: str) -> str:
    """``(deg/s)^2`` for ``deg/s``, ``g^2`` for ``g``, ``u^2`` when unknown."""
    u = unit or "u"
    return f"({u})^2" if any(c in u for c in "/* ^") else f"{u}^2"


def param_unit(code: str, name: str, unit: str = "") -> str:
    """Unit of a model parameter for a signal in ``unit`` (per-sample parametrisation)."""
    u = unit or "u"
    if name in ("sigma2", "q2", "gamma2", "sigma2_gm"):
        return squared(u)
    if name == "omega":
        return f"{u} per sample"
    if name == "beta":
        return "1/s"
    if name == "phi":
        return "1 (per sample)"
    return ""


def datasheet(model: Model, fs: float, unit: str = "") -> list[dict[str, Any]]:
    """Datasheet quantities of a model with every value set.

    Returns a list of rows ``{"label", "quantity", "value", "unit"}`` in the model's order.
    Gyroscope units (deg/s, rad/s) also give ARW in deg/sqrt(h) and RRW in deg/h/sqrt(h);
    accelerometer units (m/s^2, g) give VRW in m/s/sqrt(h) and m/s/h/sqrt(h).
    """
    u = unit or "u"
    dt = 1.0 / fs
    gyro = _GYRO.get(unit)
    acc = _ACCEL.get(unit)
    rows: list[dict[str, Any]] = []

    def add(label: str, quantity: str, value: float, unit_: str) -> None:
        rows.append({"label": label, "quantity": quantity, "value": float(value), "unit": unit_})

    for lab, p in zip(model.labels, model.processes, strict=True):
        v = dict(zip(p.param_names, p.values, strict=True))
        if any(x is None for x in v.values()):
            continue
        if p.code == "WN":
            n = math.sqrt(v["sigma2"] * dt)
            add(lab, "white noise density N", n, f"{u}/sqrt(Hz)")
            if gyro is not None:
                add(lab, "angle random walk", 60.0 * n * gyro, "deg/sqrt(h)")
            elif acc is not None:
                add(lab, "velocity random walk", 60.0 * n * acc, "m/s/sqrt(h)")
        elif p.code == "RW":
            k = math.sqrt(v["gamma2"] / dt)
            add(lab, "rate random walk K", k, f"{u}/sqrt(s)")
            if gyro is not None:
                add(lab, "rate random walk", 216000.0 * k * gyro, "deg/h/sqrt(h)")
            elif acc is not None:
                add(lab, "acceleration random walk", 216000.0 * k * acc, "m/s/h/sqrt(h)")
        elif p.code == "QN":
            add(lab, "quantization Q", math.sqrt(v["q2"]) * dt, f"{u}*s")
        elif p.code == "DR":
            add(lab, "rate ramp R", abs(v["omega"]) / dt, f"{u}/s")
        elif p.code == "GM":
            add(lab, "correlation time 1/beta", 1.0 / v["beta"], "s")
            add(lab, "stationary std sqrt(sigma2_gm)", math.sqrt(v["sigma2_gm"]), u)
            add(
                lab,
                "driving-noise PSD q = 2 beta sigma2_gm",
                2 * v["beta"] * v["sigma2_gm"],
                f"{squared(u)}/s",
            )
        elif p.code == "AR1":
            phi, s2 = v["phi"], v["sigma2"]
            if 0 < phi < 1:
                add(lab, "correlation time", -dt / math.log(phi), "s")
            add(lab, "stationary std", math.sqrt(s2 / (1 - phi * phi)), u)
    return rows
