"""Each parameter's facts are declared once, on its process class (``param()`` field metadata).

The transform to the fit's unconstrained space, the unit, the bounds and the app's slider scale
are read from the class; no table keyed by parameter name has to learn a new parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

import engine as eg
from engine.models import PROCESS_TYPES, TO_UNCONSTRAINED, Param, Process, param
from engine.models.model import rate_unit

# what the six built-in processes declared before the declarations moved onto them (the
# tables of engine/models/model.py, engine/units.py and gmwm_app/state.py)
BEFORE = {
    ("WN", "sigma2"): ("log", "(deg/s)^2", (0.0, math.inf), "log10"),
    ("QN", "q2"): ("log", "(deg/s)^2", (0.0, math.inf), "log10"),
    ("RW", "gamma2"): ("log", "(deg/s)^2", (0.0, math.inf), "log10"),
    ("DR", "omega"): ("identity", "deg/s per sample", (-math.inf, math.inf), "log10"),
    ("AR1", "phi"): ("atanh", "1 (per sample)", (-1.0, 1.0), "log10(1-x)"),
    ("AR1", "sigma2"): ("log", "(deg/s)^2", (0.0, math.inf), "log10"),
    ("GM", "beta"): ("log", "1/s", (0.0, math.inf), "log10"),
    ("GM", "sigma2_gm"): ("log", "(deg/s)^2", (0.0, math.inf), "log10"),
}


class _WhiteNoiseShape:
    """What the test processes below need beyond their fields: a white noise's WV, spectrum
    and filter terms, and no samples."""

    help = "a test process"
    quantities = PROCESS_TYPES["WN"].quantities

    def basis(self, tau, fs, nl=None):
        return 1.0 / tau

    def simulate(self, n, rng=None, fs=1.0):
        return np.zeros(n)

    def psd_terms(self, fs):
        return eg.models.PROCESS_TYPES["WN"](1.0).psd_terms(fs)

    def filter_terms(self, fs, fs_filter, horizon):
        return eg.models.PROCESS_TYPES["WN"](1.0).filter_terms(fs, fs_filter, horizon)


@pytest.mark.parametrize("code", sorted(PROCESS_TYPES))
def test_every_parameter_declares_its_param_record(code: str) -> None:
    cls = PROCESS_TYPES[code]
    specs = cls.params()
    assert list(specs) == list(cls.param_names)
    for name, spec in specs.items():
        assert isinstance(spec, Param)
        lo, hi = spec.bounds
        # the transform maps all of R inside the bounds, and back
        for u in (-30.0, -1.0, 0.0, 1.0, 30.0):
            v = spec.from_unconstrained(u)
            assert lo <= v <= hi, (code, name, u, v)
            if -15 < u < 15:
                assert spec.to_unconstrained(v) == pytest.approx(u, abs=1e-9)
        assert eg.units.param_unit(code, name, "deg/s") == spec.unit("deg/s")


@pytest.mark.parametrize(("code", "name"), sorted(BEFORE))
def test_the_built_in_declarations_say_what_the_tables_said(code: str, name: str) -> None:
    spec = PROCESS_TYPES[code].params()[name]
    transform, unit, bounds, slider = BEFORE[(code, name)]
    assert (spec.transform, spec.unit("deg/s"), spec.bounds, spec.slider) == (
        transform,
        unit,
        bounds,
        slider,
    )
    assert TO_UNCONSTRAINED[name] is not None


def test_a_new_process_needs_no_table_beside_its_class() -> None:
    """A process declared in a test (a rate and a variance, names no process used before):
    units, the unconstrained space, bounds and its slider follow from its fields alone."""

    @dataclass(frozen=True, repr=False)
    class Probe(_WhiteNoiseShape, Process, order=98, description="a test process"):
        kappa: float | None = param("log", rate_unit)
        s2_probe: float | None = param()

        display_name = "probe"

    try:
        assert eg.units.param_unit("Probe", "kappa", "g") == "1/s"
        assert eg.units.param_unit("Probe", "s2_probe", "g") == "g^2"
        p = Probe(kappa=0.5, s2_probe=2.0)
        np.testing.assert_allclose(p.to_unconstrained(), [math.log(0.5), math.log(2.0)])
        assert p.from_unconstrained(p.to_unconstrained()).values == pytest.approx((0.5, 2.0))
        assert TO_UNCONSTRAINED["kappa"](0.5) == math.log(0.5)
        assert p.bounds() == {"kappa": (0.0, math.inf), "s2_probe": (0.0, math.inf)}
        assert Probe.params()["kappa"].slider == "log10"
    finally:
        del PROCESS_TYPES["Probe"]


def test_a_field_without_its_record_is_refused() -> None:
    @dataclass(frozen=True, repr=False)
    class Bare(_WhiteNoiseShape, Process, order=97, description="a test process"):
        x: float | None = None

        display_name = "bare"

    try:
        with pytest.raises(TypeError, match=r"Bare.x has no Param record"):
            Bare.params()
    finally:
        del PROCESS_TYPES["Bare"]


def test_intervals_read_each_transform_from_the_parameters_own_class() -> None:
    """A process whose ``phi`` moves on the identity (an AR1 with another declaration) beside
    the AR1's atanh ``phi``: the univariate and the multivariate (shared term) Wald intervals
    use the class's own transform, so they are symmetric about the estimate. A lookup by the
    parameter's name finds the AR1's atanh first (PROCESS_TYPES order) and makes them
    asymmetric (by about 10 % of their width here)."""
    from engine.models import AR1
    from engine.models.model import coefficient_unit

    @dataclass(frozen=True, repr=False)
    class AR1Linear(AR1, order=90, description="a test process", nonlinear="phi"):
        phi: float | None = param("identity", coefficient_unit, (-1.0, 1.0), "linear")
        sigma2: float | None = param()

        def from_fit(self, h, nl, fs):
            return type(self)(float(nl), float(h))

    try:
        assert AR1Linear.params()["phi"].transform == "identity"
        assert AR1.params()["phi"].transform == "atanh"
        truth = AR1Linear(phi=0.95, sigma2=1.0) + eg.WN(sigma2=4.0)
        x = {c: truth.simulate(2**12, rng=seed) for c, seed in (("a", 1), ("b", 2))}
        res = eg.fit_gmwm(eg.wavelet_variance(x["a"]), AR1Linear() + eg.WN())
        ci = res.conf_int()
        k = ci.names.index("AR1Linear.phi")
        est, lo, hi = ci.estimate[k], ci.lower[k], ci.upper[k]
        assert lo < est < hi
        assert 0.5 * (lo + hi) == pytest.approx(est, abs=1e-9 * (hi - lo))
        mm = eg.MultiModel(["a", "b"], AR1Linear() + eg.WN(), shared=["AR1Linear"])
        mres = eg.fit_mgmwm(x, mm)
        mci = mres.conf_int()
        k = mci.names.index("AR1Linear.phi")
        est, lo, hi = mci.estimate[k], mci.lower[k], mci.upper[k]
        assert lo < est < hi
        assert 0.5 * (lo + hi) == pytest.approx(est, abs=1e-9 * (hi - lo))
    finally:
        del PROCESS_TYPES["AR1Linear"]
