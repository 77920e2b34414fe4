"""The first-order moving average MA(1), one class: what a new latent process takes.

``x_t = e_t + theta e_{t-1}``, ``e_t`` iid ``N(0, sigma2)``, ``|theta| < 1`` (the invertible
parametrisation; ``theta`` and ``1 / theta`` have the same autocovariance). The R packages
``gmwm``/``simts`` call it ``MA1``. Its autocovariance is ``gamma(0) = sigma2 (1 + theta^2)``,
``gamma(1) = sigma2 theta`` and 0 beyond, so its Haar WV at scale ``tau`` (samples) is

``nu2(tau) = sigma2 [(1 + theta)^2 / tau - 6 theta / tau^2]``

(the two half-window sums of ``m = tau / 2`` samples each have variance
``m gamma(0) + 2 (m - 1) gamma(1)`` and covariance ``gamma(1)``): a white noise of variance
``sigma2 (1 + theta)^2`` plus a quantization-like ``-theta sigma2`` term. Its WV spans the
same two shapes as WN and QN, so a model may not hold it beside either (it would not be
identifiable) and holds at most one. Conventions: ``docs/conventions.md``, "Latent processes
and their Haar WV".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._limits import check_sample_count
from .._quantity import Quantity, sqrt0
from .model import Process, coefficient_unit, param
from .spectrum import FilterTerms, PsdTerms

__all__ = ["MA1", "ma1_wv"]

# the search coordinate u = atanh(theta): its range (|theta| <= 1 - 1e-8) and grid
_U_MAX = math.atanh(1.0 - 1e-8)
_AXIS = np.linspace(-4.0, 4.0, 33)  # theta from -0.9993 to 0.9993
_START = np.linspace(-0.95, 0.95, 191)  # the thetas a starting value is chosen from


def ma1_wv(tau: np.ndarray, theta: float | np.ndarray, sigma2: float = 1.0) -> np.ndarray:
    """Haar WV of an MA(1) at scales ``tau`` (samples): ``sigma2 [(1+theta)^2/tau -
    6 theta/tau^2]``.

    Parameters
    ----------
    tau : array_like, shape (J,)
        Scales in samples.
    theta : float or array_like, shape (n,)
        Moving-average coefficient(s), ``|theta| < 1``; an array gives an (n, J) result.
    sigma2 : float
        Innovation variance [u^2].
    """
    t = np.asarray(tau, dtype=float)
    th = np.asarray(theta, dtype=float)
    if th.ndim:
        th = th[:, None]
    return sigma2 * ((1.0 + th) ** 2 / t - 6.0 * th / (t * t))


@dataclass(frozen=True, repr=False)
class MA1(Process, order=6, description="first-order moving average", nonlinear="theta"):
    """First-order moving average ``x_t = e_t + theta e_{t-1}``, ``Var e = sigma2``.

    Examples
    --------
    Its WV at ``tau = 2`` is ``(gamma(0) - gamma(1)) / 2``, as for any stationary process:

    >>> import numpy as np
    >>> from engine.models import MA1
    >>> ma = MA1(theta=0.5, sigma2=2.0)
    >>> print(*(f"{v:.4f}" for v in ma.autocovariance(np.array([0, 1, 2]))))
    2.5000 1.0000 0.0000
    >>> print(*(f"{v:.4f}" for v in ma.wv(np.array([2.0, 4.0, 8.0]))))
    0.7500 0.7500 0.4688
    """

    theta: float | None = param("atanh", coefficient_unit, (-1.0, 1.0), "linear")
    sigma2: float | None = param()

    display_name = "MA(1)"
    help = "first-order moving average: WV (1+θ)²σ²/τ − 6θσ²/τ² (a filtered white noise)"
    color = "#E377C2"
    unique = True
    shareable = True  # channels may share one (one theta, correlated innovations)
    excludes = {
        code: "an MA1's WV spans the same two shapes (1/tau, 1/tau^2) as WN and QN, so "
        f"their sum is not identifiable; use MA1 without {code}"
        for code in ("WN", "QN")
    }
    quantities = (
        Quantity(
            "MA1",
            "theta",
            "moving-average coefficient",
            "theta",
            lambda p, fs: p["theta"],
            lambda v, fs: v,
            lambda u: "1 (per sample)",
            si=False,
        ),
        Quantity(  # its density at f = 0: the white noise it adds at long scales
            "MA1",
            "N",
            "white noise density (long scales)",
            "",
            lambda p, fs: sqrt0(p["sigma2"] * (1.0 + p["theta"]) ** 2 / fs),
            None,
            lambda u: f"{u}/sqrt(Hz)",
        ),
    )

    def _check_value(self, name, v):
        if name == "theta" and not -1.0 < v < 1.0:
            raise ValueError(f"MA1.theta must be in (-1, 1), got {v}")
        if name == "sigma2" and v < 0:
            raise ValueError(f"MA1.sigma2 must be >= 0, got {v}")

    # ---- fitting: the linear coefficient sigma2, the non-linear value theta ---------------
    def basis(self, tau, fs, nl=None):
        return ma1_wv(tau, nl)

    def basis_many(self, tau, fs, nls):
        return ma1_wv(tau, np.asarray(nls, dtype=float))

    def phi_from_nl(self, nl, fs):
        return float(nl)  # the fitter's value is theta itself

    def nl_from_phi(self, phi, fs):
        return float(phi)

    def from_fit(self, h, nl, fs):
        return MA1(float(nl), float(h))

    # ---- the search coordinate: u = atanh(theta) -----------------------------------------
    def search_range(self, n_max):
        return -_U_MAX, _U_MAX

    def search_axis(self, tau_max, k):
        return _AXIS

    def search_nl(self, u, lo, hi):
        if isinstance(u, np.ndarray):
            return np.tanh(np.clip(u, lo, hi))
        return math.tanh(min(max(u, lo), hi))

    def search_of_nl(self, nl):
        return math.atanh(nl) if -1.0 < nl < 1.0 else None

    def start_nl(self, tau, nu, fs):
        # the theta whose WV falls from the first to the second scale as the data's does: an
        # MA1 shows there before a random walk or a drift does (0, white, without two levels)
        t, v = np.asarray(tau, dtype=float)[:2], np.asarray(nu, dtype=float)[:2]
        if t.size < 2 or not np.all(v > 0):
            return 0.0
        shape = ma1_wv(t, _START)  # (n, 2), positive for |theta| < 1
        miss = np.abs(np.log(shape[:, 1] / shape[:, 0]) - math.log(v[1] / v[0]))
        return float(_START[int(np.argmin(miss))])

    # ---- spectrum, filters, datasheet ---------------------------------------------------
    def psd_terms(self, fs):
        # sigma2 |1 + theta e^(-iw)|^2 = sigma2 (1 + theta)^2 - sigma2 theta x
        theta, s2 = self._require()
        return PsdTerms({0: s2 * (1.0 + theta) ** 2, 1: -s2 * theta})

    def filter_terms(self, fs, fs_filter, horizon):
        theta, s2 = self._require()
        return FilterTerms(
            white=s2 * (1.0 + theta) ** 2,
            fast=True,
            assignment="WN (MA1's white equivalent, (1 + theta)^2 sigma2)",
        )

    @classmethod
    def from_datasheet(cls, values, fs):
        theta = float(values["theta"])
        return MA1(theta=theta, sigma2=values["N"] ** 2 * fs / (1.0 + theta) ** 2)

    # ---- simulation ------------------------------------------------------------------------
    def simulate(self, n, rng=None, fs=1.0):
        n = check_sample_count(n)
        theta, s2 = self._require()
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        e = g.normal(0.0, math.sqrt(s2), n + 1)
        return e[1:] + theta * e[:-1]  # stationary from the first sample

    def simulate_shared(self, z, root, phi, rng):
        # z: the group's innovations e_1..e_n (rows ~ N(0, C)); e_0 from the same law, so the
        # series is stationary from its first sample; phi is the fitter's value, theta
        e0 = rng.standard_normal(z.shape[1]) @ root.T
        return z + phi * np.vstack([e0[None, :], z[:-1]])

    def autocovariance(self, lags, fs=1.0):
        theta, s2 = self._require()
        h = np.abs(np.asarray(lags))
        return np.select([h == 0, h == 1], [s2 * (1.0 + theta * theta), s2 * theta], 0.0)
