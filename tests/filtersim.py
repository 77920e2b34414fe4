"""A small Kalman filter that proves exported noise numbers in a filter.

One axis, two states: the integral of the sensor's output (an angle for a gyro, a velocity for an
accelerometer) and the sensor's bias. The filter propagates at the sensor rate ``fs`` with the
measured rate, and an absolute fix of the integral (known noise ``fix_sigma``) arrives every
``t_fix_s`` seconds. The filter knows the sensor noise only through two numbers, the ones a
filter file carries: the white-noise density ``N`` and the bias random-walk density ``K``
(continuous time, docs/conventions.md: ``N = sqrt(sigma2 / fs)``, ``K = sqrt(gamma2 * fs)``).

Truth. The platform is static (true rate 0, true integral 0), so the filter's estimate *is* its
error; the filter is linear, so the error does not depend on the trajectory. The sensor error
is simulated from a full GMWM model (``Model.simulate``'s processes, each drawn separately):
the terms that are white at the filter step (WN, QN, AR1/GM with a correlation time below one
step) are the measurement noise; the others (RW, DR, AR1/GM of one step or slower) are the true
bias, which the bias state's error is measured against. The angle error does not depend on this
split; the two-state NEES does (see :func:`split_truth`).

Discretisation. With the per-sample model of docs/conventions.md (WN of variance ``sigma2``
per sample, RW of increment variance ``gamma2``), ``x_{k+1} = F x_k + w_k`` with
``F = [[1, -dt], [0, 1]]`` and ``Q = diag(sigma2 dt^2, gamma2) = diag(N^2 dt, K^2 dt)`` is
exact: when the truth is that WN + RW and the filter has its numbers, the filter's covariance
is the error's covariance.

Speed. The covariance does not depend on the data (linear, time-invariant, fixed fix times), so
it is computed once per step in closed form between fixes; the M runs' errors are a batch
(``(runs, steps)`` arrays, cumulative sums between fixes). 100 runs of 20 min at 100 Hz
(120,000 steps) take a few seconds.

Consistency (Bar-Shalom, Li, Kirubarajan 2001, ch. 5.4): at each step the NEES ``e' P^-1 e``
averaged over the M runs is, for a consistent n-state filter, ``chi2_{nM} / M``; it lies inside
``[chi2_{nM}(0.025), chi2_{nM}(0.975)] / M`` with probability 0.95 at every step. Steps are
correlated in time, so the fraction of steps inside the band has expectation 0.95 but not a
binomial spread over steps; tests take its spread from independent groups of runs.

The headline metric is the NEES of the integral (angle or velocity) alone, n = 1: it needs no
definition of the "true bias" and is what a user of the filter sees. The two-state NEES
(``Consistency.mean_nees_state``) is exact only when the truth is itself WN + RW; with a GM in
the truth it depends on which terms one calls bias (a 0.3 s GM is neither the filter's white
noise nor its random walk), so it is kept for the sanity checks, not for the table.

Case (b), the projected and bounded numbers, comes from the engine's projection
(``engine.formats.projection.project``; :func:`projected_noise`).
:func:`local_bound`, a minimal PSD bound written before the engine had one, is kept as an
independent reference (tested as a PSD bound; not used for case (b)).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

import engine as eg
from engine.formats.projection import project

__all__ = [
    "FilterNoise",
    "Consistency",
    "plain_wn_rw",
    "folk_inflation",
    "local_bound",
    "projected_noise",
    "FilterCases",
    "filter_cases",
    "split_truth",
    "bias_prior_var",
    "nees_band",
    "block_fraction",
    "filter_covariance",
    "run_monte_carlo",
]


# ------------------------------------------------------------------------------------------
# the numbers a filter is given
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FilterNoise:
    """The two noise numbers of a WN + bias-RW filter, in continuous time.

    Parameters
    ----------
    N : float
        White-noise density [u/sqrt(Hz)] (u: the sensor's unit, e.g. deg/s).
    K : float
        Bias random-walk density [u/s/sqrt(Hz)] = [u/sqrt(s)].
    label : str
        What these numbers are (for tables).
    """

    N: float
    K: float
    label: str = ""

    def __post_init__(self) -> None:
        for name in ("N", "K"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"FilterNoise.{name} must be finite and >= 0, got {v!r}")

    @classmethod
    def from_per_sample(
        cls, sigma2: float, gamma2: float, fs: float, label: str = ""
    ) -> FilterNoise:
        """From per-sample WN variance ``sigma2`` and RW increment variance ``gamma2`` at ``fs``."""
        return cls(math.sqrt(sigma2 / fs), math.sqrt(gamma2 * fs), label)

    def sigma2(self, fs: float) -> float:
        """Per-sample WN variance at ``fs`` (``N^2 fs``)."""
        return self.N**2 * fs

    def gamma2(self, fs: float) -> float:
        """Per-sample RW increment variance at ``fs`` (``K^2 / fs``)."""
        return self.K**2 / fs

    def scaled(self, factor: float, label: str = "") -> FilterNoise:
        """Both densities multiplied by ``factor`` (variances by ``factor^2``)."""
        return FilterNoise(self.N * factor, self.K * factor, label or self.label)

    def factors_over(self, ref: FilterNoise) -> tuple[float, float]:
        """``(N / ref.N, K / ref.K)``: the inflation these numbers imply over ``ref``."""
        return (
            self.N / ref.N if ref.N > 0 else math.inf,
            self.K / ref.K if ref.K > 0 else math.inf,
        )


def _terms(model: eg.Model, code: str) -> list[eg.Process]:
    return [p for p in model.processes if p.code == code]


def plain_wn_rw(model: eg.Model, fs: float, label: str = "plain WN+RW") -> FilterNoise:
    """Case (a): the plain conversion of a fit's WN and RW terms (other terms ignored).

    ``N = sqrt(sigma2 / fs)``, ``K = sqrt(gamma2 * fs)`` (docs/conventions.md), what the
    Kalibr-style exports write; a missing term counts as 0.
    """
    s2 = sum(float(p.sigma2) for p in _terms(model, "WN"))
    g2 = sum(float(p.gamma2) for p in _terms(model, "RW"))
    return FilterNoise.from_per_sample(s2, g2, fs, label)


def folk_inflation(noise: FilterNoise, factor: float = 10.0) -> FilterNoise:
    """Case (c): the folk practice, both densities multiplied by ``factor`` (10 by default)."""
    return noise.scaled(factor, f"folk {factor:g}x")


# ------------------------------------------------------------------------------------------
# a minimal local PSD bound (the reference written before the engine's projection)
# ------------------------------------------------------------------------------------------
def _ar1_form(p: eg.Process, fs: float) -> tuple[float, float]:
    """``(phi, stationary variance)`` of an AR1 or GM term."""
    if p.code == "GM":
        return math.exp(-float(p.beta) / fs), float(p.sigma2_gm)
    phi = float(p.phi)
    return phi, float(p.sigma2) / (1 - phi * phi)


def _is_white_at_step(p: eg.Process, fs: float) -> bool:
    """WN and QN, and an AR1/GM whose correlation time is below one sample (phi < e^-1)."""
    if p.code in ("WN", "QN"):
        return True
    if p.code in ("AR1", "GM"):
        return _ar1_form(p, fs)[0] < math.exp(-1.0)
    return False


def local_bound(
    model: eg.Model,
    fs: float,
    horizon_s: float,
    label: str = "local PSD bound",
    grid: int = 21,
) -> tuple[FilterNoise, dict[str, float]]:
    """A reference WN + RW bound, independent of the engine's projection: numbers whose
    spectrum is at least the fitted model's at every frequency, with the least geometric-mean
    WV inflation.

    The rule (per-sample, discrete PSDs at ``fs``, ``c = cos(omega)``):

    * WN adds its ``sigma2``; RW its ``gamma2``.
    * QN ``sqrt(q2)(U_t - U_{t-1})`` has PSD ``q2 (2 - 2c) <= 4 q2``: bounded by WN ``4 q2``.
    * An AR1 (``phi >= 0``, stationary variance ``v``) has PSD
      ``v (1 - phi^2) / (1 + phi^2 - 2 phi c)``. It is bounded by WN of variance
      ``W = v (1 + phi) / (1 - phi)`` (its value at DC, so no smaller WN bounds it) and by RW of
      increment variance ``R = 4 v (1 - phi) / (1 + phi)`` (its value at Nyquist times
      ``2 - 2c``, so no smaller RW bounds it), and by every mix ``a W`` + ``(1 - a) R``,
      ``0 <= a <= 1`` (the inequality is linear in ``c``; check at ``c = +-1``).
    * An AR1/GM faster than one sample takes ``a = 1`` (white at the filter step); for each slower
      one ``a`` is chosen on a grid to minimise the mean over the dyadic scales
      ``2 .. horizon`` of ``log(bound's Haar WV / model's)`` (the geometric-mean inflation; a
      PSD bound implies the WV bound, so the ratio is >= 1 at every scale). The largest ratio
      is not the criterion: it sits at the shortest scale, where a sub-sample GM's WV is below
      its white-noise equivalent whatever ``a`` is, and it would let that scale choose.
    * DR is not bounded by WN + RW over an unlimited horizon; it is refused.

    Parameters
    ----------
    model : Model
        A fitted model (all values set).
    fs : float
        Sampling (= filter) rate [Hz].
    horizon_s : float
        Longest scale of the criterion [s].
    label : str
        Label of the returned numbers.
    grid : int
        Number of mix values ``a`` tried per slow AR1/GM term.

    Returns
    -------
    FilterNoise, dict
        The bound, and ``{"mean_wv_ratio", "max_wv_ratio", "binding_tau_s"}`` (the
        geometric-mean and the largest WV inflation over the band, and the scale of the
        largest).
    """
    s2 = 0.0
    g2 = 0.0
    slow: list[tuple[float, float]] = []
    for p in model.processes:
        if p.code == "WN":
            s2 += float(p.sigma2)
        elif p.code == "RW":
            g2 += float(p.gamma2)
        elif p.code == "QN":
            s2 += 4.0 * float(p.q2)
        elif p.code in ("AR1", "GM"):
            phi, v = _ar1_form(p, fs)
            if phi < 0:
                # a negative phi: PSD largest at Nyquist, v (1 - phi) / (1 + phi); WN bounds it
                s2 += v * (1 - phi) / (1 + phi)
                continue
            w, r = v * (1 + phi) / (1 - phi), 4.0 * v * (1 - phi) / (1 + phi)
            if _is_white_at_step(p, fs):
                s2 += w
            else:
                slow.append((w, r))
        else:
            raise ValueError(
                f"local_bound: no WN + RW bound for a {p.code} term over an unlimited horizon; "
                "fit a model without it or bound it by hand"
            )
    levels = int(math.floor(math.log2(max(horizon_s * fs, 2.0))))
    tau = 2.0 ** np.arange(1, levels + 1)
    target = model.wv(tau, fs)
    basis_wn, basis_rw = 1.0 / tau, (tau**2 + 2.0) / (12.0 * tau)
    best: tuple[float, float, float, float] | None = None
    for mix in itertools.product(np.linspace(0.0, 1.0, grid), repeat=len(slow)):
        sb = s2 + sum(a * w for a, (w, _) in zip(mix, slow, strict=True))
        gb = g2 + sum((1 - a) * r for a, (_, r) in zip(mix, slow, strict=True))
        ratio = (sb * basis_wn + gb * basis_rw) / target
        score = float(np.mean(np.log(ratio)))
        if best is None or score < best[0]:
            best = (score, sb, gb, ratio)
    assert best is not None
    score, sb, gb, ratio = best
    j = int(np.argmax(ratio))
    noise = FilterNoise.from_per_sample(sb, gb, fs, label)
    return noise, {
        "mean_wv_ratio": math.exp(score),
        "max_wv_ratio": float(ratio[j]),
        "binding_tau_s": float(tau[j] / fs),
    }


def projected_noise(
    fit: eg.GMWMResult, horizon_s: float | None = None
) -> tuple[FilterNoise, dict[str, float]]:
    """Case (b): the fit projected onto WN + RW and over-bounded, in the log's unit.

    The engine's ``project(fit, "WN+RW", bound=True)``; ``horizon_s`` defaults to the log
    length.

    Returns
    -------
    FilterNoise, dict
        The numbers and what bound them (``binding_tau_s`` per parameter).
    """
    fs = float(fit.fs)
    hz = fit.wv.n / fs if horizon_s is None else float(horizon_s)
    # unit "": the values stay in the log's own unit, the filter's unit
    proj = project(fit, "WN+RW", horizon_s=hz, bound=True, unit="", ci=None)
    noise = FilterNoise(proj.value("N"), proj.value("K"), "(b) engine projection")
    info = {f"{k}_binding_tau_s": p.binding_tau_s for k, p in proj.params.items()}
    return noise, info


@dataclass
class FilterCases:
    """One channel's truth and the filter numbers of the export cases.

    ``truth`` is the full fit (the simulated sensor); ``cases`` maps a key to the numbers:
    ``"a"`` the plain conversion of the ``WN+RW`` fit (what the Kalibr export writes), ``"b"``
    the full fit projected and bounded (:func:`projected_noise`), ``"c"`` the folk 10x of
    ``"a"``, ``"a0"`` the plain conversion of the full fit's own WN and RW terms.
    """

    channel: str
    fs: float
    truth_fit: eg.GMWMResult
    plain_fit: eg.GMWMResult
    cases: dict[str, FilterNoise]
    bound_info: dict[str, float]

    @property
    def truth(self) -> eg.Model:
        """The simulated sensor model (the full fit)."""
        return self.truth_fit.model


def filter_cases(
    x: np.ndarray, fs: float, channel: str = "", model: str = "2*GM+WN+RW"
) -> FilterCases:
    """Fit ``model`` and ``WN+RW`` to one channel ``x`` (log units) and build the cases."""
    wv = eg.wavelet_variance(x, fs=fs)
    full = eg.fit_gmwm(wv, model)
    wnrw = eg.fit_gmwm(wv, "WN+RW")
    a = plain_wn_rw(wnrw.model, fs, "(a) plain WN+RW")
    b, info = projected_noise(full)
    return FilterCases(
        channel=channel,
        fs=fs,
        truth_fit=full,
        plain_fit=wnrw,
        cases={
            "a": a,
            "b": b,
            "c": folk_inflation(a, 10.0).scaled(1.0, "(c) folk 10x"),
            "a0": plain_wn_rw(full.model, fs, f"(a0) WN, RW of {model}"),
        },
        bound_info=info,
    )


# ------------------------------------------------------------------------------------------
# truth
# ------------------------------------------------------------------------------------------
def split_truth(model: eg.Model, fs: float) -> tuple[list[eg.Process], list[eg.Process]]:
    """The model's terms split into (white at the filter step, bias).

    White: WN, QN, AR1/GM with a correlation time below one sample. Bias: everything else (RW,
    DR, AR1/GM of one sample or slower). The bias terms' sum is the truth of the bias state.
    """
    white = [p for p in model.processes if _is_white_at_step(p, fs)]
    bias = [p for p in model.processes if not _is_white_at_step(p, fs)]
    return white, bias


def bias_prior_var(model: eg.Model, fs: float) -> float:
    """Variance of the true bias at the first sample: the filter's initial bias variance.

    RW contributes its first increment ``gamma2`` (the simulated walk starts at one step), an
    AR1/GM its stationary variance, DR its first value ``omega^2`` (as if random).
    """
    total = 0.0
    for p in split_truth(model, fs)[1]:
        if p.code == "RW":
            total += float(p.gamma2)
        elif p.code == "DR":
            total += float(p.omega) ** 2
        else:
            total += _ar1_form(p, fs)[1]
    return total


# ------------------------------------------------------------------------------------------
# Monte Carlo
# ------------------------------------------------------------------------------------------
def nees_band(n_states: int, runs: int, level: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the run-averaged NEES of a consistent filter: ``chi2_{nM} / M``."""
    a = (1.0 - level) / 2.0
    dof = n_states * runs
    return float(chi2.ppf(a, dof) / runs), float(chi2.ppf(1.0 - a, dof) / runs)


def block_fraction(flags: np.ndarray, block: int) -> tuple[float, float, int]:
    """The fraction of epochs flagged and its standard error from the spread over blocks.

    ``flags`` (bool, epochs ``0 .. n``) is cut into consecutive blocks of ``block`` epochs
    after epoch 0 (one block per fix interval; an incomplete last block is dropped). Within a
    fix interval the epochs are strongly correlated (the error grows from the fix), between
    intervals the filter's reset makes them nearly independent, so the fraction is the mean of
    ``L`` nearly independent block fractions: its standard error is their standard deviation
    over ``sqrt(L)``. With ``L`` = 12 blocks (20 min, fixes every 100 s) and a true fraction of
    2.5 % it is about 4.5 percentage points; with ``L`` = 100 about 1.5.

    Returns
    -------
    fraction, standard_error, blocks : float, float, int
    """
    f = np.asarray(flags, bool)[1:]
    nb = f.size // int(block)
    if nb < 2:
        raise ValueError(f"block_fraction: {f.size} epochs hold fewer than two blocks of {block}")
    per = f[: nb * block].reshape(nb, block).mean(axis=1)
    return float(per.mean()), float(per.std(ddof=1) / math.sqrt(nb)), nb


@dataclass
class Consistency:
    """Consistency of a filter over ``runs`` Monte Carlo runs (``steps + 1`` epochs each).

    ``nees`` is the run-averaged NEES of the integral alone (n = 1) per epoch, ``nees_state``
    the two-state NEES; ``band``/``band_state`` their 95 % bands. ``run_mean_nees`` (integral
    NEES) and ``run_in_2sigma`` are per run (independent across runs); ``group_nees`` is the
    integral NEES summed over each group of runs (``group_runs`` runs each), for
    replicate-based spreads.
    """

    runs: int
    steps: int
    fs: float
    t_fix_s: float
    nees: np.ndarray
    nees_state: np.ndarray
    band: tuple[float, float]
    band_state: tuple[float, float]
    run_mean_nees: np.ndarray
    run_in_2sigma: np.ndarray
    group_nees: np.ndarray
    group_runs: np.ndarray

    @property
    def mean_nees(self) -> float:
        """Time-and-run average of the integral's NEES (1 when consistent)."""
        return float(self.nees.mean())

    @property
    def mean_nees_state(self) -> float:
        """Time-and-run average of the two-state NEES, divided by 2 (1 when consistent)."""
        return float(self.nees_state.mean() / 2.0)

    def fractions(self, state: bool = False) -> tuple[float, float, float]:
        """Fractions of epochs with the run-averaged NEES (below, inside, above) its band."""
        x, (lo, hi) = (self.nees_state, self.band_state) if state else (self.nees, self.band)
        below, above = float(np.mean(x < lo)), float(np.mean(x > hi))
        return below, 1.0 - below - above, above

    def above_with_error(self) -> tuple[float, float, int]:
        """Fraction of epochs above the band, per fix interval (:func:`block_fraction`):
        ``(fraction, standard error, fix intervals)``."""
        m = int(round(self.t_fix_s * self.fs))
        return block_fraction(self.nees > self.band[1], m)

    @property
    def in_2sigma(self) -> float:
        """Fraction of (run, epoch) pairs with the integral's error inside its 2-sigma bound."""
        return float(self.run_in_2sigma.mean())

    def group_in_band(self) -> np.ndarray:
        """Per group of runs: fraction of epochs with the group's average NEES in its band
        (the band of the group's run count); independent across groups."""
        out = []
        for total, m in zip(self.group_nees, self.group_runs, strict=True):
            lo, hi = nees_band(1, int(m))
            x = total / m
            out.append(float(np.mean((x >= lo) & (x <= hi))))
        return np.array(out)


def filter_covariance(
    noise: FilterNoise, fs: float, n: int, m: int, fix_sigma: float, pb0: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[float, float]]]:
    """The filter's covariance at epochs ``0 .. n`` and its gain at each fix.

    A fix of the integral at epoch 0 (``P_0 = diag(fix_sigma^2, pb0)``) and after every ``m``
    steps. Between fixes, in closed form: with ``F^i = [[1, -i dt], [0, 1]]`` and
    ``Q = diag(q1, q2)``, ``P_{k+i} = F^i P_k F^i' + sum_{l<i} F^l Q F^l'`` where the sum is
    ``[[i q1 + q2 dt^2 S2, -q2 dt S1], [., i q2]]``, ``S1 = i(i-1)/2``,
    ``S2 = (i-1) i (2i-1)/6``. At a fix, the Kalman update with ``H = [1, 0]``.

    Returns
    -------
    p11, p12, p22 : ndarray
        The covariance's entries per epoch (posterior at fix epochs).
    gains : list of (float, float)
        The Kalman gain at each fix after epoch 0, in order.
    """
    dt = 1.0 / fs
    q1, q2 = noise.N**2 * dt, noise.K**2 * dt
    rr = fix_sigma**2
    p11 = np.empty(n + 1)
    p12 = np.empty(n + 1)
    p22 = np.empty(n + 1)
    P = (rr, 0.0, pb0)
    p11[0], p12[0], p22[0] = P
    gains: list[tuple[float, float]] = []
    for start in range(0, n, m):
        stop = min(start + m, n)
        i = np.arange(1, stop - start + 1, dtype=float)
        a, b, c = P
        s1, s2 = i * (i - 1) / 2.0, (i - 1) * i * (2 * i - 1) / 6.0
        seg11 = a - 2 * i * dt * b + i * i * dt * dt * c + i * q1 + q2 * dt * dt * s2
        seg12 = b - i * dt * c - q2 * dt * s1
        seg22 = c + i * q2
        if stop - start == m:  # a fix at the segment's end
            s = seg11[-1] + rr
            gains.append((seg11[-1] / s, seg12[-1] / s))
            seg22[-1] -= seg12[-1] ** 2 / s
            seg12[-1] -= seg11[-1] * seg12[-1] / s
            seg11[-1] -= seg11[-1] ** 2 / s
        p11[start + 1 : stop + 1] = seg11
        p12[start + 1 : stop + 1] = seg12
        p22[start + 1 : stop + 1] = seg22
        P = (float(seg11[-1]), float(seg12[-1]), float(seg22[-1]))
    return p11, p12, p22, gains


