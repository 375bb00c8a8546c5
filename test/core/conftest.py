"""Fixtures shared by the core tests."""

import math

from freejoint_core.errors import PlantDivergedError
import numpy as np
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


def _diverges_keeping_state(plant, huge):
    """Step ``plant`` (k = 0, r = 2) once, then with ``[huge, -huge]``: refused, state kept."""
    plant.step([1.0, 1.0], DT)
    q, qd = plant.q, plant.qd
    with pytest.raises(PlantDivergedError, match='tau_active: the integration over step 1'):
        plant.step([huge, -huge], DT)
    np.testing.assert_array_equal(plant.q, q)
    np.testing.assert_array_equal(plant.qd, qd)
    assert plant.k == 1


@pytest.fixture
def diverges_keeping_state():
    """Return ``f(plant, huge)``: a diverging step is refused and the state kept."""
    return _diverges_keeping_state
