"""The loaded log: :class:`ImuLog`, :class:`LoadError` and channel selection.

Every reader of :mod:`engine.io` (the ROS-bag reader included) builds an :class:`ImuLog` and
raises :class:`LoadError`; they live here, apart from the readers, so that no reader imports
another. :func:`pick_channel` resolves a channel given by name, index or digit string.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import LoadError
from ..wv.classical import WaveletVariance, wavelet_variance
from ..wv.pooled import pooled_wavelet_variance

__all__ = ["LoadError", "ImuLog", "pick_channel", "channel_axis"]


@dataclass(frozen=True, eq=False)
class ImuLog:
    """A loaded IMU log: raw channels, or precomputed wavelet variances for summary files.

    Attributes
    ----------
    channels : dict of str to ndarray
        Channel name to 1-D float64 (or float32) samples; empty for summary files.
    fs : float
        Sampling frequency (Hz).
    fs_source : str
        Where ``fs`` came from: ``"file"``, ``"time column"``, ``"user"`` or ``"default"``.
    units : dict of str to str
        Channel name (and auxiliary channel name) to unit (``"deg/s"``, ``"g"``, ``"degC"``),
        ``""`` when unknown.
    source : str
        The path as given to :func:`load_log`.
    wv : dict of str to WaveletVariance
        Precomputed WV per channel (summary files only).
    meta : dict
        Format, file attributes (sensor, description, n_samples, ...) and ``notes``.
    aux : dict of str to ndarray
        Auxiliary channels sampled with the signals, not analysed as noise: the sensor's
        temperature (``temperature``, ``imu1_temperature``), same length as the channels.
    segments : tuple of (start, stop)
        Sample ranges analysed (the still parts of a flight, :mod:`engine.io.segments`):
        when set, :meth:`wavelet_variance` pools their WVs; empty: the whole log.
    """

    channels: dict[str, np.ndarray]
    fs: float
    fs_source: str = "default"
    units: dict[str, str] = field(default_factory=dict)
    source: str = ""
    wv: dict[str, WaveletVariance] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    segments: tuple[tuple[int, int], ...] = ()

    @property
    def is_summary(self) -> bool:
        """True for a wavelet-variance summary file (``wv`` set, no raw samples)."""
        return bool(self.wv) and not self.channels

    @property
    def names(self) -> list[str]:
        """Channel names: raw channels, or the WV channels of a summary file."""
        return list(self.wv) if self.is_summary else list(self.channels)

    @property
    def n(self) -> int:
        """Samples per channel (for summaries: length of the underlying raw log)."""
        if self.is_summary:
            return int(next(iter(self.wv.values())).n)
        return int(next(iter(self.channels.values())).size) if self.channels else 0

    @property
    def duration_s(self) -> float:
        """Length of the log in seconds, ``n / fs``."""
        return self.n / self.fs

    def __getitem__(self, name: str | int) -> np.ndarray:
        if self.is_summary:
            raise LoadError(
                f"file '{self.source}' is a wavelet-variance summary without raw samples: "
                f"use log.wv[name] (channels: {', '.join(self.names)})"
            )
        return self.channels[pick_channel(self.source, self.names, name)]

    def unit_of(self, channel: str | int) -> str:
        """The signal unit of a channel: the file's (or the user's), else its stored WV's."""
        name = pick_channel(self.source, self.names, channel)
        unit = self.units.get(name, "")
        if not unit and name in self.wv:
            unit = self.wv[name].unit
        return str(unit or "")

    def wavelet_variance(
        self,
        channel: str | int,
        *,
        robust: bool = False,
        eff: float = 0.6,
        levels: int | None = None,
        alpha: float = 0.05,
        fs: float | None = None,
        progress: Callable[[int, int], object] | None = None,
    ) -> WaveletVariance:
        """The wavelet variance of one channel: computed from the samples, or a summary file's.

        The one place where "the WV of a channel of a log" is decided (the CLI, batch, the
        reports and the app call it), with one set of rules.

        Parameters
        ----------
        channel : str or int
            Channel name or index (:func:`pick_channel`).
        robust, eff : bool, float
            Robust (Tukey biweight) WV and its Gaussian efficiency. A summary file gives the
            WV it stores: its robust one with ``robust=True``, its classical one otherwise.
        levels : int, optional
            Number of levels J (default :func:`engine.wv.default_levels`); a summary's WV is
            truncated to ``levels`` (it cannot be extended).
        alpha : float
            ``1 - alpha`` intervals of a computed WV.
        fs : float, optional
            Sampling frequency (Hz), default the log's; a summary's WV is relabelled to it.
        progress : callable, optional
            ``progress(j, J)`` as each level of a computed WV is done.

        Returns
        -------
        WaveletVariance
            In the channel's unit (:meth:`unit_of`).

        Raises
        ------
        LoadError
            An unknown channel; a constant channel (no noise to analyse); ``robust`` asked of a
            classical summary (or the classical WV of a robust-only summary); ``levels`` beyond
            a summary's.

        Examples
        --------
        >>> import engine as eg
        >>> log = eg.load_log(eg.demo_path())
        >>> wv = log.wavelet_variance("gyro_x", levels=10)
        >>> wv.n_levels, wv.unit
        (10, 'deg/s')
        """
        name = pick_channel(self.source, self.names, channel)
        where = f"file '{self.source}'"
        if self.is_summary:
            wv = self.wv[name]
            if robust and not wv.robust:
                raise LoadError(
                    f"{where} holds the classical WV of {name} only: robust=True needs the raw log"
                )
            if not robust and wv.robust:
                if wv.classical is None:
                    raise LoadError(f"{where} holds the robust WV of {name} only: pass robust=True")
                wv = wv.classical
            if levels is not None and levels != wv.n_levels:
                if levels > wv.n_levels:
                    raise LoadError(
                        f"levels={levels} is too many: {where} has {wv.n_levels} levels for {name}"
                    )
                wv = wv.truncate(levels)
            return wv if fs is None or wv.fs == fs else wv.with_fs(fs)
        x = self.channels[name]
        if x.size >= 4 and np.ptp(x) == 0:
            raise LoadError(
                f"{where}: channel {name!r} is constant (all {x.size} samples equal "
                f"{x[0]:g}): there is no noise to analyse"
            )
        if self.segments:  # the still parts of a flight: their coefficients pooled
            return pooled_wavelet_variance(
                [x[a:b] for a, b in self.segments],
                fs=self.fs if fs is None else fs,
                levels=levels,
                robust=robust,
                eff=eff,
                alpha=alpha,
                unit=self.unit_of(name),
            )
        return wavelet_variance(
            x,
            fs=self.fs if fs is None else fs,
            levels=levels,
            robust=robust,
            eff=eff,
            alpha=alpha,
            unit=self.unit_of(name),
            progress=progress,
        )

    def __repr__(self) -> str:
        what = "WV summary" if self.is_summary else "log"
        return (
            f"ImuLog({what} '{self.source}': {len(self.names)} channel(s) "
            f"[{', '.join(self.names)}] x {self.n} samples at {self.fs:g} Hz ({self.fs_source}))"
        )


