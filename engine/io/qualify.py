"""Is this log fit to calibrate from? Checks run before a fit, each finding with its samples.

A static calibration assumes one stationary recording. :func:`qualify_log` looks for what
breaks that assumption and says, per finding, which samples are concerned and what to do:

* **warm-up** (``"warmup"``): the first part of the log has a trend the rest does not have
  (the sensor settling after power-on); offers a start sample (:func:`drop_warmup`).
* **warm-up wander** (``"wander"``): the bias wanders more in the first part of the log than
  in the rest (the variance of the increments of block means, judged on the channel's sensor
  triad); offers a start sample too.
* **shocks** (``"shock"``): short windows with a cluster of large steps (a bump, a knock).
* **motion** (``"motion"``): longer windows whose (clipped) variance departs from the log's.
* **saturation** (``"saturation"``): samples piled up at the extreme values (clipping).
* **quantisation** (``"quantisation"``): the output step and the share of ties (a QN term).
* **periodic disturbance** (``"periodic"``): a line in the spectrum (fans, pumps, mains).
* **slow trend** (``"trend"``): a smooth trend over the whole log, which a thermal ramp (or a
  drift) causes; with a temperature channel :mod:`engine.inference.temperature` separates it.
* **timing** (``"timing"``): gaps, duplicates and jitter of the time stamps, as the loader's
  :func:`engine.io.check_time` found them (``meta["time_report"]``; not checked again here).

Every check is robust to heavy tails (it compares the log with itself) and runs in linear
time: the steps ``d_t = x_{t+1} - x_t`` are scaled by a robust scale; shocks are clusters of
steps beyond 8 robust SDs, improbable under a Poisson count whose rate is estimated from the
share of windows without any (so a heavy but stationary tail raises the rate and stays quiet);
motion is a 5-SD-clipped variance over windows of 2048 samples, more than 8 robust SDs (of
the log-variances across windows) and a factor 1.5 from their median. The false-alarm rates
on clean simulated logs are in ``docs/qualify.md`` (``tests/benchmarks/qualify_mc.py``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .log import ImuLog, channel_axis

__all__ = [
    "Finding",
    "Qualification",
    "qualify_signal",
    "qualify_log",
    "drop_warmup",
    "wander_test",
    "wander_scan",
    "triad_of",
    "KINDS",
]

#: The kinds of finding, in the order they are listed.
KINDS = (
    "warmup",
    "wander",
    "shock",
    "motion",
    "saturation",
    "periodic",
    "trend",
    "quantisation",
    "timing",
)

SHOCK_WINDOW = 128  # samples per window of the shock count
SHOCK_K = 8.0  # a step beyond SHOCK_K robust SDs is an exceedance
MOTION_WINDOW = 2048  # samples per window of the motion variance
MOTION_CLIP = 5.0  # steps clipped at MOTION_CLIP robust SDs
Z_LIMIT = 8.0  # robust z beyond which a window departs
ALPHA = 1e-3  # per-log false-alarm target of the count and spectrum tests (Bonferroni)
_BLOCKS = 256  # block means of the warm-up and trend checks
WANDER_ALPHA = 0.01  # per-log false-alarm target of the wander scan (Bonferroni over the scan)
_MAX_RANGES = 20  # ranges listed per finding


@dataclass(frozen=True)
class Finding:
    """One thing a check found in one channel.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    channel : str
        The channel (``""`` for the whole log, e.g. timing).
    severity : {"warning", "info"}
        ``"warning"``: the fit is likely affected; ``"info"``: worth knowing (quantisation).
    ranges : tuple of (start, stop)
        0-based sample ranges ``[start, stop)`` concerned (at most 20 listed; ``count`` has
        the total).
    message : str
        What was found, one line, with its figures and units.
    action : str
        What to do about it.
    count : int
        Number of ranges found (``len(ranges)`` unless truncated).
    values : dict
        The figures behind the message (e.g. ``{"frequency_hz": 50.0, "ratio": 12.3}``).
    """

    kind: str
    channel: str
    severity: str
    ranges: tuple[tuple[int, int], ...]
    message: str
    action: str
    count: int = 0
    values: dict[str, float] = field(default_factory=dict, compare=False)

    def where(self) -> str:
        """``samples 11,710-11,900`` (with ``+ k more`` when there are several)."""
        if not self.ranges:
            return ""
        a, b = self.ranges[0]
        more = max(self.count, len(self.ranges)) - 1
        return f"samples {a:,}-{b - 1:,}" + (f" (+{more} more)" if more else "")

    def line(self) -> str:
        """The finding as one line: channel, message, samples, action."""
        ch = f"{self.channel}: " if self.channel else ""
        where = self.where()
        return f"{ch}{self.message}" + (f" at {where}" if where else "") + f"; {self.action}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "kind": self.kind,
            "channel": self.channel,
            "severity": self.severity,
            "ranges": [[int(a), int(b)] for a, b in self.ranges],
            "count": int(max(self.count, len(self.ranges))),
            "message": self.message,
            "action": self.action,
            "values": {k: (float(v) if math.isfinite(v) else None) for k, v in self.values.items()},
        }


@dataclass(frozen=True, eq=False)
class Qualification:
    """What :func:`qualify_log` found in a log.

    Attributes
    ----------
    n : int
        Samples per channel.
    fs : float
        Sampling frequency (Hz).
    channels : tuple of str
        The channels checked.
    findings : tuple of Finding
        In the order of :data:`KINDS`, then of the channels.
    dropped : int
        Samples dropped from the start before the fit (:func:`drop_warmup`), 0 if none.
    """

    n: int
    fs: float
    channels: tuple[str, ...]
    findings: tuple[Finding, ...]
    dropped: int = 0

    @property
    def ok(self) -> bool:
        """True when no finding is a warning."""
        return not self.warnings

    @property
    def warnings(self) -> list[Finding]:
        """The findings of severity ``"warning"``."""
        return [f for f in self.findings if f.severity == "warning"]

    def of_kind(self, kind: str) -> list[Finding]:
        """The findings of one kind (:data:`KINDS`)."""
        return [f for f in self.findings if f.kind == kind]

    @property
    def suggested_start(self) -> int:
        """The first sample after every channel's warm-up, of the mean (``"warmup"``) or of the
        bias wander (``"wander"``); 0 without such a finding."""
        return max(
            (
                int(f.values.get("start", 0))
                for f in self.of_kind("warmup") + self.of_kind("wander")
            ),
            default=0,
        )

    def line(self) -> str:
        """One line: what was found, by kind, with the channels and the first samples."""
        dropped = f", first {self.dropped:,} samples dropped" if self.dropped else ""
        if not self.findings:
            return (
                f"log check: no finding in {len(self.channels)} channel(s) of {self.n:,} "
                f"samples{dropped}"
            )
        parts = []
        for kind in KINDS:
            fs = self.of_kind(kind)
            if not fs:
                continue
            chans = ", ".join(dict.fromkeys(f.channel for f in fs if f.channel))
            first = min((f for f in fs if f.ranges), key=lambda f: f.ranges[0][0], default=None)
            where = ""
            if kind in ("warmup", "wander"):
                where = f": start at sample {self.suggested_start:,} (drop_warmup=True)"
            elif kind == "periodic":
                freqs = sorted({round(f.values["frequency_hz"], 2) for f in fs})
                where = " at " + ", ".join(f"{v:g} Hz" for v in freqs[:4])
            elif kind == "quantisation":
                where = ""
            elif first is not None and kind != "trend":
                n_ranges = sum(max(f.count, len(f.ranges)) for f in fs)
                a, b = first.ranges[0]
                where = f" in {n_ranges} range(s), first at samples {a:,}-{b - 1:,}"
            parts.append(f"{kind} ({chans}){where}" if chans else f"{kind}{where}")
        n_warn = len(self.warnings)
        head = f"log check: {n_warn} warning(s)" if n_warn else "log check: no warning"
        return f"{head}{dropped}: " + "; ".join(parts)

    def lines(self) -> list[str]:
        """One line per finding (:meth:`Finding.line`)."""
        return [f.line() for f in self.findings]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: the one-line summary, the suggested start and the findings."""
        return {
            "summary": self.line(),
            "ok": self.ok,
            "n": int(self.n),
            "fs": float(self.fs),
            "channels": list(self.channels),
            "suggested_start": self.suggested_start,
            "dropped": int(self.dropped),
            "findings": [f.to_dict() for f in self.findings],
        }


