"""Datasheet conversions (docs/conventions.md, Units) and the unconstrained transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

import engine as eg
from engine import units


def rows(model, fs, unit):
    """``{(label, quantity): (value, unit)}`` of the datasheet rows."""
    return {
        (r["label"], r["quantity"]): (r["value"], r["unit"])
        for r in eg.units.datasheet(eg.parse_model(model), fs, unit)
    }


def test_gyro_white_noise_and_random_walk_in_datasheet_units():
    fs = 200.0
    d = rows("WN(sigma2=4e-4)+RW(gamma2=1e-12)", fs, "deg/s")
    n = math.sqrt(4e-4 / fs)  # (deg/s)/sqrt(Hz)
    assert d[("WN", "white noise density")] == (pytest.approx(n), "deg/s/sqrt(Hz)")
    assert d[("WN", "angle random walk")] == (pytest.approx(60 * n), "deg/sqrt(h)")
    k = math.sqrt(1e-12 * fs)  # (deg/s)/sqrt(s) = deg/s^2/sqrt(Hz)
    assert d[("RW", "rate random walk")][0] == pytest.approx(216000 * k)
    assert d[("RW", "rate random walk")][1] == "deg/h/sqrt(h)"
    native = [r for r in eg.units.datasheet(eg.parse_model("RW(gamma2=1e-12)"), fs, "deg/s")][0]
    assert (native["symbol"], native["unit"]) == ("K", "deg/s^2/sqrt(Hz)")
    assert native["value"] == pytest.approx(k, rel=1e-12)


def test_rad_per_second_converts_to_degrees():
    d = rows("WN(sigma2=1e-6)", 100.0, "rad/s")
    n = math.sqrt(1e-6 / 100.0)
    assert d[("WN", "angle random walk")][0] == pytest.approx(60 * n * 180 / math.pi)


def test_accelerometer_quantization_drift_and_vrw():
    """Q in integrated units (m/s), R in m/s^3 (was spelled m/s^2*s and m/s^2/s)."""
    fs = 50.0
    d = rows("QN(q2=1e-6)+WN(sigma2=1e-4)+DR(omega=-2e-7)", fs, "m/s^2")
    assert d[("QN", "quantization")] == (pytest.approx(1e-3 / fs), "m/s")
    assert d[("DR", "acceleration ramp (SI)")] == (pytest.approx(2e-7 * fs), "m/s^3")
    assert d[("WN", "velocity random walk")] == (
        pytest.approx(60 * math.sqrt(1e-4 / fs)),
        "m/s/sqrt(h)",
    )


def test_gm_correlation_time_and_psd():
    d = rows("GM(beta=0.25, sigma2_gm=9e-6)", 100.0, "deg/s")
    assert d[("GM", "correlation time")] == (pytest.approx(4.0), "s")
    assert d[("GM", "stationary std")][0] == pytest.approx(3e-3)
    assert d[("GM", "driving-noise PSD")] == (pytest.approx(4.5e-6), "(deg/s)^2/s")
    assert d[("GM", "driving-noise density")] == (
        pytest.approx(math.sqrt(4.5e-6)),
        "deg/s^2/sqrt(Hz)",
    )


def test_allan_variance_shape_of_white_noise_matches_n_squared_over_t():
    """AV(T) = N^2 / T with N the white-noise density: AV = 2 WV at T = tau/2 samples."""
    fs, s2 = 100.0, 2.5e-3
    tau = 2.0 ** np.arange(1, 12)
    wv = eg.WN(sigma2=s2).wv(tau, fs)
    t_s = tau / 2 / fs
    n2 = s2 / fs
    np.testing.assert_allclose(2 * wv, n2 / t_s)


def test_param_units():
    assert eg.units.param_unit("WN", "sigma2", "deg/s") == "(deg/s)^2"
    assert eg.units.param_unit("GM", "sigma2_gm", "g") == "g^2"
    assert eg.units.param_unit("GM", "beta", "g") == "1/s"
    assert eg.units.param_unit("DR", "omega", "m/s^2") == "m/s^2 per sample"


@pytest.mark.parametrize(
    "proc",
    [
        eg.WN(sigma2=2e-3),
        eg.QN(q2=1e-7),
        eg.RW(gamma2=1e-12),
        eg.DR(omega=-3e-6),
        eg.AR1(phi=-0.3, sigma2=0.5),
        eg.AR1(phi=0.999, sigma2=1e-4),
        eg.GM(beta=0.02, sigma2_gm=4e-5),
    ],
    ids=repr,
)
def test_unconstrained_round_trip_and_bounds(proc):
    u = proc.to_unconstrained()
    assert np.all(np.isfinite(u))
    back = proc.from_unconstrained(u)
    np.testing.assert_allclose(back.values, proc.values, rtol=1e-12)
    # any real vector maps inside the bounds
    for z in (np.full(u.size, -30.0), np.full(u.size, 30.0), np.zeros(u.size)):
        q = proc.from_unconstrained(z)
        for name, v in zip(q.param_names, q.values, strict=True):
            lo, hi = proc.bounds()[name]
            assert lo <= v <= hi


# ---------------------------------------------------------------- the one datasheet table
ALL_PROCESSES = [
    eg.WN(sigma2=2e-3),
    eg.QN(q2=1e-7),
    eg.RW(gamma2=1e-12),
    eg.DR(omega=-3e-6),
    eg.GM(beta=0.02, sigma2_gm=4e-5),
    eg.AR1(phi=0.999, sigma2=1e-4),
]


@pytest.mark.parametrize("proc", ALL_PROCESSES, ids=repr)
@pytest.mark.parametrize("fs", [1.0, 100.0, 250.0])
def test_forward_then_inverse_returns_the_process(proc, fs):
    vals = units.process_values(proc, fs)
    back = units.process_from_values(proc.code, vals, fs)
    assert type(back) is type(proc)
    np.testing.assert_allclose(back.values, proc.values, rtol=1e-12)


def test_one_parameter_conversions_follow_conventions():
    """docs/conventions.md: N = sqrt(sigma2 dt), K = sqrt(gamma2 / dt), Q = sqrt(q2) dt,
    R = omega / dt."""
    fs, dt = 250.0, 1 / 250.0
    assert units.to_datasheet("WN", 4e-4, fs) == pytest.approx(math.sqrt(4e-4 * dt), rel=1e-14)
    assert units.to_datasheet("RW", 1e-12, fs) == pytest.approx(math.sqrt(1e-12 / dt), rel=1e-14)
    assert units.to_datasheet("QN", 1e-6, fs) == pytest.approx(1e-3 * dt, rel=1e-14)
    assert units.to_datasheet("DR", -2e-7, fs) == pytest.approx(-2e-7 / dt, rel=1e-14)
    for code, v in (("WN", 0.3), ("RW", 2e-5), ("QN", 1e-6), ("DR", -4e-3)):
        back = units.to_datasheet(code, units.from_datasheet(code, v, fs), fs)
        assert back == pytest.approx(v, rel=1e-12)
    assert units.BI_FACTOR == pytest.approx(0.6643, abs=1e-4)


@pytest.mark.parametrize("fs", [1.0, 100.0, 400.0])
def test_allan_shapes_from_datasheet_values_equal_twice_the_haar_wv(fs):
    """AV(T) = 2 nu2(tau = 2 T fs): N^2/T, K^2 T/3 (+ K^2 dt^2/(6T), exact Haar term),
    3 Q^2/T^2, R^2 T^2/2 with the table's N, K, Q, R: pins value and time exponent."""
    m = 2.0 ** np.arange(0, 14)  # Allan averaging time in samples
    t = m / fs
    dt = 1.0 / fs
    procs = {"WN": eg.WN(2.5e-3), "RW": eg.RW(3e-11), "QN": eg.QN(2e-5), "DR": eg.DR(5e-8)}
    for code, p in procs.items():
        v = units.process_values(p, fs)
        av = 2.0 * p.wv(2.0 * m, fs)
        if code == "WN":
            shape = v["N"] ** 2 / t
        elif code == "RW":
            shape = v["K"] ** 2 * t / 3 + v["K"] ** 2 * dt**2 / (6 * t)
        elif code == "QN":
            shape = 3 * v["Q"] ** 2 / t**2
        else:
            shape = v["R"] ** 2 * t**2 / 2
        np.testing.assert_allclose(shape, av, rtol=1e-12, err_msg=code)


