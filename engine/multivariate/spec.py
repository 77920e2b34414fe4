"""Multivariate latent models: one univariate model per channel plus shared processes.

Multivariate latent model (the multivariate paper, section II): each of k channels is a sum
of latent processes; a WN, RW, AR1, GM or MA1 process (a class with ``shareable = True``) may
be *shared* by a group of channels, i.e. be one multivariate process whose components are
correlated with a covariance matrix ``Sigma`` (g x g, positive semi-definite); QN and DR are
per channel only. A shared AR1/GM/MA1 has one phi (beta, theta) for the whole group, so that
every element of the group has the same WV shape.
Processes are independent of each other (the paper's Condition 1).

Implied moments. For a shared process with covariance ``Sigma`` and WV shape ``b_j`` (the
process's ``basis``: ``1/tau`` for WN, ``(tau^2 + 2) / (12 tau)`` for RW, the AR1 WV per unit
innovation variance, the GM WV per unit stationary variance) the implied WV/WCCV matrix at
level j is ``b_j Sigma``: the Haar filter is linear, so the coefficients of the group are
``b_j``-scaled copies of ``Sigma``. Independent per-channel processes add to the diagonal
only. The model's (J, k, k) array is the sum over processes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._limits import check_sample_count
from ..models import PROCESS_TYPES, Model, ModelError, Process, parse_model

__all__ = ["SHAREABLE", "SharedProcess", "MultiModel"]

SHAREABLE = tuple(code for code, cls in PROCESS_TYPES.items() if cls.shareable)
"""Process codes that may be shared by several channels (QN and DR are per channel only): the
processes whose class says so (:attr:`engine.models.Process.shareable`)."""


# -------------------------------------------------------------------------------------------
# model specification
# -------------------------------------------------------------------------------------------
def phi_of_nl(proto: Process, nl: float | None, fs: float) -> float | None:
    """Fitter-space value (phi) of a user-space non-linear value (AR1 phi, GM beta [1/s]) of a
    process like ``proto`` (:meth:`engine.models.Process.phi_from_nl`)."""
    if nl is None:
        return None
    return proto.phi_from_nl(float(nl), fs)


def nl_of_phi(proto: Process, phi: float, fs: float) -> float:
    """User-space value of a fitter-space phi (GM beta [1/s] ``-log(phi) fs``, AR1 phi) of a
    process like ``proto`` (:meth:`engine.models.Process.nl_from_phi`)."""
    return proto.nl_from_phi(phi, fs)


def find_label(m: Model, label: str) -> int | None:
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
        (WN: sigma2, RW: gamma2, AR1, MA1: innovation variance, GM: stationary variance), per
        sample; None when unknown.
    nl : float or None
        The group's common non-linear value: AR1 phi, GM beta [1/s], MA1 theta; None
        otherwise.
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
        return corr_matrix(self.cov)


def corr_matrix(c: np.ndarray) -> np.ndarray:
    """Correlation matrix of a covariance (nan for a channel whose variance is 0)."""
    d = np.sqrt(np.maximum(np.diagonal(c), 0.0))
    den = np.outer(d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(den > 0, c / np.where(den > 0, den, 1.0), np.nan)
    np.fill_diagonal(r, np.where(d > 0, 1.0, np.nan))
    return r


@dataclass(frozen=True, eq=False)
class Term:
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
        :class:`SharedProcess` objects. Only the processes whose class is
        :attr:`~engine.models.Process.shareable` (WN, RW, AR1, GM, MA1) can be shared.
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
                i = find_label(m, lab)
                if i is None:
                    raise ModelError(
                        f"channel {c} has no process {lab} to share (its model "
                        f"is {m.spec()}, labels {', '.join(m.labels)})"
                    )
                procs.append(m.processes[i])
            code = procs[0].code
            if not procs[0].shareable:  # the class says (a process registered later too)
                shareable = [c for c, cls in PROCESS_TYPES.items() if cls.shareable]
                raise ModelError(
                    f"{lab} cannot be shared: {code} is per channel only (the "
                    "multivariate paper, section II); shareable: "
                    f"{', '.join(shareable)}"
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
            nl_name = procs[0].nonlinear  # the channels' processes of one label share a class
            if nl_name is not None:
                given = {getattr(p, nl_name) for p in procs} - {None}
                if (
                    nl_v is None
                    and len(given) == 1
                    and all(getattr(p, nl_name) is not None for p in procs)
                ):
                    nl_v = next(iter(given))
                elif nl_v is None and len(given) > 1:
                    raise ModelError(
                        f"the shared {lab} has one {procs[0].nonlinear} for its "
                        f"group, but the channels give {sorted(given)}"
                    )
                if nl_v is not None:
                    try:
                        procs[0].cleared().with_values(**{nl_name: float(nl_v)})
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
        i = find_label(self.models[channel], label)
        if i is None:
            raise KeyError(f"channel {channel} has no process {label}")
        return i

    def shared_index(self, channel: str) -> dict[int, SharedProcess]:
        """The shared processes of a channel, by their position in its model."""
        return {self.index(s.label, channel): s for s in self.shared if channel in s.channels}

    def terms(self) -> list[Term]:
        """Every latent process once: the shared ones first, then each channel's own."""
        terms: list[Term] = []
        for sp in self.shared:
            c0 = sp.channels[0]
            m = self.models[c0]
            proto = m.processes[self.index(sp.label, c0)].cleared()
            terms.append(
                Term(
                    sp.label,
                    tuple(self.channels.index(c) for c in sp.channels),
                    True,
                    sp.diagonal,
                    proto,
                )
            )
        for p, c in enumerate(self.channels):
            m = self.models[c]
            sh = self.shared_index(c)
            for i, (lab, proc) in enumerate(zip(m.labels, m.processes, strict=True)):
                if i not in sh:
                    terms.append(Term(lab, (p,), False, False, proc))
        return terms

    @staticmethod
    def _term_key(t: Term, channels: tuple[str, ...]) -> str:
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
        return all(t.proto.is_set for t in self.terms() if not t.shared)

    def channel_model(self, channel: str) -> Model:
        """The marginal univariate model of one channel (shared processes at their diagonal)."""
        if channel not in self.channels:
            raise KeyError(
                f"unknown channel {channel!r}; the channels are {', '.join(self.channels)}"
            )
        m = self.models[channel]
        sh = self.shared_index(channel)
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
            proc = self.models[s.channels[0]].processes[self.index(s.label, s.channels[0])]
            if s.label not in labels:
                keep.append(SharedProcess(s.label, s.channels, diagonal=s.diagonal))
            elif proc.nonlinear is not None:  # AR1, GM
                keep.append(SharedProcess(s.label, s.channels, diagonal=True))
        return MultiModel(self.channels, {c: m.cleared() for c, m in self.models.items()}, keep)

    # ---- implied moments and simulation ----------------------------------------------------
    def term_values(self, t: Term, fs: float) -> tuple[np.ndarray, float | None]:
        """(coefficient matrix g x g, fitter phi) of a term; raises when a value is missing."""
        if t.shared:
            sp = self.shared_process(t.label)
            if sp.cov is None:
                raise ModelError(
                    f"no covariance for the shared {t.label}: give cov="
                    f"{{'{t.label}': ...}} or fit the model first"
                )
            phi = phi_of_nl(t.proto, sp.nl, fs) if t.nonlinear else None
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
        for t in self.terms():
            c, phi = self.term_values(t, fs)
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
        distribution (each process's :meth:`Process.simulate_shared`). Independent processes
        as :meth:`Process.simulate`.
        """
        n = check_sample_count(n, channels=self.k)
        if not self.is_set:
            raise ModelError(
                "cannot simulate: some values are unknown; give every channel "
                "model's values and cov= (and nl=) for the shared processes"
            )
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        x = np.zeros((n, self.k))
        for t in self.terms():
            if not t.shared:
                x[:, t.chans[0]] += t.proto.simulate(n, g, fs)
                continue
            c, phi = self.term_values(t, fs)
            vals, vecs = np.linalg.eigh(c)
            root = vecs * np.sqrt(np.clip(vals, 0.0, None))  # root @ root.T = c
            z = g.standard_normal((n, len(t.chans))) @ root.T  # rows ~ N(0, c)
            comp = t.proto.simulate_shared(z, root, phi, g)
            x[:, list(t.chans)] += comp
        return x

    # ---- text ---------------------------------------------------------------------------
    def spec(self, values: bool = False) -> str:
        """Readable structure, e.g. ``gyro_x,gyro_y,gyro_z: WN+RW | shared: RW`` (with
        ``values``, each channel model with its values, as :meth:`engine.Model.spec`)."""
        specs = {c: m.spec(values=values) for c, m in self.models.items()}
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
