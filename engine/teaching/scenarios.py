"""Teaching scenarios: simulated logs with known truth where the Allan slope method goes wrong.

Each :class:`Scenario` is a latent model with true values, a log length, a sampling frequency
and a seed, the averaging-time regions a naive user would pick on the Allan deviation plot
(one per process, in seconds), and a sentence saying why the slope method (AVSM, IEEE Std 952)
fails there. :func:`simulate_scenario` turns one into an :class:`~engine.io.ImuLog`
(deterministic with the seed), which the app loads like any log.

The pitfalls (the GMWM paper, Guerrier et al. 2020, sec. I; El-Sheimy, Hou & Niu 2008):

* ``wn_gm``: a Gauss-Markov bump overlaps the white-noise slope; the -1/2 line read over a
  region where the GM already contributes over-states the white noise.
* ``qn_wn``: quantization noise hides under the white noise at the shortest averaging times;
  the -1 line through the first points reads white noise as quantization.
* ``rw_dr``: a drift (rate ramp) bends the random-walk slope upward; the +1/2 line over the
  long averaging times over-states the random walk, and the +1 line through the last points
  is read off a handful of clusters.
* ``short_log``: a log a few minutes long; the random walk is read off the last octaves of the
  Allan deviation, where a few clusters make it noisy and the log-average biased.

``tests/engine/test_teaching.py`` checks by Monte Carlo that the slope method with these regions is
biased (or erratic) while the GMWM fit of the same processes is close to the truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io import ImuLog
from ..models import DR, GM, PROCESS_TYPES, QN, RW, WN, Model, parse_model
from .slope import SLOPES

__all__ = ["Scenario", "SCENARIOS", "get_scenario", "simulate_scenario", "gmwm_spec"]


@dataclass(frozen=True)
class Scenario:
    """A teaching scenario: a simulated log with known truth and the naive AVSM regions.

    Attributes
    ----------
    key : str
        Short identifier (``"wn_gm"``, ...).
    title : str
        One-line title for a menu.
    model : Model
        The true latent model, every value set (per-sample parameters, GM in 1/s).
    n : int
        Samples.
    fs : float
        Sampling frequency (Hz).
    seed : int
        Seed of the simulation (``numpy.random.default_rng(seed)``).
    unit : str
        Signal unit (``"deg/s"`` for a gyroscope).
    regions : tuple of (str, float, float)
        The averaging-time regions a naive user picks: ``(process code, tau_lo_s, tau_hi_s)``
        with codes among ``QN, WN, BI, RW, DR`` (see :func:`engine.teaching.avsm`).
    why : str
        One or two sentences: why the slope method goes wrong here.
    channel : str
        Channel name in the simulated log.
    """

    key: str
    title: str
    model: Model
    n: int
    fs: float
    seed: int
    unit: str
    regions: tuple[tuple[str, float, float], ...]
    why: str
    channel: str = "gyro_x"

    @property
    def region_dict(self) -> dict[str, tuple[float, float]]:
        """The regions as ``{code: (tau_lo_s, tau_hi_s)}`` (the form :func:`avsm` takes)."""
        return {c: (lo, hi) for c, lo, hi in self.regions}

    @property
    def duration_s(self) -> float:
        """Length of the log in seconds."""
        return self.n / self.fs

    def simulate(self, seed: int | None = None) -> np.ndarray:
        """The simulated series (``seed`` overrides the scenario's own)."""
        return self.model.simulate(self.n, fs=self.fs, rng=self.seed if seed is None else seed)


def gmwm_spec(codes: list[str] | tuple[str, ...]) -> str:
    """The GMWM model of a set of slope-method processes: the bias-instability floor is a GM.

    Parameters
    ----------
    codes : sequence of str
        Process codes among ``QN, WN, BI, RW, DR`` (order and repeats do not matter).

    Returns
    -------
    str
        A model spec in the engine's order, e.g. ``["WN", "BI"] -> "GM+WN"``.
    """
    bad = [c for c in codes if c not in SLOPES]
    if bad:
        *first, last = SLOPES
        raise ValueError(f"unknown process {bad[0]!r}: use {', '.join(first)} or {last}")
    # the bias-instability floor is modelled by a GM; a Model prints in the engine's order
    return Model(tuple(GM() if c == "BI" else PROCESS_TYPES[c]() for c in set(codes))).spec()


_S = [
    Scenario(
        key="wn_gm",
        title="White noise overlapped by a Gauss-Markov bump",
        model=parse_model("GM(beta=1, sigma2_gm=2e-4)+WN(sigma2=1e-3)"),
        n=2**16,
        fs=100.0,
        seed=4101,
        unit="deg/s",
        regions=((WN.code, 0.01, 1.0), ("BI", 1.0, 20.0)),
        why=(
            "The Gauss-Markov bump already lifts the Allan deviation where the curve still "
            "looks like a -1/2 slope, so the white-noise line drawn there is too high; the "
            "flat 'bias instability' floor is a GM hump, not flicker noise."
        ),
    ),
    Scenario(
        key="qn_wn",
        title="Quantization noise hiding under white noise",
        model=parse_model("QN(q2=4e-4)+WN(sigma2=1e-3)"),
        n=2**15,
        fs=100.0,
        seed=4102,
        unit="deg/s",
        regions=((QN.code, 0.01, 0.02), (WN.code, 0.01, 5.0)),
        why=(
            "Quantization noise only shows at the first one or two averaging times, where the "
            "white noise is as strong, so the -1 line through them reads white noise as "
            "quantization; the -1/2 line started at the shortest times is lifted by it."
        ),
    ),
    Scenario(
        key="rw_dr",
        title="Random walk bent by a drift (rate ramp)",
        model=parse_model("WN(sigma2=1e-3)+RW(gamma2=4e-9)+DR(omega=4e-7)"),
        n=2**18,
        fs=100.0,
        seed=4103,
        unit="deg/s",
        regions=((WN.code, 0.01, 1.0), (RW.code, 10.0, 400.0), (DR.code, 300.0, 1e9)),
        why=(
            "Where the curve rises at +1/2 the drift already adds to it, so the random-walk "
            "line is too high; the +1 line through the last points rests on a handful of "
            "clusters (on a log this short the drift is uncertain for every method)."
        ),
    ),
    Scenario(
        key="short_log",
        title="A short log (five minutes)",
        model=parse_model("WN(sigma2=1e-3)+RW(gamma2=2e-8)"),
        n=30_000,
        fs=100.0,
        seed=4104,
        unit="deg/s",
        regions=((WN.code, 0.01, 1.0), (RW.code, 20.0, 1e9)),
        why=(
            "The random walk only dominates the last octaves, each averaged over a few "
            "clusters: the +1/2 line read there scatters widely from log to log and the "
            "log-average is biased low; GMWM weighs every octave by its precision."
        ),
    ),
]

#: The built-in scenarios by key, in menu order.
SCENARIOS: dict[str, Scenario] = {s.key: s for s in _S}


def get_scenario(key: str) -> Scenario:
    """The scenario ``key`` (raises ``KeyError`` naming the available keys)."""
    try:
        return SCENARIOS[key]
    except KeyError:
        raise KeyError(
            f"unknown teaching scenario {key!r}; available: {', '.join(SCENARIOS)}"
        ) from None


def simulate_scenario(scenario: Scenario | str, seed: int | None = None) -> ImuLog:
    """Simulate a scenario into a one-channel :class:`~engine.io.ImuLog`.

    Parameters
    ----------
    scenario : Scenario or str
        The scenario or its key.
    seed : int, optional
        Overrides the scenario's seed (the same seed gives the same samples).

    Returns
    -------
    ImuLog
        One channel (``scenario.channel``) in ``scenario.unit`` at ``scenario.fs``;
        ``meta`` holds ``scenario`` (the key), ``truth`` (``{channel: model spec with
        values}``), ``seed`` and ``description`` (the explanation).
    """
    sc = get_scenario(scenario) if isinstance(scenario, str) else scenario
    s = sc.seed if seed is None else int(seed)
    x = sc.simulate(s)
    return ImuLog(
        channels={sc.channel: x},
        fs=float(sc.fs),
        fs_source="file",
        units={sc.channel: sc.unit},
        source=f"scenario:{sc.key}",
        meta={
            "format": "simulated",
            "scenario": sc.key,
            "seed": s,
            "truth": {sc.channel: sc.model.spec(values=True)},
            "description": sc.why,
            "notes": [],
        },
    )
