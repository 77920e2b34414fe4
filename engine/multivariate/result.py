"""Results of the multivariate GMWM: :class:`MGMWMResult` and its :class:`SharedEstimate`."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..fit.result import FitResult, ParamRecord, ParamTable, Summary, warning_lines
from ..models import Model
from ..units import param_unit
from ..wv import WVMatrix
from .moments import conf_int as moments_conf_int
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


@dataclass(frozen=True)
class MultiParamRecord(ParamRecord):
    """One estimate of a multivariate fit (:class:`engine.fit.result.ParamRecord` plus where
    it belongs).

    ``label`` is the process's label in the channel models (``"WN"``, ``"GM_1"``) and
    ``name`` the parameter (``"sigma2"``, ``"beta"``, ``"cov[gyro_x,gyro_y]"`` for an entry of
    a shared covariance); ``channels`` the channel (independent process) or the group
    (shared process), ``shared`` which of the two. The unique name :attr:`full_name` is
    ``channel.label.name`` for an independent process, ``label.name`` for a shared one.
    """

    channels: tuple[str, ...] = ()
    shared: bool = False

    @property
    def full_name(self) -> str:
        head = self.label if self.shared else f"{self.channels[0]}.{self.label}"
        return f"{head}.{self.name}"

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["full_name"] = self.full_name
        d["channels"] = list(self.channels)
        d["shared"] = self.shared
        return d


@dataclass(frozen=True, eq=False, kw_only=True)
class MGMWMResult(FitResult[MultiModel]):
    """Result of :func:`fit_mgmwm` (the fields of :class:`engine.fit.result.FitResult`, plus:).

    Attributes
    ----------
    model : MultiModel
        The fitted model, every value set (the base :class:`engine.fit.result.FitResult` is
        generic in its model's type: here a :class:`MultiModel`).
    wvm : WVMatrix
        The empirical WV/WCCV matrix it was fitted to.
    implied : ndarray, shape (J, k, k)
        Model-implied WV (diagonal) and WCCV (off-diagonal).
    components : dict of str to ndarray (J, k, k)
        Implied array of each process (``"RW"`` shared, ``"gyro_x:WN"`` independent).
    psd_active : bool
        The positive semi-definiteness constraint of a covariance was active at the
        estimate (the coupled problem was solved).
    n_inner : int
        Newton steps of the PSD-constrained inner solves, over all evaluations (0 when the
        constraint was never active; a few per such evaluation).

    ``weights`` is ``"ci"``, ``"identity"``, ``"user"`` or ``"efficient"``; ``omega`` the
    (P J, P J) weighting matrix of the stacked moments (pair by pair, levels inside, ``P =
    k (k + 1) / 2``): diagonal except for efficient weights (:attr:`moment_weights` gives
    its diagonal as a (J, k, k) array). ``objective`` is ``sum_{p <= q, j} w (nu_hat -
    nu)^2`` at the estimate (``r' omega r`` for efficient weights); ``at_bound`` lists
    variances at 0, singular covariances and correlation times at the edge of the explored
    range; ``method`` is ``"closed-form"`` (no AR1/GM) or ``"profiled nelder-mead"``.
    """

    wvm: WVMatrix
    implied: np.ndarray
    components: dict[str, np.ndarray]
    psd_active: bool = False
    n_inner: int = 0

    @property
    def moment_weights(self) -> np.ndarray:
        """The weight of every moment (the diagonal of ``omega``), shape (J, k, k), symmetric."""
        k, nj = self.wvm.k, self.wvm.n_levels
        dg = np.diagonal(self.omega)
        out = np.zeros((nj, k, k))
        pairs = [(p, q) for p in range(k) for q in range(p, k)]
        for pi, (p, q) in enumerate(pairs):
            out[:, p, q] = out[:, q, p] = dg[pi * nj : (pi + 1) * nj]
        return out

    @property
    def unit(self) -> str:
        """The channels' common unit ("" when they differ)."""
        units = {self._unit(c) for c in self.channels}
        return units.pop() if len(units) == 1 else ""

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
    def param_records(self) -> list[MultiParamRecord]:
        """Every estimate, shared processes first (their beta/phi, then the upper triangle of
        their covariance), then each channel's own; unique names ``channel.label.name`` for
        independent processes, ``label.cov[a,b]`` (a <= b) and ``label.beta``/``.phi`` for
        shared ones (:attr:`MultiParamRecord.full_name`)."""
        out: list[MultiParamRecord] = []
        for lab, est in self.shared.items():
            g = est.channels
            m = self.model.models[g[0]]
            idx = m.indices[self.model.index(lab, g[0])]
            if est.nl is not None:
                unit = param_unit(est.code, str(est.nl_name))
                out.append(
                    MultiParamRecord(
                        est.code, idx, lab, str(est.nl_name), float(est.nl), unit, g, True
                    )
                )
            for a, b in itertools.combinations_with_replacement(range(len(g)), 2):
                out.append(
                    MultiParamRecord(
                        est.code,
                        idx,
                        lab,
                        f"cov[{g[a]},{g[b]}]",
                        float(est.cov[a, b]),
                        est.unit,
                        (g[a], g[b]),
                        True,
                    )
                )
        for t in self.model.terms():
            if t.shared:
                continue
            c = self.channels[t.chans[0]]
            m = self.model.models[c]
            idx = m.indices[m.labels.index(t.label)]
            for name, v in zip(t.proto.param_names, t.proto.values, strict=True):
                if v is None:  # a fitted model: every value is set
                    continue
                unit = param_unit(t.code, name, self._unit(c))
                out.append(MultiParamRecord(t.code, idx, t.label, name, float(v), unit, (c,)))
        return out

    def conf_int(self, alpha: float = 0.05) -> ParamTable:
        """Two-sided ``1 - alpha`` asymptotic intervals of every estimate (the sandwich
        covariance with the model-implied covariance of the stacked WV/WCCV moments,
        :func:`engine.multivariate.moments.conf_int`); an estimate on a boundary gets ``nan``
        bounds."""
        return moments_conf_int(self, alpha)

    def implied_at(self, tau_samples: np.ndarray) -> np.ndarray:
        """Implied (J', k, k) array at other scales (samples), e.g. for smooth curves."""
        return self.model.implied(tau_samples, self.fs)

    def summary(self) -> Summary:
        """Readable summary: data, per-channel parameters, shared covariances/correlations."""
        w = self.wvm
        lines = [
            f"MGMWM fit of {self.model.spec()}",
            f"  data: {w.k} channels, N = {w.n} samples, fs = {w.fs:g} Hz, {w.n_levels} levels",
            f"  weights: {self.weights}; objective = {self.objective:.6g}; {self.method}, "
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
        lines += warning_lines(self.at_bound, self.converged, self.message, self.warnings)
        return Summary("\n".join(lines))

    def _dict_extra(self) -> dict[str, Any]:
        """The ``gmwm fit --channels --json`` object beyond the base's keys."""
        return {
            "kind": "mgmwm",
            "channels": list(self.channels),
            "n": int(self.wvm.n),
            "channel_models": {c: m.spec(values=True) for c, m in self.channel_models.items()},
            "shared": {k: v.to_dict() for k, v in self.shared.items()},
            "implied": self.implied.tolist(),
            "components": {k: v.tolist() for k, v in self.components.items()},
            "psd_active": bool(self.psd_active),
            "n_inner": int(self.n_inner),
            "wv_matrix": self.wvm.to_dict(),
        }
