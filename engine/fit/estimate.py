"""The common form of every estimator's answer (GMWM, ARMAV/GMWFM, the slope method), which the
app and the Monte Carlo study put side by side, and a table that compares them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..models import Model
from ..units import BI_FACTOR, datasheet, param_unit
from .gmwm import GMWMResult

__all__ = ["MethodEstimate", "from_gmwm", "compare_table", "model_components"]


# -------------------------------------------------------------------------------------------
# the common result form
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MethodEstimate:
    """One estimator's answer, in the form shared by GMWM, ARMAV/GMWFM and the slope method.

    Attributes
    ----------
    method : str
        ``"GMWM"``, ``"ARMAV"``, ``"GMWFM(f)"``, ``"AVSM"`` or ``"AVSM-auto"``.
    model : Model
        The processes the method estimated, every value set (per-sample parameters, as
        everywhere in the engine).
    params : dict[str, float]
        Values by the engine's unique names (``WN.sigma2``, ``QN.q2``, ``RW.gamma2``,
        ``DR.omega``, ``GM_1.beta`` ...).
    tau_samples : ndarray of int, shape (J,)
        The empirical Haar WV scales (samples); for an Allan variance, ``2m``.
    implied : ndarray, shape (J,)
        The WV the estimate implies at those scales (half the implied AVAR at ``m = tau/2``).
    components : dict[str, ndarray]
        Implied WV of each process by label (``WN``, ``GM_1`` ...; ``BI`` for the slope
        method's bias-instability floor), summing to ``implied``.
    fs : float
        Sampling frequency (Hz).
    unit : str
        Signal unit.
    extras : dict[str, float]
        Quantities outside the engine's processes, e.g. ``BI.B``: the bias instability B
        [unit] of the slope method (flicker noise, whose AVAR floor is ``(0.664 B)^2``).
    objective : float or None
        The minimised objective (GMWM/GMWFM), None for the slope methods.
    notes : tuple of str
        How the estimate was made (weights, regions, slopes found ...).
    details : dict
        JSON-ready method-specific data; for the slope methods ``lines``: per process the
        fitted line ``log10 ADEV = intercept + slope log10 tau_s`` over ``[tau_lo, tau_hi]``
        seconds with the averaging time and value read off it.
    """

    method: str
    model: Model
    params: dict[str, float]
    tau_samples: np.ndarray
    implied: np.ndarray
    components: dict[str, np.ndarray]
    fs: float
    unit: str = ""
    extras: dict[str, float] = field(default_factory=dict)
    objective: float | None = None
    notes: tuple[str, ...] = ()
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def tau_s(self) -> np.ndarray:
        """WV scales in seconds."""
        return self.tau_samples / self.fs

    @property
    def implied_avar(self) -> np.ndarray:
        """Implied Allan variance at averaging times ``tau_samples / 2``."""
        return 2.0 * self.implied

    @property
    def implied_adev(self) -> np.ndarray:
        """Implied Allan deviation at averaging times ``tau_samples / 2``."""
        return np.sqrt(2.0 * self.implied)

    def implied_at(self, tau_samples: np.ndarray) -> np.ndarray:
        """Implied WV at other scales (samples), e.g. for a smooth curve."""
        tau = np.asarray(tau_samples, dtype=float)
        out = self.model.wv(tau, self.fs) if len(self.model) else np.zeros_like(tau)
        b = self.extras.get("BI.B")
        if b is not None:
            out = out + 0.5 * (BI_FACTOR * b) ** 2
        return out

    def datasheet(self) -> list[dict[str, Any]]:
        """Datasheet rows (see :func:`engine.units.datasheet`), plus the bias instability if any."""
        return datasheet(self.model, self.fs, self.unit, extras=self.extras)

    def summary(self) -> str:
        """Readable summary: method, parameters with units, datasheet view, notes."""
        lines = [
            f"{self.method} estimate of {self.model.spec() or '(no process)'}",
            f"  fs = {self.fs:g} Hz, {self.tau_samples.size} scales",
        ]
        if self.objective is not None:
            lines[-1] += f", objective = {self.objective:.6g}"
        lines += ["", f"  {'parameter':<16} {'value':>14}  unit"]
        for name, v in self.params.items():
            lab, pname = name.split(".", 1)
            code = lab.split("_")[0]
            lines.append(f"  {name:<16} {v:>14.6e}  {param_unit(code, pname, self.unit)}")
        for name, v in self.extras.items():
            lines.append(f"  {name:<16} {v:>14.6e}  {self.unit or 'u'}")
        ds = self.datasheet()
        if ds:
            lines += ["", "  datasheet view:"]
            for row in ds:
                lines.append(
                    f"  {row['label']:<8} {row['quantity']:<40} {row['symbol']:<8} "
                    f"{row['value']:>12.5g}  {row['unit']}"
                )
        if self.notes:
            lines += [""] + [f"  note: {s}" for s in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "method": self.method,
            "model": self.model.spec(),
            "model_values": self.model.spec(values=True),
            "params": {k: float(v) for k, v in self.params.items()},
            "extras": {k: float(v) for k, v in self.extras.items()},
            "fs": float(self.fs),
            "unit": self.unit,
            "tau_samples": [int(v) for v in self.tau_samples],
            "implied": [float(v) for v in self.implied],
            "components": {k: [float(x) for x in v] for k, v in self.components.items()},
            "objective": None if self.objective is None else float(self.objective),
            "notes": list(self.notes),
            "details": self.details,
        }


def from_gmwm(res: GMWMResult, method: str = "GMWM") -> MethodEstimate:
    """A GMWM fit in the common form (same model, parameters, implied WV and components)."""
    notes = [f"GMWM, weights {res.weights}, {res.method}"]
    if res.at_bound:
        notes.append(f"at a bound: {', '.join(res.at_bound)}")
    return MethodEstimate(
        method=method,
        model=res.model,
        params=dict(res.params),
        tau_samples=np.asarray(res.wv.tau_samples),
        implied=np.asarray(res.implied),
        components=dict(res.components),
        fs=float(res.wv.fs),
        unit=res.wv.unit,
        objective=float(res.objective),
        notes=tuple(notes),
        details={"weights": res.weights, "at_bound": list(res.at_bound)},
    )


def model_components(model: Model, tau: np.ndarray, fs: float) -> dict[str, np.ndarray]:
    return model.components(tau, fs) if len(model) else {}


# -------------------------------------------------------------------------------------------
# side by side
# -------------------------------------------------------------------------------------------
def compare_table(estimates: Sequence[MethodEstimate], truth: Model | None = None) -> str:
    """A text table of the parameters of several estimates (and the truth), side by side."""
    names: list[str] = []
    for e in estimates:
        for k in list(e.params) + list(e.extras):
            if k not in names:
                names.append(k)
    tv = truth.values() if truth is not None else {}
    for k in tv:
        if k not in names:
            names.append(k)
    heads = [e.method for e in estimates] + (["truth"] if truth is not None else [])
    lines = [f"{'parameter':<14}" + "".join(f"{h:>14}" for h in heads)]
    for k in names:
        row = f"{k:<14}"
        for e in estimates:
            v = e.params.get(k, e.extras.get(k))
            row += f"{v:>14.5e}" if v is not None else f"{'-':>14}"
        if truth is not None:
            v = tv.get(k)
            row += f"{v:>14.5e}" if v is not None else f"{'-':>14}"
        lines.append(row)
    return "\n".join(lines)