# --- helpers -----------------------------------------------------------------------------


def _robust_sd(d: np.ndarray) -> float:
    """1.4826 x MAD of ``d``; for a coarsely quantised ``d`` (MAD 0) the mean absolute
    deviation x 1.2533 instead (both equal the SD for Gaussian data)."""
    med = float(np.median(d))
    s = 1.4826 * float(np.median(np.abs(d - med)))
    if s == 0.0:
        s = 1.2533 * float(np.mean(np.abs(d - med)))
    return s


def _runs(mask: np.ndarray, *, join: int = 0) -> list[tuple[int, int]]:
    """``[start, stop)`` runs of True in ``mask``, runs closer than ``join`` merged."""
    if not mask.any():
        return []
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    out: list[tuple[int, int]] = []
    for a, b in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
        if out and a - out[-1][1] <= join:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _poisson_sf(k: np.ndarray, lam: float) -> np.ndarray:
    """``P(X >= k)`` for ``X ~ Poisson(lam)``."""
    from scipy import stats

    return np.asarray(stats.poisson.sf(k - 1, lam), dtype=float)


# --- the checks ---------------------------------------------------------------------------


def _shocks(d: np.ndarray, s: float, channel: str, unit: str) -> list[Finding]:
    """Clusters of steps beyond ``SHOCK_K`` robust SDs within ``SHOCK_WINDOW`` samples."""
    w = SHOCK_WINDOW
    m = d.size // w
    if m < 8:
        return []
    big = np.abs(d) > SHOCK_K * s
    # one spike in x makes two adjacent big steps: a run of L big steps counts L - 1 (at
    # least 1), so that isolated outliers of a heavy tail count once and stay Poisson
    nxt = np.concatenate([big[1:], [False]])
    prv = np.concatenate([[False], big[:-1]])
    events = (big & nxt) | (big & ~prv & ~nxt)
    counts = events[: m * w].reshape(m, w).sum(axis=1)
    p0 = float(np.mean(counts == 0))
    lam = -math.log(p0) if p0 > 0 else math.inf
    if not math.isfinite(lam):
        return []  # exceedances everywhere: nothing departs
    hit = np.flatnonzero(counts > 0)
    if hit.size == 0:
        return []
    p = _poisson_sf(counts[hit], lam) if lam > 0 else np.zeros(hit.size)
    bad = hit[p < ALPHA / m]
    if bad.size == 0:
        return []
    mask = np.zeros(d.size, dtype=bool)
    for k in bad:  # the big steps of the flagged windows
        mask[k * w : (k + 1) * w] |= big[k * w : (k + 1) * w]
    # steps a .. b-1 flagged: the samples they reach, a+1 .. b-1, are the ones off (a spike
    # at s: steps s-1 and s, sample s); a lone step marks the sample it reaches
    ranges = [(a + 1, max(b, a + 2)) for a, b in _runs(mask, join=w)]
    peak = float(np.max(np.abs(d[big]))) / s
    return [
        Finding(
            "shock",
            channel,
            "warning",
            tuple(ranges[:_MAX_RANGES]),
            f"{len(ranges)} burst(s) of steps beyond {SHOCK_K:g} robust SDs "
            f"(largest {peak:.3g} SDs; {lam * d.size / w:.3g} expected isolated ones)",
            "cut these samples out (segments=...) or fit a robust WV (robust=True)",
            len(ranges),
            {"largest_sd": peak, "rate_per_window": lam},
        )
    ]


