"""What every fit returns: the error type, labelled parameter records and the result base.

Every fit result (:class:`engine.fit.GMWMResult`, :class:`engine.fit.replicates.ReplicateResult`,
:class:`engine.fit.gmwfm.GMWFMResult`, the multivariate result) derives from :class:`FitResult`,
generic in the type of its fitted model (a univariate :class:`engine.Model`: the
:class:`UnivariateFit` results; a :class:`engine.MultiModel`: the multivariate result), with
the same fields with one name and one type each (``model``, ``params``, ``objective``, the
weighting as ``weights: str`` naming the scheme and ``omega: ndarray`` the matrix, ``converged``,
``at_bound``, ``warnings``, ``n_evaluations``, ``method``, ``message``, ``elapsed_s``), and the
same methods: ``conf_int(alpha)`` (a labelled :class:`ParamTable`), ``summary()`` (a
:class:`Summary`: a string with an HTML view for notebooks) and ``to_dict()`` (JSON-ready).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from .._jsonutil import JsonFields
from ..errors import FitError
from ..models import Model
from ..units import param_unit
from ..wv import WaveletVariance

__all__ = [
    "FitError",
    "FitResult",
    "FittedModel",
    "OneWVFit",
    "ParamRecord",
    "ParamTable",
    "Summary",
    "UnivariateFit",
    "warning_lines",
]


@dataclass(frozen=True)
class ParamRecord(JsonFields):
    """One estimated parameter with its label and unit."""

    process: str
    index: int
    label: str
    name: str
    value: float
    unit: str

    json_fields = "process index label name value unit"  # to_dict()'s keys

    @property
    def full_name(self) -> str:
        return f"{self.label}.{self.name}"


def warning_lines(at_bound: Any, converged: bool, message: str, warnings: Any = ()) -> list[str]:
    """The warning lines that end a fit summary (parameters at a bound, the fit's readable
    ``warnings``, no convergence)."""
    lines: list[str] = []
    if at_bound:
        lines += ["", f"  warning: at a bound: {', '.join(at_bound)}"]
    for w in warnings:
        lines += ["", f"  warning: {w}"]
    if not converged:
        lines += ["", f"  warning: {message}"]
    return lines


class Summary(str):
    """A fit summary: the text table (it is a ``str``) with an HTML view for notebooks."""

    def _repr_html_(self) -> str:
        return f"<pre>{html.escape(str(self))}</pre>"


@dataclass(frozen=True)
class ParamTable:
    """Labelled interval table: one row per parameter (name, estimate, lower, upper, unit)."""

    names: tuple[str, ...]
    estimate: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    units: tuple[str, ...]
    level: float

    def __len__(self) -> int:
        return len(self.names)

    def row(self, name: str) -> tuple[float, float, float]:
        """Estimate, lower and upper bound of one parameter by its unique name."""
        i = self.names.index(name)
        return float(self.estimate[i]), float(self.lower[i]), float(self.upper[i])

    def __str__(self) -> str:
        pct = f"{100 * self.level:g} %"
        lines = [f"  {'parameter':<16} {'estimate':>13} {'lower':>13} {'upper':>13}  unit ({pct})"]
        for n, e, lo, hi, u in zip(
            self.names, self.estimate, self.lower, self.upper, self.units, strict=True
        ):
            lines.append(f"  {n:<16} {e:>13.6e} {lo:>13.6e} {hi:>13.6e}  {u}")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        head = "".join(f"<th>{h}</th>" for h in ("parameter", "estimate", "lower", "upper", "unit"))
        rows = "".join(
            f"<tr><td>{html.escape(n)}</td><td>{e:.6e}</td><td>{lo:.6e}</td><td>{hi:.6e}</td>"
            f"<td>{html.escape(u)}</td></tr>"
            for n, e, lo, hi, u in zip(
                self.names, self.estimate, self.lower, self.upper, self.units, strict=True
            )
        )
        return f"<table><tr>{head}</tr>{rows}</table>"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{name: {"estimate", "lower", "upper", "unit"}}`` and the level."""
        return {
            "level": float(self.level),
            "params": {
                n: {"estimate": float(e), "lower": float(lo), "upper": float(hi), "unit": u}
                for n, e, lo, hi, u in zip(
                    self.names, self.estimate, self.lower, self.upper, self.units, strict=True
                )
            },
        }


class OneWVFit:
    """A fit of one channel's WV (GMWM, GMWFM): its sampling rate and unit are the WV's."""

    wv: WaveletVariance

    @property
    def fs(self) -> float:
        """Sampling frequency of the fitted WV (Hz)."""
        return self.wv.fs

    @property
    def unit(self) -> str:
        """Signal unit of the fitted WV."""
        return self.wv.unit


