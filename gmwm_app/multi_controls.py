"""The settings of the "Multi-channel" tab: which channels, their latent models, and which
channels share each shareable process (WN, RW, AR1, GM; QN and DR are per channel only).

:class:`MultiControls` holds the widgets and what they mean (:attr:`MultiControls.shared_groups`);
every change a user makes calls ``on_change`` (the tab refits). The callbacks are idempotent:
when the tab shows new values (:meth:`MultiControls.follow_channels`, the shared-process
widgets following the models), the widgets' echo changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import panel as pn

import engine as eg
from engine.models import parse_model
from engine.multivariate import SHAREABLE

from .multi_fit import MAX_CHANNELS, MIN_CHANNELS, parse_overrides, shareable_labels

__all__ = ["MultiControls", "DEFAULT_SPEC", "DEFAULT_SHARED", "N_SHARE_POOL"]

#: The per-channel model shown first (the demo gyros: a bias instability, white noise and a
#: rate random walk) and the processes shared by every channel at first.
DEFAULT_SPEC = "GM+WN+RW"
DEFAULT_SHARED = (eg.RW.code,)
#: Shared-process controls created up front (one per shareable label of the model).
N_SHARE_POOL = 6


class MultiControls:
    """Channels, models and shared processes of the Multi-channel tab.

    Parameters
    ----------
    on_change : callable
        Called (no argument) after every change of the settings by the user.

    Attributes
    ----------
    channel_choice : panel.widgets.MultiChoice
        The channels, in grid order.
    spec_input : panel.widgets.TextInput
        The model of every channel.
    override_input : panel.widgets.TextAreaInput
        Other models for some channels (``channel: spec`` per line).
    share_widgets : list of panel.widgets.MultiChoice
        One per shareable label of the models (a pool; the unused ones are hidden).
    share_box : panel.FlexBox
        The shared-process widgets.
    share_note : panel.pane.Markdown
        The processes that are per channel only.
    """

    def __init__(self, on_change: Callable[[], None]) -> None:
        self.on_change = on_change
        self._shared_groups: dict[str, list[str]] = {lab: [] for lab in DEFAULT_SHARED}
        self._shared_all = set(DEFAULT_SHARED)  # labels shared by every channel (default)
        self._share_labels: list[str] = []
        self.channel_choice = pn.widgets.MultiChoice(
            label=f"Channels ({MIN_CHANNELS} to {MAX_CHANNELS}, in grid order)",
            options=[],
            value=[],
            max_items=MAX_CHANNELS,
            sizing_mode="stretch_width",
            css_classes=["gmwm-mchannels"],
        )
        self.spec_input = pn.widgets.TextInput(
            label="Model of every channel (press Enter)",
            value=DEFAULT_SPEC,
            placeholder="e.g. WN+RW or GM+WN+RW",
            width=260,
            css_classes=["gmwm-mspec"],
        )
        self.override_input = pn.widgets.TextAreaInput(
            label="Other models for some channels (optional, one 'channel: spec' per line)",
            value="",
            placeholder="gyro_z: 2*GM+WN+RW",
            height=62,
            sizing_mode="stretch_width",
        )
        for w in (self.channel_choice, self.spec_input, self.override_input):
            # the user's changes; follow_channels sets the channels in one update, whose echo
            # here is the one refit
            w.param.watch(self._on_control, "value")
        self.share_widgets: list[pn.widgets.MultiChoice] = []
        self.share_box = pn.FlexBox(margin=0, sizing_mode="stretch_width")
        for i in range(N_SHARE_POOL):
            self._new_share_widget(i)
        self.share_note = pn.pane.Markdown(
            "", margin=(0, 10), styles={"font-size": "12px", "color": "#555"}
        )

    # ------------------------------------------------------------------------------------
    # what the settings mean
    # ------------------------------------------------------------------------------------
    @property
    def channels(self) -> list[str]:
        """The chosen channels, in grid order."""
        return list(self.channel_choice.value)

    @property
    def shared_groups(self) -> dict[str, list[str]]:
        """Label -> channels sharing it (groups of at least 2 channels)."""
        chans = self.channels
        out = {}
        for lab in self._share_labels:
            g = chans if lab in self._shared_all else self._shared_groups.get(lab, [])
            g = [c for c in chans if c in g]
            if len(g) >= 2:
                out[lab] = g
        return out

    def settings(self) -> tuple[tuple[str, ...], str, str, tuple]:
        """``(channels, spec, overrides, groups)``: what a fit depends on (comparable)."""
        groups = self.shared_groups
        return (
            tuple(self.channels),
            self.spec_input.value or "",
            self.override_input.value or "",
            tuple(sorted((k, tuple(v)) for k, v in groups.items())),
        )

    def share_control(self, label: str) -> pn.widgets.MultiChoice:
        """The widget that marks the channels sharing the process ``label``."""
        try:
            return self.share_widgets[self._share_labels.index(label)]
        except ValueError:
            raise KeyError(
                f"no shareable process {label!r} in the model; shareable: "
                f"{', '.join(self._share_labels) or 'none'}"
            ) from None

    def set_shared(self, label: str, channels: Sequence[str]) -> None:
        """Mark the channels that share ``label`` (fewer than 2: not shared); a change."""
        self.share_control(label).value = [c for c in self.channels if c in set(channels)]

    # ------------------------------------------------------------------------------------
    # the tab -> the widgets
    # ------------------------------------------------------------------------------------
    def follow_channels(self, names: list[str], new_log: bool) -> bool:
        """Offer the channels of the session's log; on a new log, choose its first three
        unless enough of the chosen ones are in it. True when the choice changed (then
        ``on_change`` was called)."""
        keep = [c for c in self.channels if c in names]
        if new_log and len(keep) < MIN_CHANNELS:
            keep = names[:3]
        changed = keep != self.channels
        if changed or list(self.channel_choice.options) != names:
            # one update: the value's echo (_on_control) refreshes the shares and refits once
            self.channel_choice.param.update(options=names, value=keep)
        return changed

    def _new_share_widget(self, i: int) -> None:
        w = pn.widgets.MultiChoice(
            label="",
            options=[],
            value=[],
            visible=False,
            width=330,
            margin=(2, 10),
            css_classes=[f"gmwm-mshare-{i}"],
        )
        w.param.watch(lambda e, i=i: self._on_share(i, e.new), "value")
        self.share_widgets.append(w)
        self.share_box.append(w)

    def _shown_share(self, label: str, has: Sequence[str]) -> list[str]:
        """What the widget of ``label`` shows: its group, among the channels ``has``."""
        return [c for c in self.shared_groups.get(label, []) if c in has]

    def refresh_share_widgets(self) -> None:
        """One MultiChoice per shareable label of the current models (from a pool)."""
        chans = self.channels
        models: dict[str, eg.Model] = {}
        try:
            base = parse_model(self.spec_input.value or "")
            per = parse_overrides(self.override_input.value or "", chans)
            models = {c: parse_model(per[c]) if c in per else base for c in chans}
        except ValueError:
            models = {}  # the fit reports the problem
        labels = shareable_labels(models)
        self._share_labels = [lab for lab, _ in labels]
        while len(self.share_widgets) < len(labels):
            self._new_share_widget(len(self.share_widgets))
        for i, w in enumerate(self.share_widgets):
            # one update per widget: the value's echo in _on_share equals what it shows (no-op)
            if i < len(labels):
                lab, has = labels[i]
                w.param.update(
                    label=f"{lab} shared by",
                    options=list(has),
                    value=self._shown_share(lab, has),
                    visible=True,
                )
            elif w.visible:
                w.param.update(options=[], value=[], visible=False)
        own = sorted(
            {p.code for m in models.values() for p in m.processes if p.code not in SHAREABLE}
        )
        self.share_note.object = f"{', '.join(own)}: per channel only." if own else ""

    # ------------------------------------------------------------------------------------
    # the user -> the settings
    # ------------------------------------------------------------------------------------
    def _on_share(self, i: int, value: list[str]) -> None:
        if i >= len(self._share_labels):
            return  # a hidden widget of the pool being emptied
        lab = self._share_labels[i]
        if list(value) == self._shown_share(lab, self.share_widgets[i].options):
            return  # the echo of refresh_share_widgets: nothing changed
        self._shared_all.discard(lab)
        self._shared_groups[lab] = list(value)
        self.on_change()

    def _on_control(self, _event: Any = None) -> None:
        self.refresh_share_widgets()
        self.on_change()
