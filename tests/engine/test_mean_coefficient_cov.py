"""The covariance of the means of the Haar coefficients (the drift's first-order share of V) in
closed form: exact sums of piecewise polynomials, O(J^2) whatever the log's length.

It built each level's ramp as an array of ``2^j`` values and, where the ramps of a level meet,
its weights as ``n - 1`` values: a plan at 1000 h (3.6e8 samples at 100 Hz) of a model with a
drift asked for several 512 MiB arrays and the kernel killed the process (``gmwm plan``, the
app's Plan tab). The array code is kept below as the reference.
"""

from __future__ import annotations

import json
import math
import textwrap

import numpy as np
import pytest
from conftest import run_capped

from engine.fit.asymptotic import mean_coefficient_cov
from engine.wv import haar_coefficients


def _reference_weights(ramp: np.ndarray, inc: int) -> np.ndarray:
    """The array code: weights of the increments ``u = 1..inc`` in the sum of one level's
    coefficients, ``H(min(K - 1, inc - u)) - H(K - 1 - u)``."""
    u = np.arange(1, inc + 1)
    k = ramp.size
    hx = np.concatenate([[0.0], ramp])
    return hx[np.minimum(k - 1, inc - u) + 1] - hx[np.maximum(k - 1 - u, -1) + 1]


