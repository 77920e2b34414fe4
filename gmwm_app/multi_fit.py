"""The multi-channel model of the "Multi-channel" tab, without widgets: the per-channel
spec with overrides and shared processes (:func:`build_model`), the fit summary text, and the
parametric-bootstrap test of dependence run in a worker thread (:func:`run_dependence_test`).
"""

from __future__ import annotations

import html
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import engine as eg
from engine.models import ModelError, parse_model
from engine.multivariate import SHAREABLE, DependenceTest, MultiModel

from .state import format_value

__all__ = [
    "MIN_CHANNELS",
    "MAX_CHANNELS",
    "parse_overrides",
    "shareable_labels",
    "build_model",
    "fit_text",
    "Cancelled",
    "run_dependence_test",
    "dependence_text",
]

#: Channels of a multi-channel model: at least, at most.
MIN_CHANNELS = 2
MAX_CHANNELS = 6


def parse_overrides(text: str, channels: Sequence[str]) -> dict[str, str]:
    """Per-channel model specs from lines ``channel: spec`` (blank lines and ``#`` ignored).

    Raises
    ------
    ModelError
        A line without ``:``, or a channel that is not among ``channels``.
    """
    out: dict[str, str] = {}
    for raw in (text or "").splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, spec = line.partition(":")
        if not sep or not name.strip() or not spec.strip():
            raise ModelError(
                f"cannot read the per-channel line {raw.strip()!r}: write "
                "'channel: spec', e.g. 'gyro_z: GM+WN+RW'"
            )
        name = name.strip()
        if name not in channels:
            raise ModelError(
                f"the per-channel line names {name!r}, which is not among the "
                f"chosen channels ({', '.join(channels)})"
            )
        out[name] = spec.strip()
    return out


def shareable_labels(models: Mapping[str, eg.Model]) -> list[tuple[str, list[str]]]:
    """Labels of the shareable processes (WN, RW, AR1, GM) in model order, each with the
    channels whose model has it: ``[("GM", [...]), ("WN", [...]), ...]``."""
    order: list[str] = []
    has: dict[str, list[str]] = {}
    for c, m in models.items():
        for lab, p in zip(m.labels, m.processes, strict=True):
            if p.code not in SHAREABLE:
                continue
            if lab not in has:
                order.append(lab)
                has[lab] = []
            has[lab].append(c)
    return [(lab, has[lab]) for lab in order]


def build_model(
    channels: Sequence[str],
    spec: str,
    overrides: str = "",
    shared: Mapping[str, Sequence[str]] | None = None,
) -> MultiModel:
    """The multivariate model of the view's controls.

    Parameters
    ----------
    channels : sequence of str
        The chosen channels (2 to 6), in grid order.
    spec : str
        Latent model of every channel (``"WN+RW"``), parsed by :func:`engine.parse_model`.
    overrides : str
        Optional lines ``channel: spec`` replacing ``spec`` for some channels.
    shared : mapping of str to sequence of str, optional
        Label -> channels that share it; groups of fewer than 2 chosen channels mean "not
        shared" and are ignored.

    Returns
    -------
    MultiModel

    Raises
    ------
    ModelError
        Bad spec, unknown channel, a process that cannot be shared, fewer than 2 channels.
    """
    chans = list(channels)
    if len(chans) < MIN_CHANNELS:
        raise ModelError(
            f"choose at least {MIN_CHANNELS} channels (chosen: {', '.join(chans) or 'none'})"
        )
    if not (spec or "").strip():
        raise ModelError("the model is empty: type a per-channel model, e.g. WN+RW")
    base = parse_model(spec)
    per = parse_overrides(overrides, chans)
    models = {c: parse_model(per[c]) if c in per else base for c in chans}
    groups: dict[str, list[str]] = {}
    for lab, group in (shared or {}).items():
        g = [c for c in chans if c in set(group)]
        if len(g) >= 2:
            groups[lab] = g
    return MultiModel(chans, models, shared=groups)


def fit_text(result: Any) -> str:
    """One paragraph: objective, weights, method, time and warnings of a fit."""
    if result is None:
        return ""
    w = result.wvm
    parts = [
        f"**Objective** {format_value(result.objective)} [1] ({result.weights} "
        f"weights) for **{html.escape(result.model.spec())}**: {w.k} channels, "
        f"N = {w.n:,}, fs = {w.fs:g} Hz, {w.n_levels} levels; {result.method}, "
        f"{result.n_evaluations} evaluations, {1e3 * result.elapsed_s:.0f} ms."
    ]
    if result.psd_active:
        parts.append("A covariance is on the edge of positive semi-definiteness.")
    if result.at_bound:
        parts.append(f"At a bound: {html.escape(', '.join(result.at_bound))}.")
    parts += [f"Warning: {html.escape(w)}." for w in result.warnings]
    if not result.converged:
        parts.append(html.escape(result.message))
    return " ".join(parts)


class Cancelled(Exception):
    """Raised by the progress callback when the user cancels the dependence test."""


def run_dependence_test(
    wvm: eg.wv.WVMatrix,
    model: MultiModel,
    *,
    B: int = 100,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> DependenceTest:
    """:func:`engine.multivariate.dependence_test` of every shared process (``weights="ci"``,
    one worker).

    ``progress(done, B)`` is called first with ``done = 0`` and then after every replicate;
    it may raise to stop the test.

    Raises
    ------
    ModelError
        The model shares nothing.
    FitError
        Half of the replicates or more failed.
    """
    if B < 1:
        raise ValueError(f"B must be at least 1, got {B}")
    if not model.shared:
        raise ModelError(
            "the model shares no process: mark the channels that share one first (nothing to test)"
        )
    if progress is not None:
        progress(0, B)  # the two observed fits come first
    return eg.multivariate.dependence_test(
        wvm, model, B=B, seed=seed, workers=1, weights="ci", progress=progress
    )


def dependence_text(t: DependenceTest, spec: str) -> str:
    """The test's outcome in words (Markdown)."""
    verdict = (
        "the channels are dependent (the shared covariances improve the fit more than chance)"
        if t.p_value < 0.05
        else "no evidence of dependence at the 5% level"
    )
    return (
        f"**Dependence test** of {', '.join(t.labels)} in *{html.escape(spec)}*: "
        f"D = Q(independent) - Q(shared) = {format_value(t.statistic)} [1], "
        f"p = {format_value(t.p_value, 3)} from {t.B} parametric-bootstrap replicates: "
        f"{verdict}."
    )


# -----------------------------------------------------------------------------------------
# figures (built once per grid size, updated in place)
# -----------------------------------------------------------------------------------------
