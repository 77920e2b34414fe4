"""Sample-count limits of the simulators: ``n`` is an integer >= 1, at
most 2^40, and at most what fits in half the available memory at 32 bytes per sample and
channel (engine._limits); the messages name the argument ``n`` and the largest accepted
count. Before, ``simulate(3e9)`` allocated for a minute and ``1e14`` ended in a MemoryError."""

from __future__ import annotations

import time

import numpy as np
import pytest

import engine as eg
from engine import _limits
from engine._limits import BYTES_PER_SAMPLE, MAX_SAMPLES, check_sample_count, max_samples
from engine.multivariate import MultiModel

GB23 = 23 * 10**9  # a reported machine: 23 GB


@pytest.fixture
def mem23(monkeypatch: pytest.MonkeyPatch) -> int:
    monkeypatch.setattr(_limits, "available_memory", lambda: GB23)
    return GB23 // 2 // BYTES_PER_SAMPLE  # 359 375 000 samples


def test_limit_formula(mem23: int) -> None:
    assert mem23 == 359_375_000
    assert max_samples() == mem23
    assert max_samples(channels=3) == GB23 // 2 // (3 * BYTES_PER_SAMPLE)
    assert max_samples(copies=2) == GB23 // 2 // (2 * BYTES_PER_SAMPLE)
    assert check_sample_count(mem23) == mem23  # the limit itself is accepted
    with pytest.raises(ValueError, match=f"use n <= {mem23}$"):
        check_sample_count(mem23 + 1)


def test_available_memory_is_meminfo() -> None:
    mem = _limits.available_memory()
    assert mem is not None and mem > 10**8  # this machine: some GB
    with open("/proc/meminfo") as fh:
        avail = [int(ln.split()[1]) * 1024 for ln in fh if ln.startswith("MemAvailable:")]
    assert abs(mem - avail[0]) < 0.2 * avail[0]  # read again a moment later: close


@pytest.mark.parametrize(
    ("n", "match"),
    [
        (True, "whole number"),
        (2.5, "whole number"),
        (1e5, "whole number"),  # a float, even an integral one: the caller converts
        ("100", "whole number"),
        (0, "at least 1"),
        (-3, "at least 1"),
        (10**14, r"n = 1e\+14 samples is beyond any simulation"),
        (MAX_SAMPLES + 1, "beyond any simulation"),
    ],
)
def test_bad_counts(n: object, match: str) -> None:
    with pytest.raises(ValueError, match=match) as e:
        check_sample_count(n)
    assert str(e.value).startswith("n ")  # the argument's name, for the CLI to translate
    assert check_sample_count(np.int64(7)) == 7 and check_sample_count(7) == 7


def test_every_simulator_refuses_before_allocating(mem23: int) -> None:
    model = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-6)+GM(beta=0.1, sigma2_gm=1)")
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"n = 3000000000 samples would need about 96 GB"):
        model.simulate(3_000_000_000)
    for p in model.processes:  # each process's own simulator too
        with pytest.raises(ValueError, match="n = 3000000000"):
            p.simulate(3_000_000_000)
    with pytest.raises(ValueError, match="beyond any simulation"):
        model.simulate(10**14)
    mm = MultiModel(["a", "b", "c"], "WN(sigma2=1)")
    with pytest.raises(ValueError, match=r"x 3 channels\), more than 50% of the 23 GB"):
        mm.simulate(mem23 // 3 + 1)
    assert time.perf_counter() - t0 < 1.0  # refused, not attempted
    x = model.simulate(1000, rng=1)  # small counts unchanged
    assert x.shape == (1000,) and np.isfinite(x).all()
