"""Multivariate GMWM (MGMWM): latent models shared across channels, and replicate fits.

Multivariate latent model (the multivariate paper, section II): each of k channels is a sum
of latent processes; a WN, RW, AR1 or GM process may be *shared* by a group of channels, i.e.
be one multivariate process whose components are correlated with a covariance matrix
``Sigma`` (g x g, positive semi-definite); QN and DR are per channel only. A shared AR1/GM has
one phi (beta) for the whole group, so that every element of the group has the same WV shape.
Processes are independent of each other (the paper's Condition 1).

Implied moments. For a shared process with covariance ``Sigma`` and WV shape ``b_j`` (the
process's ``basis``: ``1/tau`` for WN, ``(tau^2 + 2) / (12 tau)`` for RW, the AR1 WV per unit
innovation variance, the GM WV per unit stationary variance) the implied WV/WCCV matrix at
level j is ``b_j Sigma``: the Haar filter is linear, so the coefficients of the group are
``b_j``-scaled copies of ``Sigma``. Independent per-channel processes add to the diagonal
only. The model's (J, k, k) array is the sum over processes.

MGMWM (the paper's eq. 8). All WV and WCCV moments, the upper triangle of the (J, k, k)
array including the diagonal, are stacked and matched:
``theta_hat = argmin sum_{p <= q, j} w_pqj (nu_hat_pqj - nu_pqj(theta))^2``, with by default
``w = 1 / (ci_high - ci_low)^2`` (the univariate ``"ci"`` weights; the diagonal uses the same
eta3 intervals, so a model without shared processes reproduces the univariate fits).

How the minimum is reached (variable projection, as the univariate fit). For fixed AR1/GM
parameters the implied moments are linear in the variances ``h >= 0`` of the independent
processes and in the covariance matrices of the shared ones, so the inner problem is a
convex least-squares problem over a product of non-negative orthants and PSD cones:

1. relaxation: drop ``Sigma >= 0`` but keep ``diag(Sigma) >= 0``; with diagonal weights the
   problem separates by moment pair: a non-negative least squares per channel (its WV) and an
   ordinary least squares per pair of channels (its WCCV). If every ``Sigma`` of that
   solution is PSD it solves the constrained problem exactly (a relaxation's minimiser that
   is feasible is optimal);
2. otherwise the minimiser has a singular covariance (on the boundary of the cone). It is
   found on its *face* (which variances are 0, the rank r of every covariance): with
   ``Sigma = D F F' D`` (F of shape g x r, D a fixed diagonal scaling) the problem on the
   face is regular and Newton's method converges in a few steps. Candidate faces: every
   non-PSD covariance at 0 (a shared process absent from the data: exact, linear), the face
   of the previous evaluation, and the faces met along a log-barrier interior-point path.
   A candidate is accepted only with a certificate of optimality (the KKT conditions: the
   gradient with respect to each covariance is PSD and annihilates it; the problem is
   convex, so they are sufficient). Without a certificate, the end of the interior-point
   path (duality gap below 1e-12 of the objective) is used. (A square factor, used before,
   also reaches the minimum, since every local minimum of the factored problem is a global
   one, Burer & Monteiro 2005, but its Jacobian is singular at a singular minimiser:
   hundreds of evaluations per inner solve, 2 minutes for a 3-channel fit.)

The AR1/GM parameters (log correlation times) are searched as in the univariate fit: starts
from the univariate fit of every channel, a scan of each shared phi/beta, then Nelder-Mead on
the profiled objective with restarts and a per-block polish. Everything is deterministic.

Replicates (one univariate model fitted to several recordings) are in
:mod:`engine.fit.replicates`.

Test of dependence (:func:`dependence_test`): the objective difference between the model
with the shared processes' covariances restricted to be diagonal (independent channels) and
the full model, compared with its parametric-bootstrap distribution under the restricted
model (the multivariate paper, section IV, after eq. 8).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import optimize

from ._jsonutil import json_ready
from .fit import FitError, fit_gmwm
from .fit.result import warning_lines as _warning_lines
from .model import Model, ModelError, parse_model
from .processes import AR1, TC_MAX_FACTOR, TC_MIN, Process
from .units import param_unit
from .wccv import WVMatrix, wv_matrix

__all__ = [
    "SHAREABLE",
    "SharedProcess",
    "MultiModel",
    "MGMWMResult",
    "SharedEstimate",
    "fit_mgmwm",
    "moment_covariance",
    "DependenceTest",
    "dependence_test",
]

SHAREABLE = ("WN", "RW", "AR1", "GM")
"""Process codes that may be shared by several channels (QN and DR are per channel only)."""


# -------------------------------------------------------------------------------------------
# model specification
# -------------------------------------------------------------------------------------------
def _phi_of_nl(code: str, nl: float | None, fs: float) -> float | None:
    """Fitter-space value (phi) of a user-space non-linear value (AR1 phi, GM beta [1/s])."""
    if nl is None:
        return None
    return math.exp(-float(nl) / fs) if code == "GM" else float(nl)


def _nl_of_phi(code: str, phi: float, fs: float) -> float:
    return -math.log(phi) * fs if code == "GM" else float(phi)


def _find(m: Model, label: str) -> int | None:
    """Index of a process in a channel model by label; ``GM`` and ``GM_1`` name the same
    process when the channel has one GM (so channels with one and two GMs can share one)."""
    labels = m.labels
    if label in labels:
        return labels.index(label)
    code, _, idx = label.partition("_")
    if idx == "1" and code in labels:
        return labels.index(code)
    if not idx and f"{code}_1" in labels:
        return labels.index(f"{code}_1")
    return None


def _check_cov(label: str, chans: tuple[str, ...], cov: Any) -> np.ndarray:
    """A user-given covariance: (g, g), finite, symmetric and positive definite."""
    g = len(chans)
    c = np.asarray(cov, dtype=float)
    if c.ndim == 0 and g == 1:
        c = c.reshape(1, 1)
    if c.shape != (g, g):
        raise ModelError(
            f"the covariance of the shared {label} must be {g} x {g} (channels "
            f"{', '.join(chans)}), got shape {c.shape}"
        )
    if not np.all(np.isfinite(c)):
        raise ModelError(f"the covariance of the shared {label} has non-finite entries")
    scale = max(float(np.max(np.abs(c))), 1e-300)
    if not np.allclose(c, c.T, rtol=0, atol=1e-12 * scale):
        i, j = np.unravel_index(np.argmax(np.abs(c - c.T)), c.shape)
        raise ModelError(
            f"the covariance of the shared {label} is not symmetric: entry "
            f"[{chans[i]}, {chans[j]}] = {c[i, j]:g} but [{chans[j]}, {chans[i]}] "
            f"= {c[j, i]:g}"
        )
    c = 0.5 * (c + c.T)
    lam = np.linalg.eigvalsh(c)
    if lam[0] <= 0:
        bad = int(np.argmin(np.diagonal(c)))
        extra = (
            f"; the variance of {chans[bad]} is {c[bad, bad]:g}"
            if c[bad, bad] <= 0
            else "; a correlation is beyond +-1 or the matrix is inconsistent"
        )
        raise ModelError(
            f"the covariance of the shared {label} is not positive definite "
            f"(smallest eigenvalue {lam[0]:.3g}){extra}"
        )
    return c


@dataclass(frozen=True, eq=False)
class SharedProcess:
    """A latent process shared by a group of channels.

    Attributes
    ----------
    label : str
        The process's label in the channel models (``"RW"``, ``"GM_1"`` ...).
    channels : tuple of str
        The group (at least 2 channels).
    cov : ndarray (g, g) or None
        Covariance of the group's components in the process's linear parametrisation
        (WN: sigma2, RW: gamma2, AR1: innovation variance, GM: stationary variance), per
        sample; None when unknown.
    nl : float or None
        The group's common non-linear value: AR1 phi, GM beta [1/s]; None otherwise.
    diagonal : bool
        Covariance restricted to be diagonal (independent components with a common
        phi/beta): the null model of :func:`dependence_test`.
    """

    label: str
    channels: tuple[str, ...]
    cov: np.ndarray | None = None
    nl: float | None = None
    diagonal: bool = False

    @property
    def correlation(self) -> np.ndarray | None:
        """Correlation matrix of the covariance (None when unknown)."""
        if self.cov is None:
            return None
        return _corr(self.cov)


def _corr(c: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.maximum(np.diagonal(c), 0.0))
    den = np.outer(d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(den > 0, c / np.where(den > 0, den, 1.0), np.nan)
    np.fill_diagonal(r, np.where(d > 0, 1.0, np.nan))
    return r


@dataclass(frozen=True, eq=False)
class _Term:
    """One latent process of the multivariate model (internal)."""

    label: str
    chans: tuple[int, ...]
    shared: bool
    diagonal: bool
    proto: Process

    @property
    def code(self) -> str:
        return self.proto.code

    @property
    def nonlinear(self) -> bool:
        return self.proto.nonlinear is not None


class MultiModel:
    """A multivariate latent model: one univariate model per channel plus shared processes.

    Parameters
    ----------
    channels : sequence of str
        Channel names (at least 2), in matrix order.
    per_channel : str, Model, Process or mapping
        The latent model of every channel (``"WN+RW"``), or one per channel
        (``{"gyro_x": "WN+RW", "gyro_y": "WN+RW+GM"}``). Values in the models are used by
        :meth:`simulate` and as extra starting points of the fit.
    shared : str, sequence or mapping, optional
        The shared processes, by label in the channel models: ``"WN,RW"`` or ``["WN", "RW"]``
        (shared by all channels), ``{"RW": ["gyro_x", "gyro_y"]}`` (by a group), or
        :class:`SharedProcess` objects. Only WN, RW, AR1 and GM can be shared.
    cov : mapping of str to array, optional
        Covariance of a shared process's group (g x g, positive definite), by label.
    nl : mapping of str to float, optional
        Common phi (AR1) or beta [1/s] (GM) of a shared process, by label.

    Raises
    ------
    ModelError
        Fewer than 2 channels, an unknown channel or label, a process that cannot be shared,
        a covariance that is not positive definite, or values that disagree.

    Examples
    --------
    >>> mm = MultiModel(["gyro_x", "gyro_y", "gyro_z"], "WN+RW", shared=["RW"])
    >>> mm.spec()
    'gyro_x,gyro_y,gyro_z: WN+RW | shared: RW'
    """

    def __init__(
        self,
        channels: Sequence[str],
        per_channel: str | Model | Process | Mapping[str, str | Model | Process],
        shared: str | Sequence[str | SharedProcess] | Mapping[str, Sequence[str] | None] = (),
        *,
        cov: Mapping[str, Any] | None = None,
        nl: Mapping[str, float] | None = None,
    ) -> None:
        if isinstance(channels, str):
            channels = [c.strip() for c in channels.split(",") if c.strip()]
        chans = tuple(str(c) for c in channels)
        if len(chans) < 2:
            raise ModelError(
                f"a multivariate model needs at least 2 channels, got "
                f"{len(chans)} ({', '.join(chans) or 'none'}); fit one channel "
                "with fit_gmwm"
            )
        if len(set(chans)) != len(chans):
            dup = sorted({c for c in chans if chans.count(c) > 1})
            raise ModelError(f"channel names repeat: {', '.join(dup)}")
        self.channels: tuple[str, ...] = chans
        if isinstance(per_channel, Mapping):
            unknown = [c for c in per_channel if c not in chans]
            if unknown:
                raise ModelError(
                    f"per_channel names unknown channel(s) {', '.join(unknown)}; "
                    f"the channels are {', '.join(chans)}"
                )
            missing = [c for c in chans if c not in per_channel]
            if missing:
                raise ModelError(f"no model for channel(s) {', '.join(missing)}")
            models = {c: parse_model(per_channel[c]) for c in chans}
        else:
            m = parse_model(per_channel)
            models = {c: m for c in chans}
        for c, m in models.items():
            try:
                m.validate()
            except ModelError as e:
                raise ModelError(f"channel {c}: {e}") from None
        self.models: dict[str, Model] = models
        self.shared: tuple[SharedProcess, ...] = self._shared(shared, cov or {}, nl or {})

    # ---- construction helpers ----------------------------------------------------------
    def _shared(
        self, shared: Any, cov: Mapping[str, Any], nl: Mapping[str, float]
    ) -> tuple[SharedProcess, ...]:
        items: list[SharedProcess] = []
        if isinstance(shared, str):
            shared = [s.strip() for s in shared.split(",") if s.strip()]
        if isinstance(shared, Mapping):
            seq = [
                SharedProcess(
                    str(lab),
                    tuple(
                        self.channels
                        if g is None
                        else [c.strip() for c in g.split(",") if c.strip()]
                        if isinstance(g, str)
                        else g
                    ),
                )
                for lab, g in shared.items()
            ]
        else:
            seq = [
                s if isinstance(s, SharedProcess) else SharedProcess(str(s), self.channels)
                for s in shared
            ]
        for lab in list(cov) + list(nl):
            if lab not in {s.label for s in seq}:
                raise ModelError(
                    f"a covariance or phi/beta is given for {lab}, which is not "
                    f"shared; shared: {', '.join(s.label for s in seq) or 'none'}"
                )
        seen: set[str] = set()
        for sp in seq:
            lab = sp.label
            if lab in seen:
                raise ModelError(f"{lab} is shared twice; a process is shared by one group")
            seen.add(lab)
            group = tuple(str(c) for c in sp.channels)
            for c in group:
                if c not in self.channels:
                    raise ModelError(
                        f"the shared {lab} names unknown channel {c!r}; the "
                        f"channels are {', '.join(self.channels)}"
                    )
            if len(set(group)) != len(group):
                raise ModelError(f"the group of the shared {lab} repeats a channel")
            if len(group) < 2:
                raise ModelError(
                    f"the shared {lab} needs a group of at least 2 channels, got {', '.join(group)}"
                )
            procs = []
            for c in group:
                m = self.models[c]
                i = _find(m, lab)
                if i is None:
                    raise ModelError(
                        f"channel {c} has no process {lab} to share (its model "
                        f"is {m.spec()}, labels {', '.join(m.labels)})"
                    )
                procs.append(m.processes[i])
            code = procs[0].code
            if code not in SHAREABLE:
                raise ModelError(
                    f"{lab} cannot be shared: {code} is per channel only (the "
                    "multivariate paper, section II); shareable: "
                    f"{', '.join(SHAREABLE)}"
                )
            c_given = cov.get(lab, sp.cov)
            c_arr = None if c_given is None else _check_cov(lab, group, c_given)
            if c_arr is not None and sp.diagonal:
                c_arr = np.diag(np.diagonal(c_arr))
            # the channel processes' linear values must agree with the covariance's diagonal
            lin = [p.linear_coef() if p.is_set else None for p in procs]
            if c_arr is not None:
                for c, v, d in zip(group, lin, np.diagonal(c_arr), strict=True):
                    if v is not None and not math.isclose(v, d, rel_tol=1e-9, abs_tol=0.0):
                        raise ModelError(
                            f"channel {c}: {lab} has variance {v:g} but the "
                            f"covariance of the shared {lab} has {d:g}"
                        )
            nl_v = nl.get(lab, sp.nl)
            if procs[0].nonlinear is not None:
                given = {getattr(p, p.nonlinear) for p in procs} - {None}
                if (
                    nl_v is None
                    and len(given) == 1
                    and all(getattr(p, p.nonlinear) is not None for p in procs)
                ):
                    nl_v = next(iter(given))
                elif nl_v is None and len(given) > 1:
                    raise ModelError(
                        f"the shared {lab} has one {procs[0].nonlinear} for its "
                        f"group, but the channels give {sorted(given)}"
                    )
                if nl_v is not None:
                    try:
                        procs[0].cleared().with_values(**{procs[0].nonlinear: float(nl_v)})
                    except ValueError as e:
                        raise ModelError(f"shared {lab}: {e}") from None
            elif nl_v is not None:
                raise ModelError(f"{lab} has no phi/beta ({code} is linear)")
            items.append(
                SharedProcess(
                    lab, group, c_arr, None if nl_v is None else float(nl_v), bool(sp.diagonal)
                )
            )
        return tuple(items)

    # ---- structure ------------------------------------------------------------------------
    @property
    def k(self) -> int:
        """Number of channels."""
        return len(self.channels)

    def shared_process(self, label: str) -> SharedProcess:
        """The shared process with this label."""
        for sp in self.shared:
            if sp.label == label:
                return sp
        raise KeyError(
            f"{label} is not shared; shared: {', '.join(s.label for s in self.shared) or 'none'}"
        )

    def index(self, label: str, channel: str) -> int:
        """Position of a (shared or own) process in a channel's model, by label."""
        i = _find(self.models[channel], label)
        if i is None:
            raise KeyError(f"channel {channel} has no process {label}")
        return i

    def _shared_index(self, channel: str) -> dict[int, SharedProcess]:
        return {self.index(s.label, channel): s for s in self.shared if channel in s.channels}

    def _terms(self) -> list[_Term]:
        terms: list[_Term] = []
        for sp in self.shared:
            c0 = sp.channels[0]
            m = self.models[c0]
            proto = m.processes[self.index(sp.label, c0)].cleared()
            terms.append(
                _Term(
                    sp.label,
                    tuple(self.channels.index(c) for c in sp.channels),
                    True,
                    sp.diagonal,
                    proto,
                )
            )
        for p, c in enumerate(self.channels):
            m = self.models[c]
            sh = self._shared_index(c)
            for i, (lab, proc) in enumerate(zip(m.labels, m.processes, strict=True)):
                if i not in sh:
                    terms.append(_Term(lab, (p,), False, False, proc))
        return terms

    @staticmethod
    def _term_key(t: _Term, channels: tuple[str, ...]) -> str:
        return t.label if t.shared else f"{channels[t.chans[0]]}:{t.label}"

    @property
    def is_set(self) -> bool:
        """True when every value (variances, covariances, phi/beta) is known."""
        for sp in self.shared:
            if sp.cov is None:
                return False
            m = self.models[sp.channels[0]]
            proc = m.processes[self.index(sp.label, sp.channels[0])]
            if proc.nonlinear is not None and sp.nl is None:
                return False
        return all(t.proto.is_set for t in self._terms() if not t.shared)

    def channel_model(self, channel: str) -> Model:
        """The marginal univariate model of one channel (shared processes at their diagonal)."""
        if channel not in self.channels:
            raise KeyError(
                f"unknown channel {channel!r}; the channels are {', '.join(self.channels)}"
            )
        m = self.models[channel]
        sh = self._shared_index(channel)
        procs = []
        for i, proc in enumerate(m.processes):
            sp = sh.get(i)
            if sp is None or sp.cov is None:
                procs.append(proc)
                continue
            a = sp.channels.index(channel)
            vals = {
                proc.param_names[-1] if proc.nonlinear else proc.param_names[0]: float(sp.cov[a, a])
            }
            if proc.nonlinear is not None and sp.nl is not None:
                vals[proc.nonlinear] = sp.nl
            procs.append(proc.cleared().with_values(**vals))
        return Model(tuple(procs))

    def cleared(self) -> MultiModel:
        """The same structure with every value unknown."""
        return MultiModel(
            self.channels,
            {c: m.cleared() for c, m in self.models.items()},
            [SharedProcess(s.label, s.channels, diagonal=s.diagonal) for s in self.shared],
        )

    def without_dependence(self, labels: Sequence[str] | None = None) -> MultiModel:
        """The nested structure with independent channels for the given shared processes.

        WN/RW become independent per-channel processes; a shared AR1/GM keeps its common
        phi/beta with a diagonal covariance (so that the two models are nested). Values are
        dropped (this is the null model of :func:`dependence_test`, fitted to data).
        """
        labels = [s.label for s in self.shared] if labels is None else list(labels)
        known = {s.label for s in self.shared}
        for lab in labels:
            if lab not in known:
                raise ModelError(f"{lab} is not shared; shared: {', '.join(sorted(known))}")
        keep: list[SharedProcess] = []
        for s in self.shared:
            code = self.models[s.channels[0]].processes[self.index(s.label, s.channels[0])].code
            if s.label not in labels:
                keep.append(SharedProcess(s.label, s.channels, diagonal=s.diagonal))
            elif code in ("AR1", "GM"):
                keep.append(SharedProcess(s.label, s.channels, diagonal=True))
        return MultiModel(self.channels, {c: m.cleared() for c, m in self.models.items()}, keep)

    # ---- implied moments and simulation ----------------------------------------------------
    def _term_values(self, t: _Term, fs: float) -> tuple[np.ndarray, float | None]:
        """(coefficient matrix g x g, fitter phi) of a term; raises when a value is missing."""
        if t.shared:
            sp = self.shared_process(t.label)
            if sp.cov is None:
                raise ModelError(
                    f"no covariance for the shared {t.label}: give cov="
                    f"{{'{t.label}': ...}} or fit the model first"
                )
            phi = _phi_of_nl(t.code, sp.nl, fs) if t.nonlinear else None
            if t.nonlinear and phi is None:
                raise ModelError(f"no {t.proto.nonlinear} for the shared {t.label}")
            return np.asarray(sp.cov, float), phi
        p = t.proto
        if not p.is_set:
            missing = [n for n, v in zip(p.param_names, p.values, strict=True) if v is None]
            raise ModelError(
                f"channel {self.channels[t.chans[0]]}: {t.label} has no value for "
                f"{', '.join(missing)}"
            )
        return np.array([[p.linear_coef()]]), p.nl_value(fs)

    def components(self, tau: np.ndarray, fs: float = 1.0) -> dict[str, np.ndarray]:
        """Implied (J, k, k) WV/WCCV array of every process.

        Keys: the label of a shared process (``"RW"``), ``"channel:label"`` for an
        independent one (``"gyro_x:WN"``). Each array is zero outside the process's channels.
        """
        tau = np.asarray(tau, dtype=float)
        out: dict[str, np.ndarray] = {}
        for t in self._terms():
            c, phi = self._term_values(t, fs)
            b = t.proto.basis(tau, fs, phi) * np.ones_like(tau)
            arr = np.zeros((tau.size, self.k, self.k))
            ix = np.ix_(range(tau.size), t.chans, t.chans)
            arr[ix] = b[:, None, None] * c[None, :, :]
            out[self._term_key(t, self.channels)] = arr
        return out

    def implied(self, tau: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Implied (J, k, k) array of WV (diagonal) and WCCV (off-diagonal) at scales tau."""
        comps = self.components(tau, fs)
        return np.sum(np.array(list(comps.values())), axis=0)

    def simulate(
        self, n: int, *, fs: float = 1.0, rng: np.random.Generator | int | None = None
    ) -> np.ndarray:
        """Simulate ``n`` samples of every channel, shape (n, k).

        Shared WN: iid N(0, Sigma) vectors; shared RW: their cumulative sum; shared AR1/GM:
        ``X_t = phi X_{t-1} + e_t`` with ``e_t ~ N(0, Sigma_innovation)`` from the stationary
        distribution. Independent processes as :meth:`Process.simulate`.
        """
        from scipy.signal import lfilter

        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        if not self.is_set:
            raise ModelError(
                "cannot simulate: some values are unknown; give every channel "
                "model's values and cov= (and nl=) for the shared processes"
            )
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        x = np.zeros((n, self.k))
        for t in self._terms():
            if not t.shared:
                x[:, t.chans[0]] += t.proto.simulate(n, g, fs)
                continue
            c, phi = self._term_values(t, fs)
            vals, vecs = np.linalg.eigh(c)
            root = vecs * np.sqrt(np.clip(vals, 0.0, None))  # root @ root.T = c
            z = g.standard_normal((n, len(t.chans))) @ root.T  # rows ~ N(0, c)
            if t.code == "WN":
                comp = z
            elif t.code == "RW":
                comp = np.cumsum(z, axis=0)
            else:
                # AR1: c is the innovation covariance, the stationary one is c / (1 - phi^2);
                # GM: c is the stationary covariance, the innovations' is c (1 - phi^2)
                shrink = math.sqrt(1.0 - phi * phi)
                innov = z if t.code == "AR1" else z * shrink
                x0 = g.standard_normal(len(t.chans)) @ root.T
                if t.code == "AR1":
                    x0 = x0 / shrink
                comp = lfilter([1.0], [1.0, -phi], innov, axis=0, zi=(phi * x0)[None, :])[0]
            x[:, list(t.chans)] += comp
        return x

    # ---- text ---------------------------------------------------------------------------
    def spec(self) -> str:
        """Readable structure, e.g. ``gyro_x,gyro_y,gyro_z: WN+RW | shared: RW``."""
        specs = {c: m.spec() for c, m in self.models.items()}
        if len(set(specs.values())) == 1:
            head = f"{','.join(self.channels)}: {specs[self.channels[0]]}"
        else:
            head = "; ".join(f"{c}: {s}" for c, s in specs.items())
        parts = []
        for s in self.shared:
            g = "" if s.channels == self.channels else f"[{','.join(s.channels)}]"
            parts.append(f"{s.label}{g}{' (diagonal)' if s.diagonal else ''}")
        return head + (f" | shared: {', '.join(parts)}" if parts else "")

    def __repr__(self) -> str:
        return f"MultiModel({self.spec()!r})"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (with values where known)."""
        return {
            "channels": list(self.channels),
            "models": {c: m.spec(values=m.is_set) for c, m in self.models.items()},
            "shared": [
                {
                    "label": s.label,
                    "channels": list(s.channels),
                    "cov": None if s.cov is None else np.asarray(s.cov).tolist(),
                    "nl": s.nl,
                    "diagonal": s.diagonal,
                }
                for s in self.shared
            ],
        }


# -------------------------------------------------------------------------------------------
# the MGMWM problem
# -------------------------------------------------------------------------------------------
def _nnls(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    norms = np.sqrt(np.sum(a * a, axis=0))
    norms[norms == 0] = 1.0
    g, _ = optimize.nnls(a / norms, b, maxiter=50 * a.shape[1] + 50)
    return g / norms


def _lstsq(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    norms = np.sqrt(np.sum(a * a, axis=0))
    norms[norms == 0] = 1.0
    g = np.linalg.lstsq(a / norms, b, rcond=None)[0]
    return g / norms


class _MProblem:
    """Stacked WV/WCCV moments of a multivariate model, with the exact inner solve.

    Moments are stacked pair by pair (upper triangle, diagonal included), levels inside:
    row ``P J + j`` is level j + 1 of pair P. The objective is ``||A (y - X c)||^2`` with
    ``A`` the diagonal square root of the weights, or a full square root of ``Omega``.
    """

    def __init__(
        self,
        mm: MultiModel,
        wvm: WVMatrix,
        w: np.ndarray | None = None,
        omega: np.ndarray | None = None,
    ):
        self.mm = mm
        self.k = mm.k
        self.fs = wvm.fs
        self.tau = wvm.tau_samples.astype(float)
        nj = self.tau.size
        self.nj = nj
        self.terms = mm._terms()
        self.pairs = [(p, q) for p in range(self.k) for q in range(p, self.k)]
        self.y = np.concatenate([wvm.values[:, p, q] for p, q in self.pairs])
        if omega is None:
            self.sw: np.ndarray | None = np.sqrt(
                np.concatenate([w[:, p, q] for p, q in self.pairs])
            )
            self.a_full: np.ndarray | None = None
            self.b = self.sw * self.y
        else:
            self.sw = None
            vals, vecs = np.linalg.eigh(0.5 * (omega + omega.T))
            self.a_full = (vecs * np.sqrt(np.clip(vals, 0.0, None))).T
            self.b = self.a_full @ self.y
        # columns: (term index, local row a, local column b, pair index)
        self.cols: list[tuple[int, int, int, int]] = []
        self.pair_cols: list[list[int]] = []
        for pi, (p, q) in enumerate(self.pairs):
            idx = []
            for ti, t in enumerate(self.terms):
                if p in t.chans and q in t.chans and (p == q or (t.shared and not t.diagonal)):
                    idx.append(len(self.cols))
                    self.cols.append((ti, t.chans.index(p), t.chans.index(q), pi))
            self.pair_cols.append(idx)
        self.lower = np.array(
            [
                0.0 if self.pairs[pi][0] == self.pairs[pi][1] else -np.inf
                for _, _, _, pi in self.cols
            ]
        )
        self.fixed = [
            None if t.nonlinear else t.proto.basis(self.tau, self.fs) * np.ones_like(self.tau)
            for t in self.terms
        ]
        self.slots = [ti for ti, t in enumerate(self.terms) if t.nonlinear]
        self.tc_min = TC_MIN
        self.tc_max = TC_MAX_FACTOR * max(wvm.n, 2 ** (wvm.n_levels + 1))
        self.full = [ti for ti, t in enumerate(self.terms) if t.shared and not t.diagonal]
        self.col_of = {(ti, a, b): ci for ci, (ti, a, b, _) in enumerate(self.cols)}
        self.n_eval = 0
        self.n_coupled = 0
        self.n_inner = 0  # residual evaluations / Newton steps of the PSD-constrained solves
        self._face: tuple[Any, np.ndarray] | None = None  # last certified face, solution

    # -- non-linear coordinates: log correlation time in samples (as the univariate fit) --
    def phi_of(self, ti: int, u: float) -> float:
        if isinstance(self.terms[ti].proto, AR1) and u < -50:
            return 0.0
        tc = math.exp(min(max(u, math.log(self.tc_min)), math.log(self.tc_max)))
        return math.exp(-1.0 / tc)

    def u_of_phi(self, phi: float) -> float:
        phi = min(max(phi, 1e-300), 1 - 1e-16)
        return math.log(-1.0 / math.log(phi))

    def bases(self, u: np.ndarray) -> list[np.ndarray]:
        out = list(self.fixed)
        for ti, ui in zip(self.slots, u, strict=True):
            out[ti] = self.terms[ti].proto.basis(self.tau, self.fs, self.phi_of(ti, float(ui)))
        return out  # type: ignore[return-value]

    # -- inner problem ---------------------------------------------------------------------
    def design(self, bases: list[np.ndarray]) -> np.ndarray:
        """Weighted design ``A X`` (R x C)."""
        x = np.zeros((self.y.size, len(self.cols)))
        for ci, (ti, _, _, pi) in enumerate(self.cols):
            x[pi * self.nj : (pi + 1) * self.nj, ci] = bases[ti]
        return self.sw[:, None] * x if self.a_full is None else self.a_full @ x

    def _assemble(self, c: np.ndarray) -> tuple[dict[int, float], dict[int, np.ndarray]]:
        h: dict[int, float] = {}
        s: dict[int, np.ndarray] = {
            ti: np.zeros((len(t.chans), len(t.chans)))
            for ti, t in enumerate(self.terms)
            if t.shared
        }
        for (ti, a, b, _), v in zip(self.cols, c, strict=True):
            if self.terms[ti].shared:
                s[ti][a, b] = s[ti][b, a] = float(v)
            else:
                h[ti] = float(v)
        return h, s

    def _relaxed(self, ax: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
        """Minimiser with diag(Sigma) >= 0 and h >= 0 only (exact); with ``keep`` (a mask of
        the columns), the other coefficients are held at 0."""
        c = np.zeros(len(self.cols))
        if keep is not None:
            if not np.any(keep):
                return c
            if self.a_full is not None:
                c[keep] = self._relaxed_full(ax[:, keep], self.lower[keep])
                return c
        if self.a_full is None:  # separable by moment pair
            for pi, (p, q) in enumerate(self.pairs):
                idx = self.pair_cols[pi]
                if keep is not None:
                    idx = [i for i in idx if keep[i]]
                if not idx:
                    continue
                rows = slice(pi * self.nj, (pi + 1) * self.nj)
                a = ax[rows][:, idx]
                c[idx] = _nnls(a, self.b[rows]) if p == q else _lstsq(a, self.b[rows])
            return c
        return self._relaxed_full(ax, self.lower)

    def _relaxed_full(self, ax: np.ndarray, lower: np.ndarray) -> np.ndarray:
        """Bounded least squares ``min ||b - ax c||, c >= lower`` (full weighting matrix)."""
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        norms[norms == 0] = 1.0
        if np.all(np.isinf(lower)):
            return np.linalg.lstsq(ax / norms, self.b, rcond=None)[0] / norms
        res = optimize.lsq_linear(
            ax / norms, self.b, bounds=(lower, np.inf), method="bvls", tol=1e-14
        )
        return res.x / norms

    def solve(self, u: np.ndarray) -> tuple[float, dict[int, float], dict[int, np.ndarray], bool]:
        """Objective and linear coefficients at fixed non-linear values.

        Returns (objective, independent variances by term, shared matrices by term, coupled).
        """
        self.n_eval += 1
        ax = self.design(self.bases(u))
        c = self._relaxed(ax)
        r = self.b - ax @ c
        h, s = self._assemble(c)
        if all(_is_psd(s[ti]) for ti in self.full):
            return float(r @ r), h, s, False
        self.n_coupled += 1
        f2, h2, s2 = self._coupled(ax, h, s)
        return f2, h2, s2, True

    def _coupled(
        self, ax: np.ndarray, h0: dict[int, float], s0: dict[int, np.ndarray]
    ) -> tuple[float, dict[int, float], dict[int, np.ndarray]]:
        """The PSD-constrained inner problem, when the relaxed minimiser is not PSD.

        The minimiser then has a singular covariance. The first candidate with a certificate
        of optimality (the KKT conditions, :meth:`_uncertified`) wins:

        1. the covariances that are not PSD at 0 (the shared process is absent from the
           data), everything else exact by the relaxation (a bounded linear least squares);
        2. the face of the previous solve (which variances are 0, the rank r of every
           covariance): ``Sigma = D F F' D`` with F of shape g x r, Newton's method
           (:meth:`_face_newton`) from the previous solution (the profile is evaluated at
           nearby points);
        3. a log-barrier interior-point path (:meth:`_barrier`) that does not care about the
           rank of the minimiser; after each centring, its face (:meth:`_purify`) is
           polished as in 2 and certified. Without a certificate at the end of the path, the
           best of the path's end, its face and candidate 1.

        A factor of the minimiser's rank is a regular problem (a few Newton steps from a
        nearby point); a factor of a larger rank (e.g. square, as before) has a singular
        Jacobian at the minimiser and Gauss-Newton creeps towards it, hundreds of evaluations
        per solve, which made fits with an absent shared process take 5-120 s.
        """
        dscale = {ti: self._dscale(ax, ti) for ti in self.full}
        # 1. the non-PSD covariances (and any that the others push out of the cone) at 0
        zero = {ti for ti in self.full if not _is_psd(s0[ti])}
        while True:
            c = self._relaxed(ax, np.array([ti not in zero for ti, _, _, _ in self.cols]))
            _, s = self._assemble(c)
            bad = {ti for ti in self.full if ti not in zero and not _is_psd(s[ti])}
            if not bad:
                break
            zero |= bad
        r = self.b - ax @ c
        best = (float(r @ r), c)
        if not self._uncertified(ax, c, r, dscale):
            return self._done(best, None)

        def polish(
            c1: np.ndarray, face: tuple[np.ndarray, dict[int, int]]
        ) -> tuple[float, np.ndarray] | None:
            got = self._face_newton(ax, c1, face[0], face[1], dscale)
            if got is None or self._uncertified(ax, got[1], got[2], dscale):
                return None
            return got[0], got[1]

        # 2. the previous face
        if self._face is not None:
            got = polish(self._face[1], self._face[0])
            if got is not None:
                return self._done(got, self._face[0])

        # 3. the interior-point path, its faces polished
        def accept(cb: np.ndarray) -> tuple[tuple[float, np.ndarray], Any] | None:
            cp = self._purify(ax, cb, dscale)
            if cp is None:
                return None
            _, sp = self._assemble(cp)
            face = (cp != 0, {ti: _rank(sp[ti] / np.outer(d, d), 1e-9) for ti, d in dscale.items()})
            got = polish(cp, face)
            return None if got is None else (got, face)

        cb, got = self._barrier(ax, c, dscale, accept)
        if got is not None:
            return self._done(*got)
        for cand in (cb, self._purify(ax, cb, dscale)):
            if cand is not None:
                rc = self.b - ax @ cand
                best = min(best, (float(rc @ rc), cand), key=lambda v: v[0])
        return self._done(best, None)

    def _done(
        self, best: tuple[float, np.ndarray], face: Any
    ) -> tuple[float, dict[int, float], dict[int, np.ndarray]]:
        self._face = None if face is None else (face, best[1])
        h, s = self._assemble(best[1])
        return best[0], h, s

    def _dscale(self, ax: np.ndarray, ti: int) -> np.ndarray:
        """Scaling D of a covariance: unit entries of ``D^-1 Sigma D^-1`` on the diagonal
        change the weighted residual by about one unit."""
        g = len(self.terms[ti].chans)
        return np.array(
            [
                1.0 / math.sqrt(max(float(np.linalg.norm(ax[:, self.col_of[(ti, a, a)]])), 1e-300))
                for a in range(g)
            ]
        )

    def _uncertified(
        self,
        ax: np.ndarray,
        c: np.ndarray,
        r: np.ndarray,
        dscale: dict[int, np.ndarray],
        tol: float = 1e-6,
    ) -> set[int]:
        """Where the KKT conditions of the PSD-constrained problem fail at ``c``.

        Optimality (the problem is convex): the gradient ``G`` of the objective with respect
        to every covariance is PSD (``G Sigma = 0`` holds at any stationary point of the
        factored problem and at 0, and is checked), and the gradient with respect to every
        non-negative coefficient is >= 0 (0 where the coefficient is positive). Tolerances
        are relative
        to ``||r||`` in the scaled coordinates: a violation by ``tol ||r||`` can lower the
        objective by about ``tol^2`` times itself. Returns the failing covariance terms
        (``-1`` for the non-negative coefficients); empty when certified.
        """
        lim = tol * max(float(np.linalg.norm(r)), 1e-300)
        grad = -2.0 * (ax.T @ r)
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        out: set[int] = set()
        for ci, (ti, _, _, _) in enumerate(self.cols):
            if ti in dscale or norms[ci] == 0:
                continue
            gn = grad[ci] / norms[ci]
            if gn < -lim or (c[ci] * norms[ci] > lim and gn > lim):
                out.add(-1)
        for ti, d in dscale.items():
            g = len(d)
            gm = np.empty((g, g))
            for a in range(g):
                for b in range(a, g):
                    ci = self.col_of.get((ti, a, b), self.col_of.get((ti, b, a)))
                    gm[a, b] = gm[b, a] = grad[ci] if a == b else 0.5 * grad[ci]
            gs = gm * np.outer(d, d)
            sm = np.zeros((g, g))
            for ci, (tj, a, b, _) in enumerate(self.cols):
                if tj == ti:
                    sm[a, b] = sm[b, a] = c[ci] / (d[a] * d[b])
            if np.linalg.eigvalsh(gs)[0] < -lim or np.linalg.norm(gs @ sm) > lim * float(
                np.linalg.norm(sm)
            ):
                out.add(ti)
        return out

    def _barrier(
        self,
        ax: np.ndarray,
        c0: np.ndarray,
        dscale: dict[int, np.ndarray],
        accept: Any = None,
        gap: float = 1e-12,
    ) -> tuple[np.ndarray, Any]:
        """The PSD-constrained inner problem by a log-barrier interior-point method.

        Minimises ``t ||b - ax c||^2 - sum log c_i - sum log det Sigma`` by damped Newton
        steps (the barrier Hessian of ``log det`` is ``tr(W E W E')`` with ``W = Sigma^-1``)
        for ``t`` increasing by 20 until the duality-gap bound ``m / t`` (m the barrier
        parameter) is below ``gap ||r||^2``. Unlike a factorisation, Newton's method does not
        slow down when the minimiser is singular. Works in scaled coordinates: non-negative
        coefficients times their column norm, covariances ``D^-1 Sigma D^-1``. After each
        centring with a relative gap below 1e-3, ``accept(c)`` may end the path with its
        (not None) result. Returns the coefficients at the end (strictly inside the cones)
        and that result.
        """
        ncol = len(self.cols)
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        norms[norms == 0] = 1.0
        scale = 1.0 / norms
        cones: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]] = []
        nn = np.ones(ncol, bool)
        for ti, d in dscale.items():
            idx = np.array([ci for ci, col in enumerate(self.cols) if col[0] == ti])
            ia = np.array([self.cols[ci][1] for ci in idx])
            ib = np.array([self.cols[ci][2] for ci in idx])
            scale[idx] = d[ia] * d[ib]
            nn[idx] = False
            sfac = np.where(ia == ib, 0.5, 1.0)
            cones.append((idx, ia, ib, sfac, len(d)))
        a = ax * scale
        qm = a.T @ a
        bnorm = max(float(np.linalg.norm(self.b)), 1e-300)
        v = c0 / scale
        delta = 1e-3 * bnorm / ncol
        v[nn] = np.maximum(v[nn], delta)
        for idx, ia, ib, _, g in cones:
            sm = np.zeros((g, g))
            sm[ia, ib] = sm[ib, ia] = v[idx]
            sm = _project_psd(sm) + delta * np.eye(g)
            v[idx] = sm[ia, ib]
        m = float(np.sum(nn) + sum(cn[4] for cn in cones))

        def barrier(v: np.ndarray, deriv: bool):
            """Barrier value (inf outside), and with deriv its gradient and Hessian."""
            if np.any(v[nn] <= 0):
                return math.inf, None, None
            val = -float(np.sum(np.log(v[nn])))
            gr = np.zeros(ncol)
            he = np.zeros((ncol, ncol))
            if deriv:
                gr[nn] = -1.0 / v[nn]
                he[nn, nn] = 1.0 / v[nn] ** 2
            for idx, ia, ib, sfac, g in cones:
                sm = np.zeros((g, g))
                sm[ia, ib] = sm[ib, ia] = v[idx]
                try:
                    low = np.linalg.cholesky(sm)
                except np.linalg.LinAlgError:
                    return math.inf, None, None
                val -= 2.0 * float(np.sum(np.log(np.diagonal(low))))
                if deriv:
                    wi = np.linalg.inv(sm)
                    gr[idx] = -2.0 * sfac * wi[ia, ib]
                    he[np.ix_(idx, idx)] = (
                        2.0
                        * np.outer(sfac, sfac)
                        * (
                            wi[np.ix_(ia, ia)] * wi[np.ix_(ib, ib)]
                            + wi[np.ix_(ia, ib)] * wi[np.ix_(ib, ia)]
                        )
                    )
            return val, gr, he

        r = self.b - a @ v
        t = m / max(float(r @ r), 1e-300)
        for _ in range(300):
            pv, pg, ph = barrier(v, True)
            r = self.b - a @ v
            g = -2.0 * t * (a.T @ r) + pg
            hm = 2.0 * t * qm + ph
            dj = 1.0 / np.sqrt(np.maximum(np.diagonal(hm), 1e-300))
            try:
                step = -dj * np.linalg.solve(hm * np.outer(dj, dj), g * dj)
            except np.linalg.LinAlgError:  # pragma: no cover - the barrier Hessian is PD
                break
            dec = -float(g @ step)
            self.n_inner += 1
            if dec <= 1e-8:
                if m / t <= gap * float(r @ r) or t > 1e300:
                    break
                if accept is not None and m / t <= 1e-3 * float(r @ r):
                    done = accept(v * scale)
                    if done is not None:
                        return v * scale, done
                t *= 20.0
                continue
            slope = float(g @ step)
            curv = t * float(step @ qm @ step)
            lin = -2.0 * t * float((a.T @ r) @ step)
            s_ = 1.0
            for _ in range(60):
                nv = barrier(v + s_ * step, False)[0]
                if nv < math.inf and s_ * lin + s_ * s_ * curv + nv - pv <= 0.25 * s_ * slope:
                    break
                s_ *= 0.5
            else:
                break
            v = v + s_ * step
        return v * scale, None

    def _purify(
        self, ax: np.ndarray, c: np.ndarray, dscale: dict[int, np.ndarray], rel: float = 1e-6
    ) -> np.ndarray | None:
        """The face of an interior solution: coefficients below ``rel`` (scaled) at 0, and each
        covariance ``U M U'`` with U its eigenvectors above ``rel`` times the largest; M and
        the positive coefficients by least squares on that face. None if that leaves the
        cones."""
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        bnorm = max(float(np.linalg.norm(self.b)), 1e-300)
        blocks: list[np.ndarray] = []
        maps: list[tuple[Any, ...]] = []
        for ci, (ti, _, _, _) in enumerate(self.cols):
            if ti not in dscale and c[ci] * norms[ci] > rel * bnorm:
                blocks.append(ax[:, ci : ci + 1])
                maps.append(("h", ci))
        for ti, d in dscale.items():
            idx = [ci for ci, col in enumerate(self.cols) if col[0] == ti]
            g = len(d)
            sm = np.zeros((g, g))
            for ci in idx:
                _, a, b, _ = self.cols[ci]
                sm[a, b] = sm[b, a] = c[ci] / (d[a] * d[b])
            lam, vec = np.linalg.eigh(sm)
            keep = lam > rel * max(float(lam[-1]), bnorm)
            u = vec[:, keep]
            rk = u.shape[1]
            kl = [(k, l) for k in range(rk) for l in range(k, rk)]
            if not kl:
                continue
            tm = np.zeros((len(idx), len(kl)))
            for row, ci in enumerate(idx):
                _, a, b, _ = self.cols[ci]
                for j, (k, l) in enumerate(kl):
                    tm[row, j] = (
                        d[a] * d[b] * (u[a, k] * u[b, l] + (u[a, l] * u[b, k] if k != l else 0.0))
                    )
            blocks.append(ax[:, idx] @ tm)
            maps.append(("s", ti, idx, tm, u, kl))
        out = np.zeros(len(self.cols))
        if not blocks:
            return out
        x = _lstsq(np.hstack(blocks), self.b)
        pos = 0
        for mp in maps:
            if mp[0] == "h":
                if x[pos] < 0:
                    return None
                out[mp[1]] = x[pos]
                pos += 1
                continue
            _, ti, idx, tm, u, kl = mp
            xm = x[pos : pos + len(kl)]
            pos += len(kl)
            mm = np.zeros((u.shape[1], u.shape[1]))
            for (k, l), val in zip(kl, xm, strict=True):
                mm[k, l] = mm[l, k] = val
            if np.linalg.eigvalsh(mm)[0] < 0:
                return None
            out[idx] = tm @ xm
        return out

    def _face_newton(
        self,
        ax: np.ndarray,
        c0: np.ndarray,
        free: np.ndarray,
        ranks: dict[int, int],
        dscale: dict[int, np.ndarray],
    ) -> tuple[float, np.ndarray, np.ndarray] | None:
        """Minimum on a face: the non-negative coefficients in ``free`` (the others 0) and
        ``Sigma = D F F' D`` with F of shape g x rank, by Newton's method with the exact
        Hessian ``2 J'J + 2 (D G D kron I)`` (G the gradient with respect to Sigma), from
        ``c0``. None if a free coefficient ends negative (not the minimiser's face).
        Returns (objective, coefficients, residual)."""
        lin = np.array(
            [ci for ci, (ti, _, _, _) in enumerate(self.cols) if ti not in dscale and free[ci]],
            dtype=int,
        )
        _, s0 = self._assemble(c0)
        parts = [c0[lin]]
        cones = []
        pos = lin.size
        for ti, d in dscale.items():
            rk = ranks[ti]
            idx = np.array([ci for ci, col in enumerate(self.cols) if col[0] == ti])
            ia = np.array([self.cols[ci][1] for ci in idx])
            ib = np.array([self.cols[ci][2] for ci in idx])
            cones.append((ti, idx, ia, ib, d[ia] * d[ib], len(d), rk, pos))
            pos += len(d) * rk
            if rk:
                lam, vec = np.linalg.eigh(_project_psd(s0[ti] / np.outer(d, d)))
                lam, vec = lam[::-1][:rk], vec[:, ::-1][:, :rk]
                lam = np.maximum(lam, 1e-8 * max(float(lam[0]), 1e-12))
                parts.append((vec * np.sqrt(lam)).ravel())
        x = np.concatenate(parts)
        ncol = len(self.cols)

        def coef(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            c = np.zeros(ncol)
            dc = np.zeros((ncol, x.size))
            c[lin] = x[: lin.size]
            dc[lin, np.arange(lin.size)] = 1.0
            for _, idx, ia, ib, dd, g, rk, o in cones:
                if rk:
                    f_ = x[o : o + g * rk].reshape(g, rk)
                    c[idx] = dd * np.sum(f_[ia] * f_[ib], axis=1)
                    jb = np.zeros((idx.size, g, rk))
                    rows = np.arange(idx.size)
                    jb[rows, ia] += dd[:, None] * f_[ib]
                    jb[rows, ib] += dd[:, None] * f_[ia]
                    dc[idx, o : o + g * rk] = jb.reshape(idx.size, g * rk)
            return c, dc

        c, dc = coef(x)
        r = self.b - ax @ c
        f = float(r @ r)
        for _ in range(60 if x.size else 0):
            self.n_inner += 1
            jm = ax @ dc
            gc = -2.0 * (ax.T @ r)
            grad = dc.T @ gc
            hm = 2.0 * (jm.T @ jm)
            for _, idx, ia, ib, dd, g, rk, o in cones:
                if rk:
                    gt = np.zeros((g, g))
                    gt[ia, ib] = gt[ib, ia] = np.where(ia == ib, 1.0, 0.5) * gc[idx] * dd
                    hm[o : o + g * rk, o : o + g * rk] += 2.0 * np.kron(gt, np.eye(rk))
            lam, vec = np.linalg.eigh(hm)
            mu = max(0.0, -float(lam[0])) + 1e-12 * max(float(lam[-1]), 1e-300)
            step = -(vec @ ((vec.T @ grad) / (lam + mu)))
            s_ = 1.0
            for _ in range(40):
                cn, dcn = coef(x + s_ * step)
                rn = self.b - ax @ cn
                fn = float(rn @ rn)
                if fn <= f:
                    break
                s_ *= 0.5
            else:
                break
            x, c, dc, r = x + s_ * step, cn, dcn, rn
            done = f - fn <= 1e-15 * f
            f = fn
            if done:
                break
        if np.any(c[lin] < 0):
            return None
        return f, c, r

    def profile(self, u: np.ndarray) -> float:
        return self.solve(np.asarray(u, float))[0]


def _is_psd(s: np.ndarray) -> bool:
    if s.size == 0:
        return True
    scale = max(float(np.max(np.abs(np.diagonal(s)))), 1e-300)
    return bool(np.linalg.eigvalsh(s)[0] >= -1e-12 * scale)


def _rank(s: np.ndarray, rel: float) -> int:
    """Rank of the projection of ``s`` onto the PSD cone: eigenvalues above ``rel`` times the
    largest."""
    lam = np.linalg.eigvalsh(0.5 * (s + s.T))
    top = float(lam[-1]) if lam.size else 0.0
    return int(np.sum(lam > rel * top)) if top > 0 else 0


def _project_psd(s: np.ndarray) -> np.ndarray:
    lam, vec = np.linalg.eigh(0.5 * (s + s.T))
    return (vec * np.clip(lam, 0.0, None)) @ vec.T


def _local(
    fun, x0: np.ndarray, step: float, lo: float, hi: float
) -> tuple[float, np.ndarray, bool]:
    """Nelder-Mead with restarts on a shrinking simplex until a restart stops improving."""
    x = np.clip(np.asarray(x0, float), lo, hi)
    f = fun(x)
    converged = False
    d = x.size
    for _ in range(8):
        simplex = np.vstack(
            [x]
            + [
                np.clip(x + step * e, lo, hi) if x[i] + step <= hi else x - step * e
                for i, e in enumerate(np.eye(d))
            ]
        )
        res = optimize.minimize(
            fun,
            x,
            method="Nelder-Mead",
            options={
                "xatol": 1e-6,
                "fatol": 1e-10 * max(f, 1e-300),
                "maxfev": 300 * d + 200,
                "initial_simplex": simplex,
            },
        )
        fn = float(res.fun)
        if fn < f * (1 - 1e-10):
            x, f = np.clip(np.asarray(res.x, float), lo, hi), fn
            step = max(step / 8, 1e-5)
        else:
            converged = bool(res.success) or fn <= f
            break
    return f, x, converged


def _grid_axis(tau_max: float, npts: int) -> np.ndarray:
    return np.linspace(math.log(0.25), math.log(4.0 * tau_max), npts)


# -------------------------------------------------------------------------------------------
# results
# -------------------------------------------------------------------------------------------
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
        return _corr(self.cov)

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
        for t in self.model._terms():
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
            sh = self.model._shared_index(c)
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
        lines += _warning_lines(self.at_bound, self.converged, self.message)
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


# -------------------------------------------------------------------------------------------
# fitting
# -------------------------------------------------------------------------------------------
def _weights(wvm: WVMatrix, weights: str | np.ndarray) -> tuple[np.ndarray, str]:
    j, k = wvm.n_levels, wvm.k
    for p, c in enumerate(wvm.channels):
        if not np.any(wvm.values[:, p, p] > 0):
            raise FitError(
                f"channel {c} is constant (its WV is 0 at every level): there is "
                "no noise to model; drop it from the channels"
            )
    if isinstance(weights, str):
        if weights == "identity":
            return np.ones((j, k, k)), "identity"
        if weights != "ci":
            raise FitError(
                f"unknown weights {weights!r}: use 'ci', 'identity', 'efficient' or a "
                f"({j}, {k}, {k}) array"
            )
        width = wvm.ci_high - wvm.ci_low
        ok = np.isfinite(width) & (width > 0)
        if not np.all(ok):
            lv, p, q = (int(v) for v in np.argwhere(~ok)[0])
            what = (
                f"the WV of {wvm.channels[p]}"
                if p == q
                else f"the WCCV of {wvm.channels[p]} and {wvm.channels[q]}"
            )
            raise FitError(
                f"the interval of {what} at level {lv + 1} is empty or not finite, "
                "so weights='ci' is undefined; use weights='identity'"
            )
        return 1.0 / width**2, "ci"
    w = np.asarray(weights, dtype=float)
    if w.shape != (j, k, k):
        raise FitError(
            f"the weights have shape {w.shape}; give a ({j}, {k}, {k}) array, one "
            "non-negative weight per moment"
        )
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise FitError("the weights must be finite and non-negative")
    if not np.allclose(w, np.transpose(w, (0, 2, 1))):
        raise FitError("the weights must be symmetric in the two channel indices")
    return w, "user"


def _as_wvm(data: Any, channels: Sequence[str], fs: float | None, levels: int | None) -> WVMatrix:
    if isinstance(data, WVMatrix):
        missing = [c for c in channels if c not in data.channels]
        if missing:
            raise FitError(
                f"the model's channel(s) {', '.join(missing)} are not in the WV "
                f"matrix (channels: {', '.join(data.channels)})"
            )
        if fs is not None and not math.isclose(fs, data.fs, rel_tol=1e-9):
            raise FitError(f"fs={fs} Hz disagrees with the WV matrix's fs={data.fs} Hz")
        wvm = data.select(channels) if tuple(channels) != data.channels else data
    else:
        if isinstance(data, np.ndarray) and data.ndim == 2:
            if data.shape[1] != len(channels):
                raise FitError(
                    f"the data has {data.shape[1]} columns but the model has "
                    f"{len(channels)} channels ({', '.join(channels)})"
                )
            data = dict(zip(channels, data.T, strict=True))
        try:
            wvm = wv_matrix(data, channels=list(channels), fs=fs)
        except KeyError as e:
            raise FitError(str(e.args[0]) if e.args else str(e)) from None
    if levels is not None:
        if not 1 <= levels <= wvm.n_levels:
            raise FitError(
                f"levels={levels} is out of range: the WV matrix has {wvm.n_levels} levels"
            )
        wvm = wvm.truncate(levels)
    return wvm


def fit_mgmwm(
    data: WVMatrix | Any,
    model: MultiModel,
    *,
    weights: str | np.ndarray = "ci",
    levels: int | None = None,
    fs: float | None = None,
) -> MGMWMResult:
    """Fit a multivariate latent model by the multivariate GMWM.

    Parameters
    ----------
    data : WVMatrix, ndarray (N, k), mapping of name to series, or ImuLog
        The empirical WV/WCCV matrix (from :func:`engine.wv_matrix`), or the raw channels
        (the matrix is computed for the model's channels, in the model's order).
    model : MultiModel
        Structure (values, if any, are extra starting points).
    weights : {"ci", "identity", "efficient"} or ndarray (J, k, k)
        Moment weights: ``1 / (ci_high - ci_low)^2`` (default), ones, given diagonal weights,
        or ``"efficient"``: two-step, ``Omega = V^-1`` with V the model-implied Gaussian
        covariance of all stacked moments (:func:`moment_covariance`) at the ``"ci"`` fit
        (the GMWM paper, Corollary 1; it lets the WCCV inform the WV parameters).
    levels : int, optional
        Use only the first ``levels`` levels.
    fs : float, optional
        Sampling frequency of raw data (Hz).

    Returns
    -------
    MGMWMResult

    Raises
    ------
    ModelError
        Bad model structure (see :class:`MultiModel`) or more parameters than moments.
    FitError
        Missing or constant channels, empty intervals, bad weights.
    """
    t0 = time.perf_counter()
    if not isinstance(model, MultiModel):
        raise ModelError(
            f"model must be a MultiModel, got {type(model).__name__}; build one "
            "with MultiModel(channels, 'WN+RW', shared=['RW'])"
        )
    wvm = _as_wvm(data, model.channels, fs, levels)
    efficient = isinstance(weights, str) and weights == "efficient"
    w, wname = _weights(wvm, "ci" if efficient else weights)
    n_par = sum(
        len(t.proto.param_names)
        if not t.shared
        else (len(t.chans) if t.diagonal else len(t.chans) * (len(t.chans) + 1) // 2)
        + (1 if t.nonlinear else 0)
        for t in model._terms()
    )
    n_mom = wvm.n_levels * wvm.k * (wvm.k + 1) // 2
    if n_par > n_mom:
        raise ModelError(
            f"the model has {n_par} parameters but there are only {n_mom} "
            "moments: use more levels or a smaller model"
        )
    for c in model.channels:
        try:
            model.models[c].validate(wvm.n_levels)
        except ModelError as e:
            raise ModelError(f"channel {c}: {e}") from None
    if not efficient:
        return _fit(wvm, model, w, None, wname, t0)
    first = _fit(wvm, model, w, None, "ci", t0)
    from .inference import inverse_cov as _inverse

    omega = _inverse(moment_covariance(first.model, wvm))
    return _fit(wvm, first.model, w, omega, "efficient", t0)


def _fit(
    wvm: WVMatrix, model: MultiModel, w: np.ndarray, omega: np.ndarray | None, wname: str, t0: float
) -> MGMWMResult:
    prob = _MProblem(model, wvm, w, omega)
    lo, hi = math.log(prob.tc_min), math.log(prob.tc_max)
    if not prob.slots:
        u = np.zeros(0)
        converged, method, msg = True, "closed-form", "exact (convex inner problem)"
    else:
        u, converged = _search(prob, model, wvm, w, lo, hi)
        method = "profiled nelder-mead"
        msg = (
            "converged"
            if converged
            else "the local search stopped before meeting its "
            "tolerance; the estimate may be slightly above the minimum"
        )
    f, h, s, coupled = prob.solve(u)
    fitted = _fitted_model(model, prob, u, h, s)
    comps = fitted.components(wvm.tau_samples, wvm.fs)
    implied = np.sum(np.array(list(comps.values())), axis=0)
    iu = np.triu_indices(wvm.k)
    if omega is None:
        resid = (wvm.values - implied)[:, iu[0], iu[1]]
        objective = float(np.sum(w[:, iu[0], iu[1]] * resid**2))
        weights = w
    else:
        r = prob.y - np.concatenate([implied[:, p, q] for p, q in prob.pairs])
        objective = float(r @ omega @ r)
        dg = np.diagonal(omega).reshape(len(prob.pairs), wvm.n_levels)
        weights = np.zeros_like(w)
        for pi, (p, q) in enumerate(prob.pairs):
            weights[:, p, q] = weights[:, q, p] = dg[pi]
    at_bound = _at_bound(fitted, prob, u)
    return MGMWMResult(
        model=fitted,
        wvm=wvm,
        weights=weights,
        weights_name=wname,
        objective=objective,
        implied=implied,
        components=comps,
        converged=converged,
        at_bound=at_bound,
        psd_active=coupled,
        n_evaluations=prob.n_eval,
        method=method,
        message=msg,
        elapsed_s=time.perf_counter() - t0,
        omega=omega,
        n_inner=prob.n_inner,
    )


def moment_covariance(model: MultiModel, wvm: WVMatrix) -> np.ndarray:
    """Asymptotic Gaussian covariance of the stacked WV/WCCV moments implied by a model.

    Moments are stacked pair by pair (``(0,0), (0,1), .., (1,1), ..``), levels inside. With
    ``S(f) = sum_a s_a(f) C_a`` the model's spectral matrix (``s_a`` the spectral density of a
    process per unit variance, ``C_a`` its k x k coefficient matrix) and ``G_j = |H_j|^2`` the
    Haar squared gain,

        Cov(nu_pq_j, nu_rs_l) = 1 / max(M_j, M_l) int G_j G_l (S_pr S_qs + S_ps S_qr) df

    (Isserlis' formula for the products of the coefficient series; with p = q = r = s it is
    the univariate :func:`engine.inference.wv_cov_model`). The integrals
    ``int G_j G_l s_a s_b df`` are computed once per pair of process shapes.

    Parameters
    ----------
    model : MultiModel
        Every value set (e.g. ``result.model``).
    wvm : WVMatrix
        Gives the levels, ``M_j`` and fs.

    Returns
    -------
    ndarray, shape (P J, P J)
        ``P = k (k + 1) / 2`` pairs.
    """
    from .inference import frequency_grid as _frequency_grid
    from .inference import spectral_density as _spectral_density

    if not model.is_set:
        raise FitError("moment_covariance needs a model with every value set (a fitted model)")
    fs, k, nj = wvm.fs, model.k, wvm.n_levels
    shapes: dict[tuple[str, float | None], list[Any]] = {}
    for t in model._terms():
        c, phi = model._term_values(t, fs)
        if t.code == "DR" or not np.any(c != 0):
            continue  # deterministic, or absent
        key = (t.code, None if phi is None else float(phi))
        if key not in shapes:
            unit = t.proto.cleared().from_fit(1.0, phi, fs)
            shapes[key] = [unit, np.zeros((k, k))]
        shapes[key][1][np.ix_(t.chans, t.chans)] += c
    units = [v[0] for v in shapes.values()]
    cmats = [v[1] for v in shapes.values()]
    ns = len(units)
    f, wts = _frequency_grid(nj, Model(tuple(units)), fs)
    integ = np.zeros((ns, ns, nj, nj))
    inv_m2 = 1.0 / 4.0 ** np.arange(nj)
    chunk = 1 << 14
    for a0 in range(0, f.size, chunk):
        fc, wc = f[a0 : a0 + chunk], wts[a0 : a0 + chunk]
        x = np.pi * fc
        sin_m, cos_m = np.sin(x), np.cos(x)
        base = 1.0 / (sin_m * sin_m)
        gains = np.empty((nj, fc.size))
        for j in range(nj):
            sin2 = sin_m * sin_m
            gains[j] = sin2 * sin2 * base * inv_m2[j]
            sin_m, cos_m = 2.0 * sin_m * cos_m, 1.0 - 2.0 * sin2
        g = [gains * _spectral_density(u, fc, fs) for u in units]
        for a in range(ns):
            ga = g[a] * wc
            for b in range(a, ns):
                # einsum, not BLAS: on a loaded machine a threaded BLAS spins on these small
                # products (100x slower); the flops are negligible either way
                integ[a, b] += np.einsum("jf,lf->jl", ga, g[b])
        for a in range(ns):
            for b in range(a + 1, ns):
                integ[b, a] = integ[a, b].T
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    npairs = len(pairs)
    v = np.zeros((npairs * nj, npairs * nj))
    for a in range(ns):
        for b in range(ns):
            ca, cb = cmats[a], cmats[b]
            t = np.array(
                [[ca[p, r] * cb[q, s] + ca[p, s] * cb[q, r] for r, s in pairs] for p, q in pairs]
            )
            if np.any(t != 0):
                v += np.kron(t, integ[a, b])
    m_j = wvm.n_coef.astype(float)
    v /= np.tile(np.maximum.outer(m_j, m_j), (npairs, npairs))
    return 0.5 * (v + v.T)


def _fitted_model(
    model: MultiModel, prob: _MProblem, u: np.ndarray, h: dict[int, float], s: dict[int, np.ndarray]
) -> MultiModel:
    phis = {ti: prob.phi_of(ti, float(ui)) for ti, ui in zip(prob.slots, u, strict=True)}
    fs = prob.fs
    models = {c: list(m.processes) for c, m in model.models.items()}
    shared = []
    for ti, t in enumerate(prob.terms):
        phi = phis.get(ti)
        if t.shared:
            cov = s[ti]
            nl = None if phi is None else _nl_of_phi(t.code, phi, fs)
            shared.append(
                SharedProcess(
                    t.label, tuple(model.channels[i] for i in t.chans), None, nl, t.diagonal
                )
            )
            for a, p in enumerate(t.chans):
                c = model.channels[p]
                i = model.index(t.label, c)
                models[c][i] = (
                    t.proto.from_fit(float(cov[a, a]), phi, fs)
                    if t.nonlinear
                    else t.proto.from_fit(float(cov[a, a]), None, fs)
                )
        else:
            c = model.channels[t.chans[0]]
            i = model.models[c].labels.index(t.label)
            models[c][i] = t.proto.from_fit(float(h[ti]), phi, fs)
    out = MultiModel(
        model.channels, {c: Model(tuple(v)) for c, v in models.items()}, [sp for sp in shared]
    )
    # covariances are set directly: fitted ones may be singular (PSD, not PD)
    fixed = []
    shared_terms = [ti for ti, t in enumerate(prob.terms) if t.shared]
    for sp, ti in zip(out.shared, shared_terms, strict=True):
        fixed.append(replace(sp, cov=np.array(s[ti], dtype=float)))
    out.shared = tuple(fixed)
    return out


def _at_bound(fitted: MultiModel, prob: _MProblem, u: np.ndarray) -> list[str]:
    out = []
    for t in fitted._terms():
        if t.shared:
            sp = fitted.shared_process(t.label)
            cov = np.asarray(sp.cov)
            for a, c in enumerate(sp.channels):
                if cov[a, a] == 0.0:
                    out.append(f"{t.label}.cov[{c},{c}]")
            if not t.diagonal and cov.shape[0] > 1:
                lam = np.linalg.eigvalsh(cov)
                if lam[0] <= 1e-10 * max(float(lam[-1]), 1e-300):
                    out.append(f"{t.label}.cov (singular)")
        elif t.proto.linear_coef() == 0.0:
            p = t.proto
            name = p.param_names[-1] if p.nonlinear else p.param_names[0]
            out.append(f"{fitted.channels[t.chans[0]]}.{t.label}.{name}")
    for ti, ui in zip(prob.slots, u, strict=True):
        tc = math.exp(float(ui))
        if tc <= prob.tc_min * 1.0001 or tc >= prob.tc_max / 1.0001:
            t = prob.terms[ti]
            key = t.label if t.shared else f"{fitted.channels[t.chans[0]]}.{t.label}"
            out.append(f"{key}.{t.proto.nonlinear}")
    return out


def _search(
    prob: _MProblem, model: MultiModel, wvm: WVMatrix, w: np.ndarray, lo: float, hi: float
) -> tuple[np.ndarray, bool]:
    """Non-linear search: univariate starts, scans of shared phi/beta, Nelder-Mead, polish."""
    fs = wvm.fs
    # univariate fits of every channel give per-channel starting values
    uni: dict[str, Model] = {}
    for p, c in enumerate(model.channels):
        m = model.models[c].cleared()
        if m.is_linear:
            continue
        try:
            uni[c] = fit_gmwm(wvm.wv(p), m, weights=w[:, p, p]).model
        except (FitError, ModelError) as e:
            raise FitError(f"channel {c}: {e}") from None

    def uni_u(c: str, label: str) -> float:
        """Start from channel c's univariate fit (AR1/GM most persistent first)."""
        i = _find(uni[c], label)
        phi = None if i is None else uni[c].processes[i].nl_value(fs)
        if phi is None or not 0 < phi < 1:
            return math.log(float(prob.tau[0]))
        return min(max(prob.u_of_phi(phi), lo), hi)

    def u_from(phi: float | None) -> float:
        if phi is None or not 0 < phi < 1:
            return math.log(float(prob.tau[0]))
        return min(max(prob.u_of_phi(phi), lo), hi)

    u0 = np.empty(len(prob.slots))
    shared_slots = []
    for si, ti in enumerate(prob.slots):
        t = prob.terms[ti]
        if t.shared:
            shared_slots.append(si)
            u0[si] = np.median([uni_u(model.channels[p], t.label) for p in t.chans])
        else:
            u0[si] = uni_u(model.channels[t.chans[0]], t.label)
    starts = [u0]
    # user values as another start
    user = []
    for ti in prob.slots:
        t = prob.terms[ti]
        if t.shared:
            phi = _phi_of_nl(t.code, model.shared_process(t.label).nl, fs)
        else:
            phi = t.proto.nl_value(fs) if getattr(t.proto, t.proto.nonlinear) is not None else None
        user.append(phi)
    if all(v is not None and 0 < v < 1 for v in user):
        starts.append(np.array([u_from(v) for v in user]))
    # each shared phi/beta: the channels' univariate values and a scan, others held
    grid = _grid_axis(float(prob.tau[-1]), 40)
    best_u = min(starts, key=prob.profile).copy()
    for si in shared_slots:
        t = prob.terms[prob.slots[si]]
        cands = [uni_u(model.channels[p], t.label) for p in t.chans] + list(grid)
        vals = []
        for cval in cands:
            uu = best_u.copy()
            uu[si] = cval
            vals.append((prob.profile(uu), cval))
        best_u[si] = min(vals)[1]
    starts.append(best_u)
    step = float(grid[1] - grid[0])
    results = []
    for st in starts:
        if any(np.max(np.abs(st - r[1])) < 1e-9 for r in results):
            continue
        results.append(_local(prob.profile, st, step, lo, hi))
    f, u, conv = min(results, key=lambda r: r[0])
    # polish block by block (a channel's own AR1/GM terms, then the shared ones)
    blocks: dict[Any, list[int]] = {}
    for si, ti in enumerate(prob.slots):
        t = prob.terms[ti]
        blocks.setdefault("shared" if t.shared else t.chans[0], []).append(si)
    if len(blocks) > 1:
        for _ in range(3):
            improved = False
            for idx in blocks.values():

                def sub(v: np.ndarray, idx: list[int] = idx, base: np.ndarray = u) -> float:
                    uu = base.copy()
                    uu[idx] = v
                    return prob.profile(uu)

                fb, vb, _ = _local(sub, u[idx], step / 4, lo, hi)
                if fb < f * (1 - 1e-10):
                    u = u.copy()
                    u[idx] = vb
                    f, improved = fb, True
            if not improved:
                break
        f2, u2, conv2 = _local(prob.profile, u, step / 8, lo, hi)
        if f2 <= f:
            f, u, conv = f2, u2, conv2
    return u, conv


# -------------------------------------------------------------------------------------------
# test of dependence
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DependenceTest:
    """Parametric-bootstrap test of dependence between channels.

    ``statistic = Q_independent - Q_shared`` (objective difference, >= 0 since the models
    are nested); ``p_value = (1 + #{D_b >= statistic}) / (1 + B)``.
    """

    statistic: float
    p_value: float
    objective_independent: float
    objective_shared: float
    labels: tuple[str, ...]
    B: int
    bootstrap: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "statistic": self.statistic,
            "p_value": self.p_value,
            "objective_independent": self.objective_independent,
            "objective_shared": self.objective_shared,
            "labels": list(self.labels),
            "B": self.B,
        }


def _boot_dependence(args: tuple) -> float | None:
    null_fit, h0, h1, n, fs, levels, weights, seed = args
    x = null_fit.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    try:
        wvm = wv_matrix(x, channels=list(null_fit.channels), fs=fs, levels=levels)
        q0 = fit_mgmwm(wvm, h0, weights=weights).objective
        q1 = fit_mgmwm(wvm, h1, weights=weights).objective
    except (FitError, ModelError, ValueError):  # pragma: no cover - degenerate replicate
        return None
    return q0 - q1


def dependence_test(
    data: WVMatrix | Any,
    model: MultiModel,
    *,
    labels: Sequence[str] | None = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
    weights: str = "ci",
    fs: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> DependenceTest:
    """Does sharing processes between channels improve the fit more than chance?

    The model with the given shared processes made independent across channels (WN/RW:
    independent per-channel processes; AR1/GM: common phi/beta, diagonal covariance) is
    fitted, and the data's objective difference ``D = Q_independent - Q_shared`` is compared
    with ``D_b`` over ``B`` series simulated from the fitted independent model, each refitted
    with both models (the multivariate paper, section IV).

    Parameters
    ----------
    data : WVMatrix, or raw channels as for :func:`fit_mgmwm`
        With a WVMatrix, simulated replicates get the same length, levels and fs.
    model : MultiModel
        The model with the shared processes.
    labels : sequence of str, optional
        Shared processes to test (default: all).
    B, seed, workers
        Bootstrap replicates, base seed (replicate b uses ``SeedSequence(seed).spawn``),
        worker processes (results do not depend on it).
    weights : {"ci", "identity"}
        Weights (recomputed for every replicate from its own intervals).
    fs : float, optional
        Sampling frequency of raw data (Hz).
    progress : callable (done, total), optional
        Called after every bootstrap replicate (with ``workers > 1``, after every batch of
        ``4 workers`` replicates, once per replicate of the batch). An exception raised by
        it aborts the test and propagates (e.g. a user's cancel). Results do not depend on
        it.

    Returns
    -------
    DependenceTest
    """
    from .inference import parallel_map as _map

    if B < 1:
        raise ValueError(f"B must be at least 1, got {B}")
    if not model.shared:
        raise ModelError("the model has no shared process: nothing to test")
    wvm = _as_wvm(data, model.channels, fs, None)
    h1 = model.cleared()
    h0 = model.without_dependence(labels).cleared()
    tested = tuple(labels) if labels is not None else tuple(s.label for s in model.shared)
    fit1 = fit_mgmwm(wvm, h1, weights=weights)
    fit0 = fit_mgmwm(wvm, h0, weights=weights)
    stat = fit0.objective - fit1.objective
    seeds = np.random.SeedSequence(seed).spawn(B)
    items = [(fit0.model, h0, h1, wvm.n, wvm.fs, wvm.n_levels, weights, sd) for sd in seeds]
    if progress is None:
        out = _map(_boot_dependence, items, workers)
    else:
        out = []
        size = 1 if workers <= 1 else 4 * workers
        for i in range(0, len(items), size):
            for d in _map(_boot_dependence, items[i : i + size], workers):
                out.append(d)
                progress(len(out), len(items))
    boot = [d for d in out if d is not None]
    if len(boot) < max(1, B // 2):
        raise FitError("too many bootstrap replicates failed; the model may be unidentifiable")
    p = (1 + sum(d >= stat for d in boot)) / (1 + len(boot))
    return DependenceTest(
        float(stat),
        float(p),
        float(fit0.objective),
        float(fit1.objective),
        tested,
        len(boot),
        tuple(float(d) for d in boot),
    )


# -------------------------------------------------------------------------------------------
# command line: ``gmwm fit`` with several channels or several files
# -------------------------------------------------------------------------------------------
def cli_fit(args: Any) -> dict[str, Any] | str:
    """``gmwm fit`` for several channels (MGMWM) or several recordings (replicates).

    ``gmwm fit IN.h5 --model WN+RW --channels gyro_x,gyro_y,gyro_z [--shared RW]
    [--dependence-test]`` fits a multivariate model; ``gmwm fit IN1.h5 IN2.h5 ... --model M
    [--channel gyro_x]`` fits one model to every file. Errors are raised as FitError /
    ModelError / LoadError (the command prints them on one line, exit status 2).
    """
    import argparse

    from .io import load_log

    files = [args.input] + list(getattr(args, "more_inputs", None) or [])
    channels = getattr(args, "channels", None)
    shared = getattr(args, "shared", None)
    if getattr(args, "ci", None):
        raise FitError("--ci intervals are available for single-channel fits only")
    if channels is None:
        if shared:
            raise FitError("--shared needs --channels (the channels that share the processes)")
        if getattr(args, "dependence_test", False):
            raise FitError("--dependence-test needs --channels and --shared")
        if args.weights == "efficient":
            raise FitError(
                "--weights efficient is not available for replicate fits; use ci or identity"
            )
        from .cli import _load_wv
        from .fit.replicates import fit_replicates

        wvs, names = [], []
        for f in files:
            wv, name = _load_wv(argparse.Namespace(**{**vars(args), "input": f}))
            wvs.append(wv)
            names.append(name)
        res = fit_replicates(wvs, args.model, weights=args.weights)
        if args.json:
            d = res.to_dict()
            d["inputs"] = files
            d["channels"] = names
            return json_ready(d)
        head = "\n".join(f"{f} [{n}]" for f, n in zip(files, names, strict=True))
        return f"{head}\n{res.summary()}"
    if len(files) > 1:
        raise FitError(
            "--channels takes one INPUT (channels recorded together); several "
            "INPUT files are replicates of one channel (use --channel)"
        )
    if getattr(args, "robust", False):
        raise FitError("--robust is not available with --channels (the WCCV is classical)")
    if getattr(args, "stream", False):
        raise FitError("--stream is not available with --channels")
    names = [c.strip() for c in channels.split(",") if c.strip()]
    try:
        from .cli_export import log_kwargs

        kw = log_kwargs(args)
    except ImportError:  # pragma: no cover - older command line without the log options
        kw = {}
    log = load_log(args.input, fs=args.fs, **kw)
    if log.is_summary:
        raise FitError(
            f"{args.input} is a WV summary file: --channels needs the raw channels "
            "(the WCCV is not stored)"
        )
    unknown = [c for c in names if c not in log.channels]
    if unknown:
        raise FitError(
            f"{args.input}: unknown channel(s) {', '.join(unknown)}; the channels "
            f"are {', '.join(log.channels)}"
        )
    model = MultiModel(names, args.model, shared=shared or ())
    wvm = wv_matrix(log, channels=names, levels=args.levels)
    res = fit_mgmwm(wvm, model, weights=args.weights)
    test = None
    if getattr(args, "dependence_test", False):
        test = dependence_test(wvm, model, B=args.bootstrap, seed=args.seed, workers=args.workers)
    if args.json:
        d = res.to_dict()
        d["input"] = args.input
        if test is not None:
            d["dependence_test"] = test.to_dict()
        return json_ready(d)
    text = f"{args.input} [{', '.join(names)}]\n{res.summary()}"
    if test is not None:
        text += (
            f"\n\n  test of dependence ({', '.join(test.labels)} shared vs independent): "
            f"D = {test.statistic:.4g}, p = {test.p_value:.3g} "
            f"(parametric bootstrap, B = {test.B})"
        )
    return text