def _motion(d: np.ndarray, s: float, channel: str) -> list[Finding]:
    """Windows whose clipped step variance departs from the log's (robust z and a factor)."""
    w = MOTION_WINDOW
    m = d.size // w
    if m < 8:
        return []
    c = MOTION_CLIP * s
    v = np.mean(np.minimum(d[: m * w] ** 2, c * c).reshape(m, w), axis=1)
    floor = 1e-12 * c * c
    lv = np.log(np.maximum(v, floor))
    med = float(np.median(lv))
    spread = 1.4826 * float(np.median(np.abs(lv - med)))
    if spread == 0.0:
        return []
    z = (lv - med) / spread
    bad = (np.abs(z) > Z_LIMIT) & (np.abs(lv - med) > math.log(1.5))
    if not bad.any():
        return []
    wins = _runs(bad)
    ranges = [(a * w, min(b * w + 1, d.size + 1)) for a, b in wins]
    worst = float(np.exp(np.max(np.abs(lv[bad] - med))))
    return [
        Finding(
            "motion",
            channel,
            "warning",
            tuple(ranges[:_MAX_RANGES]),
            f"{len(ranges)} stretch(es) of {w}-sample windows whose step variance is up to "
            f"{worst:.3g} times (or 1/{worst:.3g} of) the log's",
            "cut these samples out (segments=...): the sensor moved or the noise changed",
            len(ranges),
            {"worst_ratio": worst},
        )
    ]