class _Dim:
    """A physical unit: SI factor and exponents of base dimensions (rad, m, s, u)."""

    def __init__(self, f: float, d: dict[str, float]):
        self.f, self.d = f, {k: v for k, v in d.items() if v != 0}

    def __mul__(self, o):
        o = o if isinstance(o, _Dim) else _Dim(float(o), {})
        keys = set(self.d) | set(o.d)
        return _Dim(self.f * o.f, {k: self.d.get(k, 0) + o.d.get(k, 0) for k in keys})

    def __truediv__(self, o):
        o = o if isinstance(o, _Dim) else _Dim(float(o), {})
        return self * _Dim(1 / o.f, {k: -v for k, v in o.d.items()})

    def __rtruediv__(self, o):
        return _Dim(float(o), {}) / self

    def __pow__(self, e):
        return _Dim(self.f**e, {k: v * e for k, v in self.d.items()})


_NS = {
    "deg": _Dim(math.pi / 180, {"rad": 1}),
    "rad": _Dim(1.0, {"rad": 1}),
    "m": _Dim(1.0, {"m": 1}),
    "s": _Dim(1.0, {"s": 1}),
    "h": _Dim(3600.0, {"s": 1}),
    "Hz": _Dim(1.0, {"s": -1}),
    "mg": _Dim(9.80665e-3, {"m": 1, "s": -2}),
    "u": _Dim(1.0, {"u": 1}),
    "sqrt": lambda x: x**0.5,
}