def _reference_sums(n: int, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """The array code: ``sum_u W_a W_b`` (ramps and plateau, by symmetry where the ramps do not
    meet; else the weights built whole) and ``sum_s w_a w_b`` (the weights differenced)."""
    inc = n - 1
    ramps, tris = [], []
    for j in range(1, levels + 1):
        m = 1 << (j - 1)
        tri = np.concatenate([np.arange(1, m + 1), np.arange(m - 1, 0, -1)]) / float(2 * m)
        tris.append(tri)
        ramps.append(np.cumsum(tri))
    rw = np.empty((levels, levels))
    wn = np.empty((levels, levels))
    for b in range(levels):
        hb, kb = ramps[b], ramps[b].size
        for a in range(b + 1):
            ha, ka = ramps[a], ramps[a].size
            if 2 * kb <= inc:
                tail = np.concatenate([np.cumsum(hb[::-1])[::-1], [0.0]])
                dot = ha @ hb[:ka] + ha[-1] * tail[ka]
                rw[a, b] = 2.0 * dot + (inc - 2 * kb) * ha[-1] * hb[-1]
                wn[a, b] = 2.0 * (tris[a] @ tris[b][:ka])
            else:
                wa, wb = _reference_weights(ha, inc), _reference_weights(hb, inc)
                rw[a, b] = wa @ wb
                wn[a, b] = np.diff(wa, prepend=0.0, append=0.0) @ np.diff(
                    wb, prepend=0.0, append=0.0
                )
            rw[b, a], wn[b, a] = rw[a, b], wn[a, b]
    return rw, wn


def _closed_form(n: int, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """The random walk's and the white noise's factors through the public function."""
    m_j = (n - 2 ** np.arange(1, levels + 1) + 1).astype(float)
    mm = np.outer(m_j, m_j)
    rw = mean_coefficient_cov({1: 0.0, 0: 0.0, -1: 1.0}, [], n, m_j) * mm
    wn = mean_coefficient_cov({1: 0.0, 0: 1.0, -1: 0.0}, [], n, m_j) * mm
    return rw, wn


LENGTHS = [
    *range(2, 70),
    *(2**p + d for p in range(7, 21) for d in (-1, 0, 1)),
    1000,
    3001,
    12345,
    99999,
    777777,
]


@pytest.mark.parametrize("n", LENGTHS)
def test_the_closed_form_equals_the_array_code_at_every_level(n):
    # every level a log of n samples has (2^J <= n): both branches, the ramps meeting or not
    levels = int(math.floor(math.log2(n)))
    ref = _reference_sums(n, levels)
    mine = _closed_form(n, levels)
    for r, m in zip(ref, mine, strict=True):
        np.testing.assert_allclose(m, r, rtol=1e-9, atol=1e-12 * float(np.abs(r).max()))


@pytest.mark.parametrize("n", [4, 5, 7, 8, 13, 16, 31, 33, 64, 100, 777])
def test_the_closed_form_equals_the_haar_coefficients_weights_on_the_samples(n):
    # independent of both: the sum of the level-j coefficients is linear in the samples; its
    # weights on unit vectors give the covariance under RW + WN (X_0 = 0, increments iid)
    levels = int(math.floor(math.log2(n)))
    m_j = n - 2 ** np.arange(1, levels + 1) + 1
    eye = np.eye(n)
    w = np.array(
        [[haar_coefficients(eye[i], j).sum() for i in range(n)] for j in range(1, levels + 1)]
    )
    idx = np.arange(n)
    cov_x = 0.3 * np.minimum.outer(idx, idx) + 0.7 * np.eye(n)
    direct = w @ cov_x @ w.T / np.outer(m_j, m_j)
    mine = mean_coefficient_cov({1: 0.0, 0: 0.7, -1: 0.3}, [], n, m_j)
    np.testing.assert_allclose(mine, direct, rtol=1e-11, atol=1e-15)


def test_a_billion_samples_in_closed_form_keep_the_invariants():
    # no array: where a level's ramps do not meet (levels 1-28 of 10^9 samples), one more
    # increment adds P_a P_b = (tau_a / 4)(tau_b / 4) to the random walk's factor (a difference
    # of two numbers n P_a P_b: float cancellation n eps = 1e-7) and nothing to the white
    # noise's (the plateau's weights on the samples are 0); the white noise's factor at a long
    # log is 2 sum_d G_a(d) G_b(d) over the finer triangle
    n, levels = 10**9 + 7, 29
    rw0, wn0 = _closed_form(n, levels)
    rw1, wn1 = _closed_form(n + 1, levels)
    tau = 2.0 ** np.arange(1, levels)
    np.testing.assert_allclose((rw1 - rw0)[:-1, :-1], np.outer(tau, tau) / 16.0, rtol=1e-5)
    np.testing.assert_allclose(wn1[:-1, :-1], wn0[:-1, :-1], rtol=1e-14)
    assert 2 ** (levels + 1) - 2 > n - 1  # the coarsest level's ramps meet: another branch
    for a, b in ((0, 0), (2, 5), (9, 19), (19, 19)):
        ma, mb = 1 << a, 1 << b
        tri_a = np.concatenate([np.arange(1, ma + 1), np.arange(ma - 1, 0, -1)]) / (2.0 * ma)
        tri_b = np.concatenate([np.arange(1, mb + 1), np.arange(mb - 1, 0, -1)]) / (2.0 * mb)
        assert wn0[a, b] == pytest.approx(2.0 * tri_a @ tri_b[: tri_a.size], rel=1e-12)
    assert np.all(np.isfinite(rw0)) and np.all(np.linalg.eigvalsh(wn0) > 0)


_PLAN_DRIFT = textwrap.dedent(
    """
    import json, resource, time
    import engine as eg
    from engine.cli import main
    t = time.process_time()
    plan = eg.plan_run("WN(sigma2=1)+DR(omega=1e-6)", 100, "N within 1 %, R within 20 %")
    cpu = time.process_time() - t
    rc = main(["plan", "--model", "WN(sigma2=1)+DR(omega=1e-6)", "--fs", "100",
               "--target", "N within 1 %, R within 20 %", "--json"])
    hwm = next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
    print(json.dumps({
        "cpu": cpu, "rc": rc, "required": plan.required, "achieved": plan.achieved,
        "finite": {k: bool((v[-3:] == v[-3:]).all()) for k, v in plan.precision.items()},
        "maxrss_mb": int(hwm.split()[1]) / 1024,
    }))
    """
)


def test_a_plan_with_a_drift_answers_in_bounded_memory_and_cpu():
    """Was: killed by the kernel (several 512 MiB arrays for the plan's 1000 h log at 100 Hz;
    under a 3 GB address space numpy's _ArrayMemoryError). The child has 1.5 GB of address
    space; the plan takes 0.6-0.65 s of CPU in a fresh process here, 0.45 s of it the drift share's
    closed form (542 pairs of levels, each cached), and 41 MB."""

    r = run_capped(_PLAN_DRIFT, 1536 << 20, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.strip().splitlines()
    out = json.loads(lines[-1])
    cli = json.loads("\n".join(lines[:-1]))
    assert out["rc"] == 0
    assert out["required"]["N"] is not None and out["required"]["R"] is not None
    assert out["achieved"]["N"] <= 0.01 and out["achieved"]["R"] <= 0.20
    assert all(out["finite"].values()), out["finite"]
    assert out["cpu"] < 1.0, out
    assert out["maxrss_mb"] < 300, out  # about 40 MB here (the imports)
    assert [t["samples"] for t in cli["targets"]] == [out["required"]["N"], out["required"]["R"]]
