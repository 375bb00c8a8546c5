"""Fixtures shared by the core tests."""

import math

import pytest

DT = 1e-3


def _step_alongside(plant, ref, periods):
    """Step two plants of an n = 4 arm (3 active joints) with the same torques for ``periods``."""
    for k in range(periods):
        tau = [math.sin(3e-3 * k), 0.4, -0.2 * math.cos(2e-3 * k)]
        ref.step(tau, DT)
        plant.step(tau, DT)
        assert plant.last_disturbance == ref.last_disturbance


@pytest.fixture
def step_alongside():
    """Return ``f(plant, ref, periods)``: both stepped at 1 ms, the same disturbances checked."""
    return _step_alongside