def _simulate_batch(
    processes: list[eg.Process], runs: int, n: int, fs: float, rng: np.random.Generator
) -> np.ndarray:
    out = np.zeros((runs, n))
    for r in range(runs):
        for p in processes:
            out[r] += p.simulate(n, rng, fs)
    return out


def _estimates(
    err: np.ndarray, fixes: np.ndarray, gains: list[tuple[float, float]], m: int, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """The filter's integral and bias estimates (runs x epochs) for rate errors ``err`` (runs
    x steps) and fixes of the integral (truth 0) every ``m`` steps, with the gains of
    :func:`filter_covariance`. The integral estimate is the integral's error (the truth is 0)."""
    size, n = err.shape
    th_all = np.empty((size, n + 1))
    bh_all = np.empty((size, n + 1))
    theta = fixes[:, 0].copy()  # initialised by the fix at time 0 (truth 0)
    bhat = np.zeros(size)
    th_all[:, 0], bh_all[:, 0] = theta, bhat
    for f, start in enumerate(range(0, n, m)):
        stop = min(start + m, n)
        i = np.arange(1, stop - start + 1, dtype=float)
        drift = dt * np.cumsum(err[:, start:stop], axis=1)
        th = theta[:, None] + drift - dt * i * bhat[:, None]
        bh = np.repeat(bhat[:, None], stop - start, axis=1)
        if stop - start == m:
            k1, k2 = gains[f]
            innov = fixes[:, f + 1] - th[:, -1]
            th[:, -1] += k1 * innov
            bh[:, -1] += k2 * innov
        th_all[:, start + 1 : stop + 1], bh_all[:, start + 1 : stop + 1] = th, bh
        theta, bhat = th[:, -1].copy(), bh[:, -1].copy()
    return th_all, bh_all


@dataclass
class RecordedConsistency:
    """The integral's NEES of the filter run on recorded error segments.

    ``nees`` is the segment-averaged NEES per epoch, ``band`` its 95 % band
    ``chi2_M(0.025, 0.975) / M`` for ``M`` segments."""

    segments: int
    nees: np.ndarray
    band: tuple[float, float]
    epochs_per_fix: int = 1

    @property
    def mean_nees(self) -> float:
        """Time-and-segment average of the integral's NEES (1 when consistent)."""
        return float(self.nees.mean())

    @property
    def above(self) -> float:
        """Fraction of epochs whose segment-averaged NEES is above the band."""
        return float(np.mean(self.nees > self.band[1]))

    @property
    def below(self) -> float:
        """Fraction of epochs below the band."""
        return float(np.mean(self.nees < self.band[0]))

    def above_with_error(self) -> tuple[float, float, int]:
        """Fraction of epochs above the band, per fix interval (:func:`block_fraction`):
        ``(fraction, standard error, fix intervals)``."""
        return block_fraction(self.nees > self.band[1], self.epochs_per_fix)


def run_recorded(
    errors: np.ndarray,
    noise: FilterNoise,
    *,
    fs: float,
    hold: int,
    t_fix_s: float,
    fix_sigma: float,
    pb0: float,
    seed: int = 0,
) -> RecordedConsistency:
    """The two-state filter on recorded sensor errors (segments x samples at the log's rate
    ``fs``), each sample held for ``hold`` filter steps (a filter at ``hold * fs`` Hz fed by
    the IMU at ``fs``: zero-order hold, as an EKF that predicts faster than its IMU). Fixes of
    the integral (truth 0: the sensor is static and the errors are the recording minus its
    turn-on bias) every ``t_fix_s`` s with standard deviation ``fix_sigma``; ``pb0`` is the
    filter's initial bias variance."""
    fs_f = fs * hold
    err = np.repeat(np.asarray(errors, float), hold, axis=1)
    n = err.shape[1]
    m = int(round(t_fix_s * fs_f))
    p11, _, _, gains = filter_covariance(noise, fs_f, n, m, fix_sigma, pb0)
    rng = np.random.default_rng(seed)
    fixes = rng.normal(0.0, fix_sigma, (err.shape[0], n // m + 1))
    th_all, _ = _estimates(err, fixes, gains, m, 1.0 / fs_f)
    nees = np.mean(th_all**2 / p11, axis=0)[::hold]  # at the IMU's epochs
    return RecordedConsistency(err.shape[0], nees, nees_band(1, err.shape[0]), m // hold)


def run_monte_carlo(
    truth: eg.Model,
    noise: FilterNoise,
    *,
    fs: float,
    duration_s: float,
    t_fix_s: float,
    fix_sigma: float,
    runs: int = 100,
    groups: int = 10,
    seed: int = 0,
) -> Consistency:
    """Run the two-state filter with ``noise`` on sensor errors simulated from ``truth``.

    Parameters
    ----------
    truth : Model
        The sensor's error model (all values set), simulated at ``fs``.
    noise : FilterNoise
        The filter's N and K (all it knows of the sensor noise).
    fs : float
        Sensor and filter rate [Hz].
    duration_s : float
        Length of each run [s]; ``round(duration_s * fs)`` propagation steps.
    t_fix_s : float
        Interval between absolute fixes of the integral [s]; a whole number of steps. A fix at
        time 0 initialises the integral.
    fix_sigma : float
        Standard deviation of a fix [u s], known to the filter.
    runs : int
        Monte Carlo runs (independent draws of the truth and of the fix noise).
    groups : int
        The runs are simulated in this many groups (batches); each group's NEES is kept.
    seed : int
        Seed of the whole experiment.

    Returns
    -------
    Consistency
    """
    if fs <= 0 or duration_s <= 0 or fix_sigma <= 0:
        raise ValueError(
            f"run_monte_carlo: fs, duration_s and fix_sigma must be > 0, got {fs}, "
            f"{duration_s}, {fix_sigma}"
        )
    n = int(round(duration_s * fs))
    m = int(round(t_fix_s * fs))
    if m < 1 or abs(m - t_fix_s * fs) > 1e-9 * max(1.0, m):
        raise ValueError(f"run_monte_carlo: t_fix_s * fs = {t_fix_s * fs} must be a whole >= 1")
    if not 1 <= groups <= runs:
        raise ValueError(f"run_monte_carlo: groups must be in 1..runs={runs}, got {groups}")
    dt = 1.0 / fs
    pb0 = bias_prior_var(truth, fs)
    white, bias = split_truth(truth, fs)

    p11, p12, p22, gains = filter_covariance(noise, fs, n, m, fix_sigma, pb0)
    det = p11 * p22 - p12 * p12
    if np.any(det <= 0) or np.any(p11 <= 0):
        raise ValueError(
            "run_monte_carlo: the filter's covariance is singular (N = K = 0 with no bias "
            "prior?); give the filter positive noise numbers"
        )
    i11, i12, i22 = p22 / det, -p12 / det, p11 / det

    rng = np.random.default_rng(seed)
    sizes = np.full(groups, runs // groups)
    sizes[: runs % groups] += 1
    group_nees = np.zeros((groups, n + 1))
    nees_state = np.zeros(n + 1)
    run_mean, run_2s = [], []
    for g, size in enumerate(sizes):
        size = int(size)
        wsum = _simulate_batch(white, size, n, fs, rng)
        bsum = _simulate_batch(bias, size, n + 1, fs, rng)
        err = wsum + bsum[:, :n]  # the rate error the filter integrates
        fixes = rng.normal(0.0, fix_sigma, (size, n // m + 1))
        th_all, bh_all = _estimates(err, fixes, gains, m, dt)
        db = bh_all - bsum
        e2 = i11 * th_all**2 + 2 * i12 * th_all * db + i22 * db**2
        ea = th_all**2 / p11
        group_nees[g] = ea.sum(axis=0)
        nees_state += e2.sum(axis=0)
        run_mean.append(ea.mean(axis=1))
        run_2s.append(np.mean(ea <= 4.0, axis=1))
    return Consistency(
        runs=runs,
        steps=n,
        fs=fs,
        t_fix_s=t_fix_s,
        nees=group_nees.sum(axis=0) / runs,
        nees_state=nees_state / runs,
        band=nees_band(1, runs),
        band_state=nees_band(2, runs),
        run_mean_nees=np.concatenate(run_mean),
        run_in_2sigma=np.concatenate(run_2s),
        group_nees=group_nees,
        group_runs=sizes,
    )
