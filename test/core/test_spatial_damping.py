"""
A failed joint's drivetrain in the spatial plant: ``passive_damping``.

The damping is checked against the arm's energy, not against the code's own formula: with
no gravity, no disturbance and no actuator torque, the kinetic energy ``0.5 qd' M(q) qd``
(Pinocchio's mass matrix) is conserved by the frictionless plant and falls by exactly the
work of ``-b qd_p`` on the free joint with damping. MuJoCo's plant with its own joint damping
is the Pinocchio plant to round-off, and bad values are refused naming the argument.
"""
import math
import os

from freejoint_core.errors import FreejointValueError
from freejoint_core.mujoco_plant import SpatialMujocoPlant
from freejoint_core.spatial_model import KNOWN_ARMS, robot_data_dir, SpatialArm
from freejoint_core.spatial_offline import CASES
from freejoint_core.spatial_plant import SpatialPlant
import numpy as np
import pytest

DT = 0.0005


def _weightless(name, free):
    """Return the example arm with its joint ``free`` free and no gravity."""
    path, base, tip = KNOWN_ARMS[name]
    return SpatialArm(os.path.join(robot_data_dir(), path), base, tip, [free],
                      gravity=(0.0, 0.0, 0.0))


def _energy(arm, q, qd):
    return 0.5 * float(qd @ arm.terms(q, qd).M @ qd)


def _coast(arm, damping, seconds=0.4):
    """Let the arm coast from a spinning free joint; return energies and free-joint rates."""
    q0 = np.array(CASES['panda_j7'][2])
    qd0 = np.full(arm.n, 0.1)
    qd0[arm.passive[0]] = 3.0
    plant = SpatialPlant(arm, DT, dist_bound=0.0, q0=q0, qd0=qd0, passive_damping=damping)
    rates, energy = [plant.qd[arm.passive[0]]], [_energy(arm, plant.q, plant.qd)]
    for _ in range(int(round(seconds / DT))):
        plant.step(np.zeros(arm.r), DT)
        rates.append(plant.qd[arm.passive[0]])
        energy.append(_energy(arm, plant.q, plant.qd))
    return np.array(energy), np.array(rates)


def test_without_damping_a_coasting_arm_keeps_its_kinetic_energy():
    energy, _ = _coast(_weightless('panda', 'panda_joint7'), 0.0)
    assert abs(energy[-1] - energy[0]) <= 1e-9 * energy[0]


def test_the_energy_a_damped_free_joint_loses_is_the_work_of_its_damping_torque():
    b = 1.0
    energy, rates = _coast(_weightless('panda', 'panda_joint7'), b)
    # work of -b w over the run, Simpson's rule on the 0.5-ms samples (an even number)
    w2 = rates ** 2
    work = b * DT / 3.0 * (w2[0] + w2[-1] + 4.0 * w2[1:-1:2].sum() + 2.0 * w2[2:-1:2].sum())
    lost = energy[0] - energy[-1]
    assert lost > 0.01 * energy[0]                      # the damping did take energy out
    assert abs(lost - work) <= 1e-4 * lost, (lost, work)     # quadrature: 4e-6 here
    assert abs(rates[-1]) < abs(rates[0])


@pytest.mark.parametrize('name, free', [('panda', 'panda_joint7'), ('ur5', 'wrist_2_joint')])
def test_mujocos_joint_damping_is_the_pinocchio_plants_damping_to_round_off(name, free):
    path, base, tip = KNOWN_ARMS[name]
    arm = SpatialArm(os.path.join(robot_data_dir(), path), base, tip, [free])
    q0 = np.array(CASES['panda_j7' if name == 'panda' else 'ur5_wrist2'][2])
    qd0 = np.zeros(arm.n)
    qd0[arm.passive[0]] = 2.0
    one = SpatialPlant(arm, DT, dist_bound=0.5, seed=4, q0=q0, qd0=qd0, passive_damping=2.5)
    two = SpatialMujocoPlant(arm, DT, dist_bound=0.5, seed=4, q0=q0, qd0=qd0,
                             passive_damping=2.5)
    active = list(arm.active)
    for k in range(300):
        tau = arm.gravity_torque(one.q)[active] + 0.5 * np.sin(0.01 * k + np.arange(arm.r))
        one.step(tau, 0.001)
        two.step(tau, 0.001)
    np.testing.assert_allclose(two.q, one.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(two.qd, one.qd, rtol=0, atol=1e-12)
    # and the damping acted: the same run without it ends elsewhere
    free_run = SpatialPlant(arm, DT, dist_bound=0.5, seed=4, q0=q0, qd0=qd0)
    for k in range(300):
        tau = arm.gravity_torque(free_run.q)[active] + 0.5 * np.sin(
            0.01 * k + np.arange(arm.r))
        free_run.step(tau, 0.001)
    assert abs(free_run.q[arm.passive[0]] - one.q[arm.passive[0]]) > 0.05


def test_damping_acts_on_the_free_joints_only():
    path, base, tip = KNOWN_ARMS['ur5']
    arm = SpatialArm(os.path.join(robot_data_dir(), path), base, tip, ['wrist_2_joint'])
    plant = SpatialPlant(arm, DT, passive_damping=1.5)
    assert plant.damping.tolist() == [0.0, 0.0, 0.0, 0.0, 1.5, 0.0]


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf, 'x', None])
def test_a_bad_damping_is_refused_naming_passive_damping(bad):
    path, base, tip = KNOWN_ARMS['ur5']
    arm = SpatialArm(os.path.join(robot_data_dir(), path), base, tip, ['wrist_2_joint'])
    with pytest.raises(FreejointValueError, match=r'^passive_damping: '):
        SpatialPlant(arm, DT, passive_damping=bad)
    with pytest.raises(FreejointValueError, match=r'^passive_damping: '):
        SpatialMujocoPlant(arm, DT, passive_damping=bad)