def pick_channel(src: str, names: list[str], channel: str | int) -> str:
    """Resolve ``channel`` (name, index, or digit string) against ``names``."""
    shown = ", ".join(names[:50]) + (", ..." if len(names) > 50 else "")
    if isinstance(channel, str) and channel in names:
        return channel
    if isinstance(channel, str) and channel.strip().lstrip("-").isdigit():
        channel = int(channel)
    if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool):
        if -len(names) <= int(channel) < len(names):
            return names[int(channel)]
        raise LoadError(
            f"file '{src}': channel index {int(channel)} is out of range; the file has "
            f"{len(names)} channel(s) (indices 0..{len(names) - 1}): {shown}"
        )
    raise LoadError(
        f"file '{src}' has no channel {channel!r}; available channels: {shown}. "
        "Pass one of these names or an integer index"
    )


def channel_axis(name: str) -> str:
    """Axis letter of a channel name (``gyro_x`` -> ``x``, ``imu/acc[1]`` -> ``y``), else the
    name itself."""
    n = name.strip().lower()
    m = re.search(r"\[(\d)\]$", n)
    if m and int(m.group(1)) < 3:
        return "xyz"[int(m.group(1))]
    m = re.search(r"(?:^|[^a-z])([xyz])$", n) or re.search(r"([xyz])$", n)
    return m.group(1) if m else name
