"""The vertices of the bound's feasible set ``{y >= 0 : b y >= 1}`` (engine.formats.bound.
lower_vertices, the exact core of the least-inflation bound) against brute force: every
intersection of two constraint lines or of one with an axis that satisfies all constraints."""

from __future__ import annotations

import numpy as np
import pytest

import engine as eg
from engine.formats.bound import columns, fine_scales, lower_vertices


def brute_vertices(b: np.ndarray) -> np.ndarray:
    """All feasible points where two of the constraints (rows of b, or y0 = 0, y1 = 0) are
    tight (Cramer's rule on every pair), deduplicated; O(n^3)."""
    r = np.vstack([b, [[1.0, 0.0], [0.0, 1.0]]])
    c = np.concatenate([np.ones(len(b)), [0.0, 0.0]])
    i, j = np.triu_indices(len(r), 1)
    det = r[i, 0] * r[j, 1] - r[i, 1] * r[j, 0]
    ok = np.abs(det) > 1e-14 * np.maximum(np.abs(r[i]).max(1), np.abs(r[j]).max(1)) ** 2
    i, j, det = i[ok], j[ok], det[ok]
    y = np.column_stack(
        [(c[i] * r[j, 1] - c[j] * r[i, 1]) / det, (r[i, 0] * c[j] - r[j, 0] * c[i]) / det]
    )
    feas = np.all(y >= -1e-12, axis=1) & np.all(b @ y.T >= 1 - 1e-9, axis=0)
    return _dedup(y[feas])


def _dedup(v: np.ndarray) -> np.ndarray:
    v = v[np.lexsort((v[:, 1], v[:, 0]))]
    out = [v[0]]
    for p in v[1:]:
        if not np.allclose(p, out[-1], rtol=1e-9, atol=1e-12):
            out.append(p)
    return np.array(out)


@pytest.mark.parametrize("seed", range(40))
def test_vertices_equal_brute_force_on_random_rows(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    b = np.exp(rng.normal(size=(n, 2)) * rng.uniform(0.1, 3.0))
    if seed % 4 == 0:
        b[n // 2 :] = b[: n - n // 2]  # duplicated rows
    v = lower_vertices(b)
    assert np.all(b @ v.T >= 1 - 1e-9)  # every vertex feasible
    assert v[0, 0] == 0.0 and v[-1, 1] == 0.0  # from the y1 axis to the y0 axis
    assert np.all(np.diff(v[:, 0]) >= 0) and np.all(np.diff(v[:, 1]) <= 0)
    np.testing.assert_allclose(_dedup(v), brute_vertices(b), rtol=1e-8, atol=1e-12)


def test_vertices_of_a_gauss_markov_consumer_over_six_decades():
    """The case that made exports slow: a WN+GM consumer (T_c 1000 s) on the fine
    grid of a 0.02 s .. 10^4 s band over the demo gyro_x's true 2*GM+WN+RW WV, 5 % higher at
    the dyadic scales (a data floor): hundreds of rows, a hundred of them hull vertices."""
    fs = 100.0
    truth = "GM(beta=0.01, sigma2_gm=9e-6)+GM(beta=0.5, sigma2_gm=1.6e-5)+WN(sigma2=2.5e-3)"
    tau = fine_scales(np.unique(2 * np.round(np.geomspace(2, 1e6, 115) / 2)))
    a = columns("WN+GM", tau, fs, 1000.0)
    target = eg.parse_model(truth + "+RW(gamma2=2.1e-11)").wv(tau, fs)
    target[np.isin(tau, 2.0 ** np.arange(1, 20))] *= 1.05
    b = a / target[:, None]
    b = (b / b.max(axis=0))[::3]  # every third row: brute force is O(n^3)
    v = lower_vertices(b)
    assert len(b) > 200 and len(_dedup(v)) > 100
    np.testing.assert_allclose(_dedup(v), brute_vertices(b), rtol=1e-7)
