"""Model algebra, parsing, canonical specs, labels and identifiability rules."""

from __future__ import annotations

import numpy as np
import pytest

import engine as eg
from engine import AR1, DR, GM, QN, RW, WN, Model  # noqa: F401  (used by eval of repr)


def test_algebra_builds_a_flat_canonical_model():
    m = WN() + RW() + 2 * GM()
    assert isinstance(m, Model)
    assert [p.code for p in m] == ["GM", "GM", "WN", "RW"]
    assert m.spec() == "2*GM+WN+RW"
    assert m == GM() * 2 + RW() + WN()
    assert m.labels == ["GM_1", "GM_2", "WN", "RW"]
    assert m.param_names == [
        "GM_1.beta",
        "GM_1.sigma2_gm",
        "GM_2.beta",
        "GM_2.sigma2_gm",
        "WN.sigma2",
        "RW.gamma2",
    ]
    assert m.n_params == 6 and not m.is_linear
    assert (QN() + WN() + RW() + DR()).is_linear


@pytest.mark.parametrize("spec", ["2*GM+WN+RW", "WN+RW+2*GM", "rw + gm*2 + wn", "GM+WN+GM+RW"])
def test_parse_any_order(spec):
    assert eg.parse_model(spec) == WN() + RW() + 2 * GM()
    assert eg.parse_model(spec).spec() == "2*GM+WN+RW"


def test_parse_with_values():
    m = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)+GM(0.5, 2e-3)")
    assert m == GM(beta=0.5, sigma2_gm=2e-3) + WN(sigma2=1.0) + RW(gamma2=1e-4)
    assert m.is_set
    assert m.values()["RW.gamma2"] == 1e-4
    # spec with values parses back to the same model
    assert eg.parse_model(m.spec(values=True)) == m


def test_repr_evaluates_back():
    for m in (
        WN() + RW() + 2 * GM(),
        GM(beta=0.1, sigma2_gm=1e-4) + WN(sigma2=2.0),
        AR1(phi=0.5, sigma2=1.0) + QN(q2=1e-3) + DR(omega=-2e-5),
    ):
        assert eval(repr(m)) == m


def test_implied_wv_is_sum_of_components():
    m = eg.parse_model(
        "GM(beta=1, sigma2_gm=1)+QN(q2=0.1)+WN(sigma2=1)+RW(gamma2=1e-6)+DR(omega=1e-4)"
    )
    tau = 2.0 ** np.arange(1, 15)
    comps = m.components(tau, fs=10.0)
    assert list(comps) == ["GM", "QN", "WN", "RW", "DR"]
    np.testing.assert_allclose(sum(comps.values()), m.wv(tau, fs=10.0), rtol=1e-14)
    np.testing.assert_allclose(comps["WN"], 1 / tau)
    np.testing.assert_allclose(comps["QN"], 0.6 / tau**2)


@pytest.mark.parametrize(
    ("spec", "levels", "match"),
    [
        ("WN+WN", None, "2 WN terms"),
        ("QN+2*QN+WN", None, "3 QN terms"),
        ("RW+RW", None, "RW terms"),
        ("DR+DR+WN", None, "DR terms"),
        ("AR1+GM", None, "mixes AR1 and GM"),
        ("3*GM+WN+RW", 7, "8 parameters but the WV has only 7 levels"),
    ],
)
def test_unidentifiable_models_are_rejected_with_reason(spec, levels, match):
    with pytest.raises(eg.ModelError, match=match):
        eg.parse_model(spec).validate(levels)


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("", "empty"),
        ("WN+", "empty term"),
        ("XX+WN", "unknown process 'XX'"),
        ("WN(sigma2=abc)", "not a number"),
        ("WN(beta=1)", "no parameter 'beta'"),
        ("GM((1)", "unbalanced"),
        ("2**WN", "cannot read the term"),
        ("AR1(phi=2, sigma2=1)", r"phi must be in \(-1, 1\)"),
    ],
)
def test_parse_errors_say_what_is_wrong(spec, match):
    with pytest.raises(eg.ModelError, match=match):
        eg.parse_model(spec)


def test_simulate_needs_values():
    with pytest.raises(eg.ModelError, match="no value for WN.sigma2"):
        (WN() + RW(gamma2=1.0)).simulate(10)


def test_simulate_is_reproducible_and_additive():
    m = eg.parse_model("WN(sigma2=1)+DR(omega=0.5)")
    a = m.simulate(100, rng=7)
    np.testing.assert_array_equal(a, m.simulate(100, rng=7))
    np.testing.assert_allclose(
        a - 0.5 * np.arange(1, 101), eg.WN(sigma2=1.0).simulate(100, np.random.default_rng(7))
    )


def test_processes_register_in_canonical_order():
    """Each concrete process registers itself; the registry drives parsing and spec order."""
    from engine.models import PROCESS_TYPES

    # the built-in six in this order, any process added later by its declared order
    builtin = ["GM", "AR1", "QN", "WN", "RW", "DR"]
    assert [c for c in PROCESS_TYPES if c in builtin] == builtin
    orders = [cls.order for cls in PROCESS_TYPES.values()]
    assert orders == sorted(orders)
    assert all(PROCESS_TYPES[c].code == c for c in PROCESS_TYPES)
    assert eg.parse_model("DR+RW+WN+QN+AR1").spec() == "AR1+QN+WN+RW+DR"


_LONG = 15_000  # a pasted string of a reported size (10-20 KB)


@pytest.mark.parametrize(
    ("spec", "bad"),
    [
        ("WN+" + "X" * _LONG, "unknown process 'XXXX"),  # the bad token
        ("WN+(" * (_LONG // 4), "unbalanced '('"),
        ("WN+GM(beta=0.1, " + "q" * _LONG + "=1)", "GM has no parameter 'qqqq"),
        ("9" * 5000 + "*WN", "the multiplier in '9999"),  # not int(): 5000 digits raise
        ("WN+RW(gamma2=" + "z" * _LONG + ")", "RW.gamma2: 'zzzz"),
        ("WN+ +" + "RW" * (_LONG // 2), "empty term"),
        ("WN+RW(1)" * (_LONG // 8) + "+QQ", "cannot read the term 'RW(1)WN'"),
    ],
)
def test_parse_errors_do_not_echo_a_long_model_whole(spec: str, bad: str) -> None:
    """The message names the bad token and quotes at most 60 characters of any piece, with
    its length; it stays short (was: the 15 KB string echoed whole)."""
    with pytest.raises(eg.ModelError) as exc:
        eg.parse_model(spec)
    msg = str(exc.value)
    assert bad in msg and len(msg) < 400, (len(msg), msg[:500])
    assert "characters)" in msg  # the long piece's length is said
    assert "\n" not in msg
