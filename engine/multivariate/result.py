"""Results of the multivariate GMWM: :class:`MGMWMResult` and its :class:`SharedEstimate`."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..fit.result import warning_lines
from ..model import Model
from ..units import param_unit
from ..wccv import WVMatrix
from .spec import MultiModel, corr_matrix

__all__ = ["SharedEstimate", "MGMWMResult"]


@dataclass(frozen=True, eq=False)
class SharedEstimate:
    """Estimated shared process: covariance and correlation of its group.

    Attributes
    ----------
    label, code : str
        Label in the channel models and process code (WN, RW, AR1, GM).
    channels : tuple of str
        The group, in matrix order.
    cov : ndarray (g, g)
        Covariance (per sample; GM: stationary, AR1: innovation), positive semi-definite.
    nl, nl_name : float or None, str or None
        The common beta [1/s] (GM) or phi (AR1).
    unit : str
        Unit of the covariance entries.
    """

    label: str
    code: str
    channels: tuple[str, ...]
    cov: np.ndarray
    nl: float | None
    nl_name: str | None
    unit: str

    @property
    def corr(self) -> np.ndarray:
        """Correlation matrix (nan for a channel whose variance is 0)."""
        return corr_matrix(self.cov)

    @property
    def min_eigenvalue(self) -> float:
        return float(np.linalg.eigvalsh(self.cov)[0])

    def to_dict(self) -> dict[str, Any]:
        rho = self.corr
        return {
            "label": self.label,
            "process": self.code,
            "channels": list(self.channels),
            "cov": self.cov.tolist(),
            "corr": [[None if not np.isfinite(v) else float(v) for v in row] for row in rho],
            "nl": self.nl,
            "nl_name": self.nl_name,
            "unit": self.unit,
        }


@dataclass(frozen=True, eq=False)
class MGMWMResult:
    """Result of :func:`fit_mgmwm`.

    Attributes
    ----------
    model : MultiModel
        The fitted model, every value set.
    wvm : WVMatrix
        The empirical WV/WCCV matrix it was fitted to.
    weights : ndarray, shape (J, k, k)
        Weight of every moment (symmetric; the objective uses the upper triangle).
    weights_name : str
        ``"ci"``, ``"identity"``, ``"user"`` or ``"efficient"`` (then ``weights`` holds the
        diagonal of ``omega``).
    objective : float
        ``sum_{p <= q, j} w (nu_hat - nu)^2`` at the estimate (``r' omega r`` for efficient
        weights).
    implied : ndarray, shape (J, k, k)
        Model-implied WV (diagonal) and WCCV (off-diagonal).
    components : dict of str to ndarray (J, k, k)
        Implied array of each process (``"RW"`` shared, ``"gyro_x:WN"`` independent).
    converged : bool
        The non-linear search met its tolerance (always True without AR1/GM).
    at_bound : list of str
        Estimates on the boundary: variances at 0, singular covariances, correlation times
        at the edge of the explored range.
    psd_active : bool
        The positive semi-definiteness constraint of a covariance was active at the
        estimate (the coupled problem was solved).
    n_evaluations : int
        Profiled-objective evaluations.
    n_inner : int
        Newton steps of the PSD-constrained inner solves, over all evaluations (0 when the
        constraint was never active; a few per such evaluation).
    method : str
        ``"closed-form"`` (no AR1/GM) or ``"profiled nelder-mead"``.
    message : str
        Convergence note.
    elapsed_s : float
        Wall time (s).
    omega : ndarray (P J, P J) or None
        The full weighting matrix of the stacked moments (``weights="efficient"``); None
        for diagonal weights.
    """

    model: MultiModel
    wvm: WVMatrix
    weights: np.ndarray
    weights_name: str
    objective: float
    implied: np.ndarray
    components: dict[str, np.ndarray]
    converged: bool
    at_bound: list[str] = field(default_factory=list)
    psd_active: bool = False
    n_evaluations: int = 0
    method: str = ""
    message: str = ""
    elapsed_s: float = 0.0
    omega: np.ndarray | None = field(default=None, repr=False)
    n_inner: int = 0

    @property
    def channels(self) -> tuple[str, ...]:
        return self.model.channels

    @property
    def fs(self) -> float:
        return self.wvm.fs

    def _unit(self, channel: str) -> str:
        i = self.wvm.channels.index(channel)
        return self.wvm.units[i] if i < len(self.wvm.units) else ""

    @property
    def channel_models(self) -> dict[str, Model]:
        """The fitted marginal univariate model of every channel (for the diagonal panels)."""
        return {c: self.model.channel_model(c) for c in self.channels}

    @property
    def shared(self) -> dict[str, SharedEstimate]:
        """Estimated shared processes by label."""
        out = {}
        for sp in self.model.shared:
            m = self.model.models[sp.channels[0]]
            proc = m.processes[self.model.index(sp.label, sp.channels[0])]
            u = self._unit(sp.channels[0])
            out[sp.label] = SharedEstimate(
                sp.label,
                proc.code,
                sp.channels,
                np.asarray(sp.cov, float),
                sp.nl,
                proc.nonlinear,
                param_unit(proc.code, proc.param_names[-1], u),
            )
        return out

    def covariance(self, label: str) -> np.ndarray:
        """Covariance matrix of a shared process (its group's channels)."""
        return self.shared[label].cov

    def correlation(self, label: str) -> np.ndarray:
        """Correlation matrix of a shared process."""
        return self.shared[label].corr

    @property
    def param_records(self) -> list[dict[str, Any]]:
        """Every estimate as ``{"name", "value", "unit", "channels"}``: ``channel.label.name``
        for independent processes, ``label.cov[a,b]`` (a <= b) and ``label.beta``/``.phi`` for
        shared ones."""
        out: list[dict[str, Any]] = []
        for lab, est in self.shared.items():
            g = est.channels
            if est.nl is not None:
                out.append(
                    {
                        "name": f"{lab}.{est.nl_name}",
                        "value": float(est.nl),
                        "unit": param_unit(est.code, str(est.nl_name)),
                        "channels": list(g),
                    }
                )
            for a, b in itertools.combinations_with_replacement(range(len(g)), 2):
                out.append(
                    {
                        "name": f"{lab}.cov[{g[a]},{g[b]}]",
                        "value": float(est.cov[a, b]),
                        "unit": est.unit,
                        "channels": [g[a], g[b]],
                    }
                )
        for t in self.model.terms():
            if t.shared:
                continue
            c = self.channels[t.chans[0]]
            for name, v in zip(t.proto.param_names, t.proto.values, strict=True):
                out.append(
                    {
                        "name": f"{c}.{t.label}.{name}",
                        "value": float(v),
                        "unit": param_unit(t.code, name, self._unit(c)),
                        "channels": [c],
                    }
                )
        return out

    @property
    def params(self) -> dict[str, float]:
        """Flat estimates by name (see :attr:`param_records`)."""
        return {r["name"]: r["value"] for r in self.param_records}

    def implied_at(self, tau_samples: np.ndarray) -> np.ndarray:
        """Implied (J', k, k) array at other scales (samples), e.g. for smooth curves."""
        return self.model.implied(tau_samples, self.fs)

    def summary(self) -> str:
        """Readable summary: data, per-channel parameters, shared covariances/correlations."""
        w = self.wvm
        lines = [
            f"MGMWM fit of {self.model.spec()}",
            f"  data: {w.k} channels, N = {w.n} samples, fs = {w.fs:g} Hz, {w.n_levels} levels",
            f"  weights: {self.weights_name}; objective = {self.objective:.6g}; {self.method}, "
            f"{self.n_evaluations} evaluations, {1e3 * self.elapsed_s:.1f} ms"
            + ("; PSD constraint active" if self.psd_active else ""),
        ]
        for c in self.channels:
            u = self._unit(c)
            lines += ["", f"  channel {c} (marginal model):"]
            m = self.model.channel_model(c)
            sh = self.model.shared_index(c)
            for i, (lab, p) in enumerate(zip(m.labels, m.processes, strict=True)):
                tag = f" (shared {sh[i].label})" if i in sh else ""
                for name, v in zip(p.param_names, p.values, strict=True):
                    lines.append(
                        f"    {lab + '.' + name:<16} {v:>14.6e}  {param_unit(p.code, name, u)}{tag}"
                    )
        for lab, est in self.shared.items():
            g = est.channels
            width = max(12, max(len(c) for c in g) + 2)
            lines += [
                "",
                f"  shared {lab} ({est.code}) over {', '.join(g)}"
                + (
                    f"; {est.nl_name} = {est.nl:.6g}{' 1/s' if est.nl_name == 'beta' else ''}"
                    if est.nl is not None
                    else ""
                )
                + f"; covariance [{est.unit}]:",
            ]
            lines.append("    " + " " * width + "".join(f"{c:>{width}}" for c in g))
            for a, ca in enumerate(g):
                lines.append(
                    f"    {ca:<{width}}"
                    + "".join(f"{est.cov[a, b]:>{width}.4e}" for b in range(len(g)))
                )
            lines.append("    correlation:")
            rho = est.corr
            for a, ca in enumerate(g):
                lines.append(
                    f"    {ca:<{width}}"
                    + "".join(f"{rho[a, b]:>{width}.4f}" for b in range(len(g)))
                )
        lines += warning_lines(self.at_bound, self.converged, self.message)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (the ``gmwm fit --channels --json`` object)."""
        return {
            "kind": "mgmwm",
            "model": self.model.spec(),
            "channels": list(self.channels),
            "n": int(self.wvm.n),
            "fs": float(self.wvm.fs),
            "weights": self.weights_name,
            "objective": float(self.objective),
            "params": self.param_records,
            "channel_models": {c: m.spec(values=True) for c, m in self.channel_models.items()},
            "shared": {k: v.to_dict() for k, v in self.shared.items()},
            "implied": self.implied.tolist(),
            "components": {k: v.tolist() for k, v in self.components.items()},
            "converged": bool(self.converged),
            "at_bound": list(self.at_bound),
            "psd_active": bool(self.psd_active),
            "method": self.method,
            "n_evaluations": int(self.n_evaluations),
            "n_inner": int(self.n_inner),
            "wv_matrix": self.wvm.to_dict(),
        }