def _saturation(x: np.ndarray, channel: str, unit: str) -> list[Finding]:
    """Samples piled up at the maximum or minimum: more at the extreme than next to it."""
    out = []
    for side, ext in (("maximum", np.max(x)), ("minimum", np.min(x))):
        at = x == ext
        k = int(np.count_nonzero(at))
        if k < 3:
            continue
        inner = x[~at]
        if inner.size == 0:
            continue
        nxt = np.max(inner) if side == "maximum" else np.min(inner)
        k_next = int(np.count_nonzero(inner == nxt))
        if k <= k_next:  # a natural tail thins out towards its extreme
            continue
        ranges = _runs(at)
        longest = max(b - a for a, b in ranges)
        if longest < 2 and k < 10:
            continue
        out.append(
            Finding(
                "saturation",
                channel,
                "warning",
                tuple(ranges[:_MAX_RANGES]),
                f"{k} samples ({100 * k / x.size:.3g} %) sit at the {side} {ext:.6g} {unit} "
                f"(longest run {longest}), more than the {k_next} at the next value: clipped",
                "cut the clipped samples out (segments=...) or record with a wider range",
                len(ranges),
                {"value": float(ext), "samples": float(k), "longest_run": float(longest)},
            )
        )
    return out


#: A step below this fraction of the per-sample noise SD is the storage's resolution, not the
#: sensor's: rounding adds less than 1e-5 of the sample variance (``r^2 / 12``), so no QN term.
STORAGE_STEP = 0.01


def _quantisation(d: np.ndarray, s: float, channel: str, unit: str) -> list[Finding]:
    """The output step (every nonzero step an integer multiple of the smallest) and ties."""
    nz = np.abs(d[d != 0])
    if nz.size == 0:
        return []
    q = float(np.min(nz))
    r = nz / q
    if float(np.max(np.abs(r - np.rint(r)))) > 0.02:
        return []
    ties = float(np.mean(d == 0))
    r = q / (s / math.sqrt(2))  # the step over the white-noise SD of a sample
    if r < STORAGE_STEP:
        # the storage's resolution (a float32 column: 9.5e-7 m/s^2 at 1 g): rounding adds
        # r^2 / 12 of the sample variance, nothing a QN term could resolve
        action = (
            f"nothing to do: rounding to this step adds {100 * r * r / 12:.2g} % to the sample "
            "variance, no QN term needed"
        )
    else:
        action = "include QN in the model" + (
            "; the step is coarse: the shortest scales are mostly quantisation" if r > 1 else ""
        )
    return [
        Finding(
            "quantisation",
            channel,
            "info",
            (),
            f"quantised in steps of {q:.6g} {unit} ({100 * ties:.3g} % of consecutive samples "
            f"tie; step = {r:.3g} x the noise SD per sample)",
            action,
            0,
            {"step": q, "ties": ties, "step_over_sd": r},
        )
    ]