class FittedModel(Protocol):
    """What the base of a fit result needs of its model: its specification string."""

    def spec(self, values: bool = False) -> str: ...


ModelT = TypeVar("ModelT", bound=FittedModel)


@dataclass(frozen=True, eq=False, kw_only=True)
class FitResult(Generic[ModelT]):
    """Base of every fit result, generic in the type of its fitted model.

    Attributes
    ----------
    model : ModelT
        The fitted model, every parameter set: an :class:`engine.Model` (AR1/GM most
        persistent first, :class:`UnivariateFit`) or an :class:`engine.MultiModel`.
    weights : str
        The weighting scheme: ``"ci"``, ``"identity"``, ``"efficient"`` or ``"user"``.
    omega : ndarray
        The weighting matrix itself (for a replicate fit, block diagonal over the stacked
        levels of the recordings).
    objective : float
        The minimised objective at the estimate.
    converged : bool
        True when the local search met its tolerance.
    at_bound : list[str]
        Parameters estimated on the boundary of their space.
    warnings : list[str]
        Readable warnings about the estimate: an AR1/GM whose correlation time is shorter
        than one sample (white noise in disguise, :func:`engine.fit._varpro.sub_sample_message`).
    n_evaluations : int
        Number of objective evaluations.
    method : str
        The algorithm (``"closed-form"``, ``"grid+nelder-mead"`` ...).
    message : str
        Human-readable convergence note.
    elapsed_s : float
        Wall time of the fit (s).
    """

    model: ModelT
    weights: str
    omega: np.ndarray
    objective: float
    converged: bool = True
    at_bound: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    n_evaluations: int = 0
    method: str = ""
    message: str = ""
    elapsed_s: float = 0.0

    # what a subclass provides
    @property
    def fs(self) -> float:
        """Sampling frequency (Hz)."""
        raise NotImplementedError

    @property
    def unit(self) -> str:
        """Signal unit."""
        return ""

    def _summary_head(self) -> list[str]:
        return [f"fit of {self.model.spec()}"]

    def _summary_tail(self) -> list[str]:
        return []

    def _dict_extra(self) -> dict[str, Any]:
        return {}

    @property
    def param_records(self) -> Sequence[ParamRecord]:
        """Parameters with process code, index among its kind, label, name, value and unit."""
        raise NotImplementedError

    # shared
    @property
    def params(self) -> dict[str, float]:
        """Estimated values by unique name (``WN.sigma2``, ``GM_1.beta`` ...)."""
        return {r.full_name: r.value for r in self.param_records}

    def conf_int(self, alpha: float = 0.05) -> ParamTable:
        """Two-sided ``1 - alpha`` asymptotic intervals of every parameter (see
        :func:`engine.inference.param_intervals`)."""
        raise FitError(f"asymptotic intervals are not available for a {type(self).__name__}")

    def summary(self) -> Summary:
        """Readable summary: model, data, parameters with units, fit, warnings."""
        lines = self._summary_head() + ["", f"  {'parameter':<16} {'value':>14}  unit"]
        for r in self.param_records:
            lines.append(f"  {r.full_name:<16} {r.value:>14.6e}  {r.unit}")
        lines += self._summary_tail()
        lines += warning_lines(self.at_bound, self.converged, self.message, self.warnings)
        return Summary("\n".join(lines))

    def __str__(self) -> str:
        return str(self.summary())

    def _repr_html_(self) -> str:
        return self.summary()._repr_html_()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        d: dict[str, Any] = {
            "model": self.model.spec(),
            "model_values": self.model.spec(values=True),
            "fs": float(self.fs),
            "weights": self.weights,
            "objective": float(self.objective),
            "params": [r.to_dict() for r in self.param_records],
            "converged": bool(self.converged),
            "at_bound": list(self.at_bound),
            "warnings": list(self.warnings),
            "method": self.method,
            "n_evaluations": int(self.n_evaluations),
        }
        d.update(self._dict_extra())
        return d


@dataclass(frozen=True, eq=False, kw_only=True)
class UnivariateFit(FitResult[Model]):
    """Base of the results whose model is one univariate :class:`engine.Model` (GMWM, GMWFM,
    replicates): its parameter records are the model's processes' values."""

    @property
    def param_records(self) -> Sequence[ParamRecord]:
        """Parameters with process code, index among its kind, label, name, value and unit."""
        m = self.model
        return [
            ParamRecord(p.code, idx, lab, name, float(v), param_unit(p.code, name, self.unit))
            for lab, idx, p in zip(m.labels, m.indices, m.processes, strict=True)
            for name, v in zip(p.param_names, p.values, strict=True)
            if v is not None  # a fitted model: every value is set
        ]
