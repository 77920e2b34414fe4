"""Processes own their behaviour.

* An AST scan of ``engine/`` and ``gmwm_app/``: outside ``engine/models`` no ``isinstance``
  check against a concrete process class: code that needs a process's behaviour calls a method
  or reads a class attribute of the process (``p.psd(f, fs)``, ``p.display_name``), so adding
  a process means adding one class.
* Every registered process class implements every behaviour method (a new process cannot be
  half-implemented), and the behaviour methods agree with independent formulas.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.models import PROCESS_TYPES, Process

ROOT = Path(__file__).resolve().parents[2]
CODES = frozenset(PROCESS_TYPES)


def _class_names(node: ast.AST) -> list[str]:
    """Names of the classes an ``isinstance`` second argument names (``WN``, ``eg.GM``, tuples)."""
    if isinstance(node, ast.Tuple):
        return [n for elt in node.elts for n in _class_names(elt)]
    if isinstance(node, ast.Name):
        return [node.id]
    if isinstance(node, ast.Attribute):
        return [node.attr]
    return []


def scan() -> list[str]:
    """The ``isinstance`` checks against process classes outside ``engine/models``."""
    checks = []
    for pkg in ("engine", "gmwm_app"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith("engine/models/"):
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Call)
                    and isinstance(node.func, ast.Name)
                    and node.func.id == "isinstance"
                    and len(node.args) == 2
                ):
                    hit = [n for n in _class_names(node.args[1]) if n in CODES]
                    if hit:
                        checks.append(f"{rel}:{node.lineno}: isinstance(..., {', '.join(hit)})")
    return checks


def test_no_isinstance_on_process_classes_outside_models():
    checks = scan()
    assert checks == [], (
        "branch on the process's behaviour (a method or class attribute of "
        "engine.models.Process), not on its class:\n" + "\n".join(checks)
    )


# -------------------------------------------------------------------------------------------
# every process implements every behaviour
# -------------------------------------------------------------------------------------------
FS = 50.0
#: One instance per registered process, every value set (a new process must be added here:
#: test_every_process_has_an_example fails until it is).
EXAMPLES: dict[str, Process] = {
    "WN": eg.WN(sigma2=2.5),
    "QN": eg.QN(q2=0.7),
    "RW": eg.RW(gamma2=0.3),
    "DR": eg.DR(omega=0.02),
    "AR1": eg.AR1(phi=0.8, sigma2=1.3),
    "GM": eg.GM(beta=2.0, sigma2_gm=4.0),
    "MA1": eg.parse_model("MA1(theta=-0.4, sigma2=1.1)").processes[0],
}


def test_every_process_has_an_example():
    assert set(EXAMPLES) == set(PROCESS_TYPES)


@pytest.mark.parametrize("code", sorted(PROCESS_TYPES))
def test_every_process_class_implements_every_behaviour(code):
    from engine.models.model import (
        BEHAVIOUR,
        DESCRIPTIVE,
        NONLINEAR_BEHAVIOUR,
        SHARED_BEHAVIOUR,
    )

    cls = PROCESS_TYPES[code]
    assert cls.missing_behaviour() == []
    for name in BEHAVIOUR:
        assert getattr(cls, name) is not getattr(Process, name), name
    for name in NONLINEAR_BEHAVIOUR if cls.nonlinear else ():
        assert getattr(cls, name) is not getattr(Process, name), name
    for name in SHARED_BEHAVIOUR if cls.shareable else ():
        assert getattr(cls, name) is not getattr(Process, name), name
    for name in DESCRIPTIVE:
        assert getattr(cls, name), name
    # the Allan slope and its read point come together
    assert (cls.allan_slope is None) == (cls.read_tau is None)


def test_a_half_implemented_process_is_refused_at_class_creation():
    from dataclasses import dataclass

    with pytest.raises(TypeError, match=r"HalfDone does not implement .*psd_terms"):

        @dataclass(frozen=True, repr=False)
        class HalfDone(Process, order=9, description="half done"):
            x: float | None = None
            display_name = "half"
            help = "half"
            quantities = eg.WN.quantities

            def basis(self, tau, fs, nl=None):
                return 1.0 / tau

            def simulate(self, n, rng=None, fs=1.0):
                return np.zeros(n)

    assert "HalfDone" not in PROCESS_TYPES


def _acvs_psd(p: Process, f: np.ndarray, lags: int = 4000) -> np.ndarray:
    """``S(f) = sum_h gamma(h) cos(2 pi f h)`` from the autocovariance (independent of psd)."""
    h = np.arange(-lags, lags + 1)
    g = p.autocovariance(h, FS)
    return np.cos(2 * np.pi * np.outer(f, h)) @ g


@pytest.mark.parametrize("code", ["WN", "QN", "AR1", "GM"])
def test_psd_of_stationary_processes_is_the_fourier_transform_of_the_autocovariance(code):
    p = EXAMPLES[code]
    f = np.array([0.01, 0.07, 0.2, 0.33, 0.5])
    np.testing.assert_allclose(p.psd(f, FS), _acvs_psd(p, f), rtol=1e-9, atol=1e-12)


def test_psd_of_random_walk_and_drift():
    f = np.array([0.01, 0.1, 0.5])
    # the generalised spectrum of a random walk: gamma2 / |1 - e^(2 pi i f)|^2
    np.testing.assert_allclose(
        EXAMPLES["RW"].psd(f, FS), 0.3 / np.abs(1 - np.exp(2j * np.pi * f)) ** 2, rtol=1e-12
    )
    assert np.all(EXAMPLES["DR"].psd(f, FS) == 0.0)


@pytest.mark.parametrize("code", sorted(PROCESS_TYPES))
def test_psd_integrates_to_the_variance_of_the_haar_coefficients(code):
    """nu2_j = int |H_j(f)|^2 S(f) df for every process with a spectrum (the drift's WV is
    deterministic: 0 here)."""
    p = EXAMPLES[code]
    nf = 1 << 16
    f = (np.arange(nf) + 0.5) / (2 * nf)  # midpoints on (0, 1/2): no node at f = 0
    for tau in (2, 8, 32):
        m = tau // 2
        z = np.exp(2j * np.pi * f)
        gain = np.abs((1 - z**m) ** 2 / (2 * m * (1 - z))) ** 2  # |H_j|^2 of the Haar filter
        nu = 2 * np.sum(gain * p.psd(f, FS)) / (2 * nf)
        expected = 0.0 if p.deterministic else float(p.wv(np.array([tau]), FS)[0])
        assert nu == pytest.approx(expected, rel=2e-3, abs=1e-12), tau


@pytest.mark.parametrize("code", sorted(PROCESS_TYPES))
def test_datasheet_values_round_trip(code):
    p = EXAMPLES[code]
    vals = eg.units.process_values(p, FS)
    assert set(vals) == {q.symbol for q in p.quantities}
    back = type(p).from_datasheet(vals, FS)
    np.testing.assert_allclose(
        [abs(v) for v in back.values], [abs(v) for v in p.values], rtol=1e-12
    )


@pytest.mark.parametrize("code", ["AR1", "GM"])
def test_phi_and_the_non_linear_parameter_are_inverse_maps(code):
    p = EXAMPLES[code]
    phi = p.nl_value(FS)
    assert 0 < phi < 1
    assert p.nl_from_phi(phi, FS) == pytest.approx(getattr(p, p.nonlinear), rel=1e-12)
    # the fit's basis is basis_scale(phi) times the AR1 WV per unit innovation variance
    tau = 2.0 ** np.arange(1, 8)
    np.testing.assert_allclose(
        p.basis(tau, FS, phi), p.basis_scale(phi) * eg.models.ar1_wv(tau, phi, 1.0), rtol=1e-12
    )


def test_white_equivalent_is_the_density_at_zero_frequency():
    ar = EXAMPLES["AR1"]
    assert ar.white_equivalent(FS) == pytest.approx(1.3 / (1 - 0.8) ** 2, rel=1e-12)
    gm = EXAMPLES["GM"]
    phi = math.exp(-2.0 / FS)
    assert gm.white_equivalent(FS) == pytest.approx(4.0 * (1 + phi) / (1 - phi), rel=1e-12)
    assert EXAMPLES["WN"].white_equivalent(FS) == 2.5
    assert EXAMPLES["QN"].white_equivalent(FS) == 0.0
    assert EXAMPLES["RW"].white_equivalent(FS) == math.inf


@pytest.mark.parametrize("code", sorted(PROCESS_TYPES))
def test_filter_terms_keep_the_white_and_the_bias_apart(code):
    p = EXAMPLES[code]
    # a slow filter (1 Hz) and a fast one (the log's rate)
    for fs_f in (1.0, FS):
        t = p.filter_terms(FS, fs_f, 100.0)
        assert t.assignment
        assert t.fast == (t.white > 0)
        assert t.white >= 0 and t.rw_k2 >= 0
    # white at any filter step: a stationary process without a correlation time (WN, QN)
    white = p.correlation_time(FS) is None and not p.deterministic
    assert p.filter_terms(FS, FS, 100.0).fast == (white and math.isfinite(p.white_equivalent(FS)))
    if code in ("WN", "QN", "RW", "DR", "AR1", "GM"):  # the built-in six
        assert p.filter_terms(FS, FS, 100.0).fast == (code in ("WN", "QN"))
    # GM with T_c = 0.5 s: bias at 50 Hz, white at 1 Hz (step 1 s > T_c)
    if code == "GM":
        assert p.filter_terms(FS, 1.0, 100.0).fast
        assert p.filter_terms(FS, FS, 100.0).slow == pytest.approx((2.0, 4.0))


def test_display_names_are_distinct_and_shown_in_the_app():
    from gmwm_app.state import PROCESS_CODES, PROCESS_NAMES

    names = [cls.display_name for cls in PROCESS_TYPES.values()]
    assert len(set(names)) == len(names)
    assert set(PROCESS_CODES) == set(PROCESS_TYPES)
    assert PROCESS_NAMES == {c: cls.display_name for c, cls in PROCESS_TYPES.items()}


def test_isinstance_scan_finds_a_planted_branch(tmp_path, monkeypatch):
    """The scan is able to fail: a file with an isinstance chain is reported."""
    import test_process_behaviour as me

    pkg = tmp_path / "engine"
    pkg.mkdir()
    (pkg / "bad.py").write_text(
        '"""Doc: "WN" in a docstring is fine."""\n'
        "def f(p):\n"
        "    if isinstance(p, (eg.GM, AR1)):\n"
        "        return 1\n"
        '    return p.code == "RW"\n'
    )
    (tmp_path / "gmwm_app").mkdir()
    monkeypatch.setattr(me, "ROOT", tmp_path)
    checks = me.scan()
    assert checks == ["engine/bad.py:3: isinstance(..., GM, AR1)"]