def dim(unit: str) -> _Dim:
    """Evaluate a unit spelling (``deg/h/sqrt(h)``, ``(deg/s)^2/s``) into a _Dim."""
    got = eval(unit.replace("^", "**"), {"__builtins__": {}}, _NS)  # noqa: S307 - test only
    return got if isinstance(got, _Dim) else _Dim(float(got), {})


# time exponent of each quantity relative to the signal unit u, from its Allan shape
# (N^2/T, K^2 T, Q^2/T^2, R^2 T^2 are u^2) or definition
_EXPECTED = {
    "N": (1, 0.5),
    "K": (1, -0.5),
    "Q": (1, 1.0),
    "R": (1, -1.0),
    "B": (1, 0.0),
    "T_c": (0, 1.0),
    "sigma_gm": (1, 0.0),
    "q": (2, -1.0),
    "sqrt(q)": (1, -0.5),
}


@pytest.mark.parametrize("unit", ["deg/s", "m/s^2", "rad/s", "mg", ""])
def test_every_unit_spelling_is_dimensionally_right(unit):
    """Every row of the table: its unit has the dimension its Allan shape implies, and the
    native, SI and datasheet-display rows of a quantity are the same physical value (this pins
    60, 216000, 3600^2, the deg/h and mg factors and every spelling)."""
    fs = 100.0
    model = eg.parse_model(
        "GM(beta=0.02, sigma2_gm=4e-5)+QN(q2=1e-7)+WN(sigma2=2e-3)+RW(gamma2=1e-12)+DR(omega=3e-6)"
    )
    rows = units.datasheet_rows(model, fs, unit, n_levels=12)
    u = dim(unit or "u")
    groups: dict[tuple[str, tuple], list[float]] = {}
    for r in rows:
        if not math.isfinite(r.value):
            continue
        d = dim(r.unit)
        si = r.value * d.f
        groups.setdefault((r.process, tuple(sorted(d.d.items()))), []).append(si)
        if r.quantity.endswith(("(SI)", "SI)")) or r.symbol not in _EXPECTED:
            continue
        if r.unit in ("deg/sqrt(h)", "deg/h/sqrt(h)", "deg/h^2", "deg/h", "mg"):
            continue  # display rows: checked by the group equality below
        if r.unit.startswith("m/s/"):
            continue
        pu, ps = _EXPECTED[r.symbol]
        want = (u**pu) * _Dim(1.0, {"s": ps})
        assert d.d == want.d, (r.symbol, r.unit, d.d, want.d)
        assert d.f == pytest.approx(want.f, rel=1e-12), (r.symbol, r.unit)
    for key, vals in groups.items():
        np.testing.assert_allclose(vals, vals[0], rtol=1e-12, err_msg=str(key))
    if unit in ("deg/s", "m/s^2"):
        kinds = {r.quantity for r in rows}
        disp = "angle random walk" if unit == "deg/s" else "velocity random walk"
        assert disp in kinds and any(r.quantity.endswith("(SI)") for r in rows)


def test_squared_unit_one_spelling():
    """One helper and one spelling for squared units: ``u^2`` when unknown."""
    assert units.squared("") == "u^2"
    assert units.squared("deg/s") == "(deg/s)^2"
    assert units.squared("g") == "g^2"
    wv = eg.wavelet_variance(np.random.default_rng(1).normal(size=256), fs=1.0)
    assert "WV [u^2]" in wv.table()
    from gmwm_app.views import unit_squared

    assert unit_squared("") == "u²" and unit_squared("deg/s") == "(deg/s)²"


def test_one_bi_factor():
    import engine.formats
    import engine.teaching.slope

    assert engine.teaching.slope.BI_FACTOR is units.BI_FACTOR
    assert engine.formats.BI_FACTOR is units.BI_FACTOR
    assert units.BI_FACTOR == pytest.approx(math.sqrt(2 * math.log(2) / math.pi), rel=1e-15)
