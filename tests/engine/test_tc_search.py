"""The correlation-time search of a Gauss-Markov bias (engine.formats.bound.solve): the
exported ``T_c`` minimises the least-inflation objective along ``log T_c`` to the search's
tolerance (1e-4 in ``log T_c``), on a real log where the objective has two minima between
two neighbouring points of the search's coarse grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

import engine as eg
from engine.formats import project
from engine.formats.projection import log_inflation_at_tc
from engine.formats.tails import log_tail_factors


@pytest.fixture(scope="module")
def accel_x(real_data):
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    fit = eg.fit_gmwm(log.wavelet_variance("accel_x"), "2*GM+WN+RW")
    return fit, log_tail_factors(log, ["accel_x"])["accel_x"]


@pytest.mark.real_data
def test_the_exported_tc_is_a_local_minimum_of_the_objective(accel_x) -> None:
    """ADIS16405 imu1 accel_x: between the grid points 585 s and 4,537 s the objective (log of
    the geometric-mean inflation at a fixed ``T_c``) has minima at about 1,486 s (0.9936) and
    2,466 s (1.0247); the grid point 1,635 s (1.0085) lies on the first one's slope. The
    bounded search of the whole bracket ended in the second (above the grid point) and the old
    code kept the grid point, where the objective still falls towards shorter ``T_c`` (1.0083
    at -1e-3 in log ``T_c``)."""
    fit, tails = accel_x
    p = project(fit, "WN+GM", channel="accel_x", tails=tails, ci=None)
    tc = p.value("T_c")
    # the objective at the exported T_c is the projection's own
    f0 = float(log_inflation_at_tc(fit, [tc], channel="accel_x", tails=tails)[0])
    assert math.log(p.inflation["geometric_mean"]) == pytest.approx(f0, rel=1e-9)
    # no lower value within 10x and 100x the search's tolerance on either side
    d = np.array([-1e-2, -3e-3, -1e-3, 1e-3, 3e-3, 1e-2])
    near = log_inflation_at_tc(fit, tc * np.exp(d), channel="accel_x", tails=tails)
    assert np.all(near > f0), (tc, f0, near)
    # and none on a scan of +-0.05 in log T_c finer than the grid's bracket: the objective's
    # slope here is at most 0.6 per unit of log T_c, so within the tolerance 1e-4 of the
    # minimum it is at most 6e-5 above it
    scan = log_inflation_at_tc(
        fit, tc * np.exp(np.linspace(-0.05, 0.05, 201)), channel="accel_x", tails=tails
    )
    assert f0 <= float(np.min(scan)) + 1e-4, (tc, f0, float(np.min(scan)))
    assert 1400.0 < tc < 1600.0
