"""The report's figures as data: :class:`FigureSpec` (curves, bands, points; no drawing library).

:func:`channel_figures` and :func:`check_figure` turn a :class:`~.data.ChannelReport` into
specs that :mod:`.render` draws with Bokeh (interactive) or matplotlib (static), so both
outputs show the same curves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..units import squared
from .data import ChannelReport

__all__ = [
    "Layer",
    "FigureSpec",
    "channel_figures",
    "check_figure",
    "fleet_adev_figure",
    "spread_figure",
    "PALETTE",
    "RAW_WV_COLOR",
    "RAW_WV_LABEL",
]

#: Colours of the data, the model and the processes (Bokeh's Category10).
PALETTE = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)
_DATA, _MODEL = "#1f77b4", "#d62728"
#: The raw (uncompensated) signal's WV beside the temperature-compensated one that is fitted:
#: its colour and legend label (the report's WV figure and the app's Fit view).
RAW_WV_COLOR = "#7f7f7f"
RAW_WV_LABEL = "WV before temperature compensation"


@dataclass(frozen=True, eq=False)
class Layer:
    """One drawn thing: ``kind`` is ``line``, ``dashed``, ``points``, ``band`` (``y`` to
    ``y2``) or ``errorbar`` (a vertical bar from ``y`` to ``y2`` at each ``x``); ``label`` goes
    in the legend (``""``: none)."""

    kind: str
    x: np.ndarray
    y: np.ndarray
    label: str = ""
    color: str = _DATA
    y2: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class FigureSpec:
    """A figure, log-log unless said: ``key`` (unique in the report), axes, layers;
    ``x_range_of`` names the figure whose x-range this one shares (the residual strip under
    its WV); ``x_ticks`` labels the x positions (the units of a fleet's spread plots)."""

    key: str
    title: str
    x_label: str
    y_label: str
    layers: list[Layer] = field(default_factory=list)
    height: int = 330
    x_range_of: str = ""
    log_x: bool = True
    log_y: bool = True
    x_ticks: tuple[tuple[float, str], ...] = ()


def _fine(t: np.ndarray) -> np.ndarray:
    """A fine grid (16 points per octave) over the octave times ``t``."""
    return np.geomspace(t[0], t[-1], 16 * max(t.size - 1, 1) + 1)


def channel_figures(ch: ChannelReport, prefix: str = "") -> list[FigureSpec]:
    """Allan deviation, WV with the fit and its decomposition, residual strip, PSD (keys
    ``<prefix><channel>-adev`` ...)."""
    fit = ch.fit
    if fit is None:
        return []
    u = ch.unit or "u"
    key = prefix + ch.name
    out: list[FigureSpec] = []
    wv = fit.wv
    if ch.allan is not None:
        av = ch.allan
        lv = f"{100 * (1 - av.alpha):g} % interval"
        t = _fine(av.tau_s)
        layers = [
            Layer("band", av.tau_s, av.adev_low, lv, _DATA, av.adev_high),
            Layer("points", av.tau_s, av.adev, "overlapping ADEV", _DATA),
            Layer(
                "line", t, np.sqrt(2.0 * fit.model.wv(2.0 * t * fit.fs, fit.fs)), "model", _MODEL
            ),
        ]
        for i, g in enumerate(ch.guides):
            label = (
                f"{g.code} slope {g.slope:+g}: {g.symbol} = {g.display_value:.3g} {g.display_unit}"
                if g.display_unit
                else f"{g.code} slope {g.slope:+g}: {g.symbol} = {g.datasheet_value:.3g} {g.unit}"
            )
            layers.append(Layer("dashed", t, g.adev(t), label, PALETTE[(i + 2) % 10]))
        out.append(
            FigureSpec(
                f"{key}-adev",
                f"{key}: overlapping Allan deviation and IEEE slope guides",
                "averaging time T [s]",
                f"ADEV [{u}]",
                layers,
            )
        )
    tau = _fine(wv.tau_s)
    tau_samples = tau * fit.fs
    layers = [
        Layer(
            "band", wv.tau_s, wv.ci_low, f"{100 * (1 - wv.alpha):g} % interval", _DATA, wv.ci_high
        ),
        Layer("points", wv.tau_s, wv.variance, "empirical WV", _DATA),
        Layer("line", tau, fit.implied_at(tau_samples), f"GMWM fit {fit.model.spec()}", _MODEL),
    ]
    comps = fit.model.components(tau_samples, fit.fs)
    for i, (lab, c) in enumerate(comps.items()):
        if np.any(c > 0):
            layers.append(Layer("dashed", tau, c, lab, PALETTE[(i + 2) % 10]))
    layers += _raw_wv_layers(ch)
    out.append(
        FigureSpec(
            f"{key}-wv",
            f"{key}: wavelet variance, fit and decomposition",
            "scale tau [s]",
            f"WV [{squared(u) if ch.unit else 'u^2'}]",
            layers,
        )
    )
    ratio = wv.variance / fit.implied
    out.append(
        FigureSpec(
            f"{key}-resid",
            f"{key}: residual strip, empirical / fitted WV (1: on the model)",
            "scale tau [s]",
            "empirical / fitted",
            [
                Layer(
                    "band",
                    wv.tau_s,
                    wv.ci_low / fit.implied,
                    "interval / fit",
                    _DATA,
                    wv.ci_high / fit.implied,
                ),
                Layer("line", wv.tau_s, np.ones_like(ratio), "", _MODEL),
                Layer("points", wv.tau_s, ratio, "empirical / fit", _DATA),
            ],
            height=190,
            x_range_of=f"{key}-wv",
        )
    )
    tl = ch.timeline
    if tl is not None:  # a flight analysed on its still segments: where they are
        lo, hi = float(np.min(tl.low)), float(np.max(tl.high))
        layers = [Layer("band", tl.t, tl.low, "samples (min..max per block)", _DATA, tl.high)]
        for i, (a, b) in enumerate(tl.segments):
            x = np.array([a, b])
            label = "still segments (analysed)" if i == 0 else ""
            layers.append(Layer("band", x, np.full(2, lo), label, PALETTE[2], np.full(2, hi)))
        out.append(
            FigureSpec(
                f"{key}-segments",
                f"{key}: the log in time; shaded: the still segments the WV pools",
                "time [s]",
                f"{ch.name} [{u}]",
                layers,
                height=220,
                log_x=False,
                log_y=False,
            )
        )
    sp = ch.spectrum
    if sp is not None:
        layers = [Layer("line", sp.f, sp.welch, f"Welch (nperseg {sp.nperseg})", _DATA)]
        if np.all(np.isfinite(sp.model)):
            layers.append(Layer("line", sp.f, sp.model, "model PSD", _MODEL))
        for i, (lab, c) in enumerate(sp.components.items()):
            layers.append(Layer("dashed", sp.f, c, lab, PALETTE[(i + 2) % 10]))
        out.append(
            FigureSpec(
                f"{key}-psd",
                f"{key}: power spectral density (one-sided)",
                "frequency [Hz]",
                f"PSD [{squared(u) if ch.unit else 'u^2'}/Hz]",
                layers,
            )
        )
    return out


def _raw_wv_layers(ch: ChannelReport) -> list[Layer]:
    """With a temperature fit, the WV of the raw (uncompensated) signal beside the fitted,
    compensated one: its points and interval, in grey (none without a temperature fit)."""
    tf = ch.temperature
    if tf is None or tf.wv_raw is None:
        return []
    raw = tf.wv_raw
    return [
        Layer("band", raw.tau_s, raw.ci_low, "", RAW_WV_COLOR, raw.ci_high),
        Layer("points", raw.tau_s, raw.variance, RAW_WV_LABEL, RAW_WV_COLOR),
    ]


def check_figure(ch: ChannelReport, prefix: str = "") -> FigureSpec | None:
    """The datasheet check: empirical ADEV and interval, datasheet and GMWM model, and the
    scales where the datasheet is outside the interval."""
    c = ch.check
    if c is None:
        return None
    t = c.allan_tau_s
    lo, hi = np.sqrt(2.0 * c.ci_low), np.sqrt(2.0 * c.ci_high)
    layers = [
        Layer("band", t, lo, f"{100 * c.level:g} % interval", _DATA, hi),
        Layer("points", t, c.empirical_adev, "empirical ADEV", _DATA),
        Layer("line", t, c.datasheet_adev, "datasheet model", "#2ca02c"),
    ]
    if c.fit_wv is not None:
        layers.append(Layer("line", t, np.sqrt(2.0 * c.fit_wv), "GMWM fit", _MODEL))
    out = np.array([v != "inside" for v in c.verdict])
    if out.any():
        layers.append(
            Layer("points", t[out], c.datasheet_adev[out], "datasheet outside", "#000000")
        )
    return FigureSpec(
        f"{prefix}{ch.name}-check",
        f"{ch.name}: datasheet check",
        "averaging time T [s]",
        f"ADEV [{ch.unit}]",
        layers,
    )


def fleet_adev_figure(
    key: str, channel: str, unit: str, curves: Sequence[tuple[str, ChannelReport]]
) -> FigureSpec:
    """Every unit's overlapping Allan deviation of one channel, overlaid (points and line, a
    colour per unit); ``curves`` are ``(unit name, its ChannelReport)``."""
    layers = []
    for i, (name, ch) in enumerate(curves):
        av = ch.allan
        if av is None:
            continue
        c = PALETTE[i % len(PALETTE)]
        layers.append(Layer("line", av.tau_s, av.adev, name, c))
        layers.append(Layer("points", av.tau_s, av.adev, "", c))
    return FigureSpec(
        key,
        f"{channel}: overlapping Allan deviation of every unit",
        "averaging time T [s]",
        f"ADEV [{unit or 'u'}]",
        layers,
        height=360,
    )


def spread_figure(
    key: str,
    title: str,
    y_label: str,
    names: Sequence[str],
    values: Sequence[tuple[float, float, float, bool]],
    limit: float | None = None,
) -> FigureSpec:
    """One term across the units: per unit (x = 1, 2 ... labelled by ``names``) its value and
    interval ``(value, low, high, outlier)``, outliers in red, the median dashed and the
    acceptance ``limit`` (if any) as a green line. Missing units have a NaN value."""
    x = np.arange(1.0, len(names) + 1.0)
    v = np.array([t[0] for t in values], float)
    lo = np.array([t[1] for t in values], float)
    hi = np.array([t[2] for t in values], float)
    out = np.array([t[3] for t in values], bool)
    ok = np.isfinite(v)
    iv = ok & np.isfinite(lo) & np.isfinite(hi)
    edge = np.array([0.5, len(names) + 0.5])
    layers = []
    if iv.any():
        layers.append(Layer("errorbar", x[iv], lo[iv], "interval", _DATA, hi[iv]))
    layers.append(Layer("points", x[ok & ~out], v[ok & ~out], "unit", _DATA))
    if (ok & out).any():
        layers.append(Layer("points", x[ok & out], v[ok & out], "outlier (|z| > 3.5)", _MODEL))
    if ok.any():
        med = float(np.median(v[ok]))
        layers.append(Layer("dashed", edge, np.array([med, med]), "median", "#7f7f7f"))
    if limit is not None:
        layers.append(Layer("line", edge, np.array([limit, limit]), "limit", "#2ca02c"))
    return FigureSpec(
        key,
        title,
        "unit",
        y_label,
        layers,
        height=240,
        log_x=False,
        log_y=False,
        x_ticks=tuple((float(i), n) for i, n in zip(x, names, strict=True)),
    )