def _welch(x: np.ndarray, fs: float, nper: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Welch PSD (one-sided, density): Hann window, 50 % overlap, each segment's line removed;
    segments in chunks so that memory stays bounded. Returns frequencies, PSD, segments."""
    hop = nper // 2
    frames = np.lib.stride_tricks.sliding_window_view(x, nper)[::hop]
    k = frames.shape[0]
    t = np.arange(nper) - (nper - 1) / 2
    win = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(nper) / nper)
    acc = np.zeros(nper // 2 + 1)
    for i in range(0, k, 64):
        fr = frames[i : i + 64]
        fr = fr - fr.mean(axis=1, keepdims=True) - np.outer(fr @ t / float(t @ t), t)
        acc += np.sum(np.abs(np.fft.rfft(fr * win, axis=1)) ** 2, axis=0)
    p = acc / (k * fs * float(win @ win))
    p[1:-1] *= 2
    return np.fft.rfftfreq(nper, 1 / fs), p, k


def _periodic(x: np.ndarray, fs: float, channel: str, unit: str) -> list[Finding]:
    """Lines in the Welch PSD: bins far above the running median of their neighbours."""
    from scipy import ndimage, stats

    n = x.size
    if n < 8192:
        return []
    nper = int(min(16384, 2 ** math.floor(math.log2(n / 32))))
    f, p, k_seg = _welch(x, fs, nper)
    dof = 2 * 0.9 * k_seg  # Hann, 50 % overlap: about 90 % of the independent segments' dof
    # the lowest bins are bent by each segment's line removal: neither tested nor in the floor
    # (a running median over a monotone spectrum is its centre value, edges included)
    lo = 6
    floor = np.empty_like(p)
    floor[lo:] = ndimage.median_filter(p[lo:], size=31, mode="nearest")
    ratio = p[lo:] / np.maximum(floor[lo:], np.finfo(float).tiny)
    thr = max(1.5, float(stats.chi2.isf(ALPHA / ratio.size, dof)) / dof * 1.25)
    over = ratio > thr
    if not over.any():
        return []
    out = []
    df = float(f[1] - f[0])
    for a, b in _runs(over)[:5]:
        k = lo + a + int(np.argmax(ratio[a:b]))
        i0, i1 = max(k - 2, 0), min(k + 3, p.size)
        excess = float(np.sum(np.maximum(p[i0:i1] - floor[i0:i1], 0.0)) * df)
        fk = float(np.sum(f[i0:i1] * p[i0:i1]) / np.sum(p[i0:i1]))
        out.append(
            Finding(
                "periodic",
                channel,
                "warning",
                ((0, n),),
                f"a line at {fk:.4g} Hz, {ratio[k - lo]:.3g} times the noise floor around it "
                f"(amplitude about {math.sqrt(2 * excess):.3g} {unit})",
                "find the source (fan, pump, mains) and switch it off or isolate the sensor; "
                "a fit treats the line as extra noise at its scale",
                1,
                {
                    "frequency_hz": fk,
                    "ratio": float(ratio[k - lo]),
                    "amplitude": math.sqrt(2 * excess),
                },
            )
        )
    return out


def _block_means(x: np.ndarray, k: int) -> tuple[np.ndarray, int]:
    b = x.size // k
    return x[: b * k].reshape(k, b).mean(axis=1), b


def _warmup(x: np.ndarray, channel: str, unit: str) -> list[Finding]:
    """A trend in the first 1/64 .. 1/8 of the log far steeper than in the segments after."""
    if x.size < _BLOCKS * 8:
        return []
    m, b = _block_means(x - float(np.median(x)), _BLOCKS)
    best = None
    for n_seg in (64, 32, 16, 8):
        ln = _BLOCKS // n_seg
        seg = m.reshape(n_seg, ln)
        t = np.arange(ln) - (ln - 1) / 2
        slopes = seg @ t / float(t @ t)
        others = slopes[1:]
        centre = float(np.median(others))
        spread = math.sqrt(float(np.mean((others - centre) ** 2)))
        if spread == 0:
            continue
        z = abs(float(slopes[0]) - centre) / spread
        if z > 10 and (best is None or ln > best[1]):
            best = (z, ln, float(slopes[0]))
    if best is None:
        return []
    z, ln, slope = best
    ref_lo, ref_hi = min(2 * ln, _BLOCKS // 2), min(4 * ln, _BLOCKS)
    level = float(np.median(m[ref_lo:ref_hi]))
    noise = 1.4826 * float(np.median(np.abs(np.diff(m[ref_lo:]))))
    off = np.flatnonzero(np.abs(m[:ref_lo] - level) > 3 * max(noise, 1e-300))
    start = int((off[-1] + 1) * b) if off.size else ln * b
    amp = float(m[0] - level)
    return [
        Finding(
            "warmup",
            channel,
            "warning",
            ((0, start),),
            f"warm-up: the first {start:,} samples settle by {amp:+.3g} {unit} (a trend "
            f"{z:.3g} times steeper than in the rest of the log)",
            f"drop them (drop_warmup=True starts at sample {start:,})",
            1,
            {"start": float(start), "amplitude": amp, "z": z},
        )
    ]


def wander_scan(n: int, fs: float) -> list[tuple[int, int]]:
    """The (block, blocks) pairs the wander check scans for a log of ``n`` samples at ``fs`` Hz.

    The early part is ``T = n 2^(-k/2)`` samples, ``k = 4..10`` (a quarter to a 32nd of the
    log, in half-octaves), cut into ``L`` = 8, 16 or 32 blocks of ``T // L`` samples; a block
    is at least 32 samples and 1 s (the bias wander is a matter of seconds and longer).
    Every choice follows from the log's length and rate; the scan's multiple testing is
    accounted for by Bonferroni over its length (:func:`wander_test`).
    """
    shortest = max(32, math.ceil(fs))
    out = []
    for k in range(4, 11):
        early = int(n * 2.0 ** (-k / 2))
        for blocks in (8, 16, 32):
            b = early // blocks
            if b >= shortest:
                out.append((b, blocks))
    return out


def _increments(c: np.ndarray, b: int) -> np.ndarray:
    """Differences of consecutive means of blocks of ``b`` samples, from the cumulative sum
    ``c`` (``c[0] = 0``) of a de-meaned series."""
    k = (c.size - 1) // b
    return np.diff(np.diff(c[: k * b + 1 : b]) / b)


def wander_test(xs: list[np.ndarray], fs: float) -> tuple[float, int, int, int, list[float]] | None:
    """Does the bias wander more in the first part of the log? The scan of the wander check.

    Each series is first clipped at ``SHOCK_K`` robust SDs about its median (so that heavy
    tails, spikes and bursts leave the block means alone). For
    each (block ``b``, blocks ``L``) of :func:`wander_scan` and each series, the increments
    ``e_k`` of consecutive ``b``-sample means, less their mean over the rest (a drift), give
    ``R = mean(e_k^2, k < L - 1) / var(e_k, k >= L)``: the first ``L`` blocks' wander over the
    rest's. Under a stationary model (WN, QN, RW, DR, GM, ...) ``R`` is about F-distributed;
    the increments are correlated (-1/2 at lag 1 for white noise, 1/4 for a random walk), so
    each degree of freedom count is divided by ``1 + 2 (rho_1^2 + rho_2^2)``, the rest's
    autocorrelations (Satterthwaite). The series' one-sided p-values are pooled by Stouffer's
    sum of normal scores, and the smallest over the scan is multiplied by the scan's length
    (Bonferroni). The false-alarm rate on clean simulated logs is in ``docs/qualify.md``
    (``tests/benchmarks/wander_mc.py``).

    Parameters
    ----------
    xs : list of ndarray
        The series judged together (a sensor triad), each of at least ``n`` samples; the first
        ``n = min(len)`` are used.
    fs : float
        Sampling frequency (Hz).

    Returns
    -------
    (p, b, L, start, ratios) or None
        The scan-adjusted p-value (at most 1), the block (samples) and count of the most
        significant early part, the first sample after the excess wander (a variance
        change point of the increments at that block size, in the first quarter of the log)
        and each series' variance ratio before that point against after it; None when the
        log is too short for the scan.
    """
    from scipy import stats

    n = min(int(x.size) for x in xs)
    scan = wander_scan(n, fs)
    if not scan:
        return None
    cs = []
    for x in xs:
        # the samples clipped at SHOCK_K robust SDs about their median: a heavy tail, a spike
        # or a burst does not move the block means, and the wander (far smaller than the
        # spread of the samples in a static log) is kept
        y = np.asarray(x[:n], dtype=float)
        med = float(np.median(y))
        s = _robust_sd(y)
        if s == 0.0:
            return None
        y = np.clip(y, med - SHOCK_K * s, med + SHOCK_K * s)
        cs.append(np.concatenate([[0.0], np.cumsum(y - float(np.mean(y)))]))
    best: tuple[float, int, int] | None = None
    for b, blocks in scan:
        z = 0.0
        for c in cs:
            e = _increments(c, b)
            rest = e[blocks:]
            e = e - float(np.mean(rest))
            er = e[blocks:]
            ss = float(er @ er)
            if ss <= 0.0:
                return None
            rho2 = sum((float(er[k:] @ er[:-k]) / ss) ** 2 for k in (1, 2))
            f = 1.0 + 2.0 * rho2
            early = e[: blocks - 1]
            # the early deviations are from the rest's mean: their variance is (1 + 1/n_r)
            ratio = float(early @ early) / early.size / (ss / (er.size - 1) * (1 + 1 / er.size))
            p = float(stats.f.sf(ratio, early.size / f, (er.size - 1) / f))
            z += float(stats.norm.isf(min(max(p, 1e-300), 1.0)))
        p_pool = float(stats.norm.sf(z / math.sqrt(len(cs))))
        if best is None or p_pool < best[0]:
            best = (p_pool, b, blocks)
    assert best is not None
    p_min, b, blocks = best
    # where the excess ends: the split of the increments at this block size that maximises the
    # Gaussian likelihood of two variances (pooled over the series), in the first quarter
    es = []
    for c in cs:
        e = _increments(c, b)
        es.append(e - float(np.mean(e[blocks:])))
    m = es[0].size
    ks = np.arange(2, max(3, m // 4 + 1))
    ll = np.zeros(ks.size)
    for e in es:
        c2 = np.concatenate([[0.0], np.cumsum(e * e)])
        v1 = c2[ks] / ks
        v2 = (c2[-1] - c2[ks]) / (m - ks)
        ll -= ks * np.log(np.maximum(v1, 1e-300)) + (m - ks) * np.log(np.maximum(v2, 1e-300))
    k = int(ks[int(np.argmax(ll))])
    start = (k + 1) * b  # increment k - 1 ends with block k
    ratios = [float(np.mean(e[:k] ** 2) / np.mean(e[k:] ** 2)) for e in es]
    return min(1.0, p_min * len(scan)), b, blocks, start, ratios


def _wander(xs: dict[str, np.ndarray], fs: float, report: tuple[str, ...]) -> list[Finding]:
    """The wander check on one sensor triad (``xs``: its channels), findings for ``report``."""
    got = wander_test(list(xs.values()), fs)
    if got is None:
        return []
    p, b, blocks, start, ratios = got
    if p >= WANDER_ALPHA:
        return []
    names = list(xs)
    pooled = f" ({', '.join(names)} pooled)" if len(names) > 1 else ""
    out = []
    for ch, r in zip(names, ratios, strict=True):
        if ch not in report:
            continue
        out.append(
            Finding(
                "wander",
                ch,
                "warning",
                ((0, start),),
                f"warm-up wander: the bias wanders more in the first {start:,} samples "
                f"({start / fs:.4g} s): the variance of the steps of {b / fs:.3g} s means is "
                f"{r:.3g} times the rest's{pooled} (p = {p:.2g} over the scan)",
                f"drop them (drop_warmup=True starts at sample {start:,}) or start the "
                "recording later after turn-on",
                1,
                {
                    "start": float(start),
                    "ratio": r,
                    "p": p,
                    "block_s": b / fs,
                    "early_s": b * blocks / fs,
                },
            )
        )
    return out


def trend_test(x: np.ndarray, *, blocks: int = 64) -> tuple[float, float, float]:
    """Share of the variance of ``blocks`` block means a quadratic explains, its range over
    the log, and that range over the SD of the block-to-block steps of the residual.

    A random walk's block means wander (range about ``sqrt(blocks)`` steps); a thermal ramp
    or a drift gives a smooth trend whose range is many steps.
    """
    m, _ = _block_means(np.asarray(x, dtype=float) - float(np.median(x)), blocks)
    t = np.linspace(-1, 1, blocks)
    coef = np.polyfit(t, m, 2)
    fit = np.polyval(coef, t)
    resid = m - fit
    tot = float(np.sum((m - m.mean()) ** 2))
    r2 = 1 - float(np.sum(resid**2)) / tot if tot > 0 else 0.0
    rng = float(np.ptp(fit))
    step = float(np.std(np.diff(resid))) / math.sqrt(2)
    return r2, rng, rng / step if step > 0 else math.inf


def _trend(x: np.ndarray, channel: str, unit: str) -> list[Finding]:
    if x.size < _BLOCKS * 8:
        return []
    r2, rng, steps = trend_test(x)
    if not (r2 > 0.95 and steps > 40):
        return []
    return [
        Finding(
            "trend",
            channel,
            "warning",
            ((0, x.size),),
            f"a slow trend of {rng:.3g} {unit} over the log ({100 * r2:.3g} % of the block "
            f"means' variance, {steps:.3g} times their step noise): a thermal ramp or a drift",
            "log the temperature and compensate it (temperature=...), or keep DR in the model",
            1,
            {"range": rng, "r2": r2, "steps": steps},
        )
    ]


def _timing(report: dict[str, Any] | None) -> list[Finding]:
    """The loader's time-column report as a finding (gaps, duplicates, reversals, jitter)."""
    if not report:
        return []
    counts = {k: int(v) for k, v in (report.get("counts") or {}).items() if v}
    jitter = report.get("jitter") or 0.0
    if not counts and jitter <= 0.01:
        return []
    ranges = tuple(
        (max(int(e["index"]) - 1, 0), int(e["index"]) + 1) for e in report.get("events", [])
    )
    found = ", ".join(f"{v} {k}(s)" for k, v in counts.items())
    msg = (
        f"time column '{report.get('column', 'time')}': "
        + (found or "no gap")
        + (f", jitter {100 * jitter:.3g} % of the step" if jitter > 0.01 else "")
    )
    a, b = report.get("longest") or (0, 0)
    return [
        Finding(
            "timing",
            "",
            "warning" if counts else "info",
            ranges[:_MAX_RANGES],
            msg,
            f"the longest clean segment is samples {a:,}-{b - 1:,} (segment='longest')"
            if counts
            else "the samples are treated as uniform",
            len(ranges),
            {"jitter": float(jitter)},
        )
    ]


# --- entry points -------------------------------------------------------------------------


def qualify_signal(
    x: np.ndarray, fs: float, *, channel: str = "x", unit: str = "", wander: bool = True
) -> list[Finding]:
    """Run every per-channel check on one signal.

    Parameters
    ----------
    x : ndarray, shape (n,)
        The samples.
    fs : float
        Sampling frequency (Hz).
    channel, unit : str
        Names used in the messages.
    wander : bool
        Run the warm-up wander check on this signal alone (:func:`qualify_log` runs it on the
        channel's sensor triad instead).

    Returns
    -------
    list of Finding
        In the order of :data:`KINDS`; empty for a clean log. NaN samples and constant
        signals give no finding (the loader refuses them).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(1).normal(size=100_000)
    >>> x[50_000:50_010] += 30.0
    >>> [(f.kind, f.ranges[0]) for f in qualify_signal(x, 100.0)]
    [('shock', (50000, 50010))]
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 64 or not np.all(np.isfinite(x)):
        return []
    d = np.diff(x)
    s = _robust_sd(d)
    if s == 0.0:
        return []
    dc = d - np.median(d)  # the steps about their centre (a drift's step is not a shock)
    found = (
        _warmup(x, channel, unit)
        + (_wander({channel: x}, fs, (channel,)) if wander else [])
        + _shocks(dc, s, channel, unit)
        + _motion(dc, s, channel)
        + _saturation(x, channel, unit)
        + _periodic(x, fs, channel, unit)
        + _trend(x, channel, unit)
        + _quantisation(d, s, channel, unit)
    )
    return found


def triad_of(log: ImuLog, channel: str) -> list[str]:
    """The channels of ``log`` in the sensor triad of ``channel``: the same name but for the
    axis letter at its end (``gyro_x``, ``gyro_y``, ``gyro_z``) and the same unit; the channel
    alone when its name ends in no axis letter."""
    ax = channel_axis(channel)
    if ax not in ("x", "y", "z") or not channel.lower().endswith(ax):
        return [channel]
    stem, unit = channel[:-1], log.unit_of(channel)
    return [
        c
        for c in log.names
        if c[:-1] == stem and c[-1:].lower() in "xyz" and log.unit_of(c) == unit
    ]


def qualify_log(log: ImuLog, channels: list[str] | None = None) -> Qualification:
    """Check a loaded log before a fit: :func:`qualify_signal` per channel, the warm-up
    wander per sensor triad (:func:`triad_of`: every channel of the log in the triad of a
    channel checked is pooled, so that one channel gets the verdict of its triad), and the
    loader's time-column report.

    Parameters
    ----------
    log : ImuLog
        A raw log (a WV summary has no samples: no finding but its time report).
    channels : list of str, optional
        Channels to check (default: all).

    Returns
    -------
    Qualification
        Findings in the order of :data:`KINDS`; :meth:`Qualification.line` says it in one line.
    """
    names = tuple(channels) if channels else tuple(log.names)
    found: list[Finding] = []
    if not log.is_summary:
        for ch in names:
            found += qualify_signal(
                log.channels[ch], log.fs, channel=ch, unit=log.unit_of(ch), wander=False
            )
        for triad in dict.fromkeys(tuple(triad_of(log, ch)) for ch in names):
            xs = {c: log.channels[c] for c in triad}
            if all(np.all(np.isfinite(x)) and np.ptp(x) > 0 for x in xs.values()):
                found += _wander(xs, log.fs, names)
        # a wander that ends within a mean transient's cut adds nothing to it
        cut = max((int(f.values["start"]) for f in found if f.kind == "warmup"), default=0)
        found = [f for f in found if f.kind != "wander" or f.values["start"] > cut]
    found += _timing(log.meta.get("time_report"))
    order = {k: i for i, k in enumerate(KINDS)}
    found.sort(key=lambda f: order[f.kind])
    return Qualification(
        log.n, float(log.fs), names, tuple(found), int(log.meta.get("dropped_warmup", 0))
    )


def drop_warmup(log: ImuLog, start: int) -> ImuLog:
    """The log without its first ``start`` samples (channels, auxiliary channels, segments).

    Parameters
    ----------
    log : ImuLog
        A raw log.
    start : int
        First sample kept (:attr:`Qualification.suggested_start`); 0 returns ``log``.

    Returns
    -------
    ImuLog
        A new log; ``meta["dropped_warmup"]`` holds ``start`` and ``meta["notes"]`` says so.
    """
    if start <= 0 or log.is_summary:
        return log
    if start >= log.n - 64:
        raise ValueError(f"start={start} leaves fewer than 64 of the log's {log.n} samples")
    segs = tuple(
        (max(a - start, 0), b - start) for a, b in log.segments if b - start > max(a - start, 0)
    )
    meta = dict(log.meta)
    meta["dropped_warmup"] = int(start) + int(log.meta.get("dropped_warmup", 0))
    meta["notes"] = [
        *log.meta.get("notes", []),
        f"first {start} samples ({start / log.fs:.4g} s) dropped as warm-up",
    ]
    return dataclasses.replace(
        log,
        channels={k: v[start:] for k, v in log.channels.items()},
        aux={k: v[start:] for k, v in log.aux.items()},
        segments=segs,
        meta=meta,
    )
