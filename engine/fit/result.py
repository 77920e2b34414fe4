"""What every fit returns: the error type, labelled parameter records and the result base."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["FitError", "ParamRecord", "warning_lines"]


class FitError(ValueError):
    """The data or the settings do not allow a fit (says what and how to fix it)."""


@dataclass(frozen=True)
class ParamRecord:
    """One estimated parameter with its label and unit."""

    process: str
    index: int
    label: str
    name: str
    value: float
    unit: str

    @property
    def full_name(self) -> str:
        return f"{self.label}.{self.name}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "process": self.process,
            "index": self.index,
            "name": self.name,
            "value": float(self.value),
            "unit": self.unit,
        }


def warning_lines(at_bound: Any, converged: bool, message: str) -> list[str]:
    """The warning lines that end a fit summary (parameters at a bound, no convergence)."""
    lines: list[str] = []
    if at_bound:
        lines += ["", f"  warning: at a bound: {', '.join(at_bound)}"]
    if not converged:
        lines += ["", f"  warning: {message}"]
    return lines
