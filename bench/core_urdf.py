"""
Benchmark: the URDF arm models, Pinocchio per tick and the MuJoCo plant per period.

Figures (printed; nothing is asserted):

* ``PinArmModel.terms`` (M, h = C qd + G, J, Jdot qd, fk from one Pinocchio pass) per
  tick, for the shipped Table I URDF and the 4-link example, and
  ``PinArmModel.decoupling`` (Da, b) per tick, with the closed-form models'
  ``decoupling`` beside them for reference;
* ``MujocoPlant.step`` and ``PinPlant.step`` (RK4 on Pinocchio's ABA) per 1 ms control
  period at ``DEFAULT_DT_SUB`` (3-link and 4-link), with the RK4 ``Plant`` of the same
  arms for reference;
* the closed loop of the 4-link example per tick (law on the Pinocchio nominal model +
  RK4 plant on Pinocchio's ABA, ``urdf_offline.run_arm``), against the 1 kHz budget;
* agreement: the largest difference Pinocchio - closed form (M, Cqd, G, J, Jdot qd, fk)
  over random states, and the closed loop on the paper's circle on MuJoCo vs RK4
  (largest end-effector difference over the 5000 ticks, mm), both cases.

Timings: ``core_timing.per_call_us``.
Usage: ``python bench/core_urdf.py`` in the workspace (``. tools/env.sh``).
"""

import time

from core_timing import per_call_us, print_rows
from freejoint_core import offline
from freejoint_core.arm import ArmModel, NOMINAL_SCALE, table1
from freejoint_core.models import make_model
from freejoint_core.mujoco_plant import MujocoPlant
from freejoint_core.pin_model import PinArmModel
from freejoint_core.pin_plant import PinPlant
from freejoint_core.plant import DEFAULT_DT_SUB, Plant
from freejoint_core.trajectory import CircleQuintic
from freejoint_core.urdf import four_link_arm, FOUR_LINK_CIRCLE, FOUR_LINK_Q0
from freejoint_core.urdf import paper_arm
from freejoint_core.urdf_offline import run_arm
import numpy as np

DT = 1e-3


def _state(n):
    rng = np.random.default_rng(1)
    return rng.uniform(-np.pi, np.pi, n), rng.uniform(-2.0, 2.0, n)


def _model_timings(arm, label, calls):
    pin_model = PinArmModel(arm, scale=NOMINAL_SCALE)
    ref = make_model(arm.nominal(NOMINAL_SCALE))
    q, qd = _state(arm.params.n)
    kind = 'scalar kernel' if arm.params.n == 3 else 'general numpy'
    return [
        {'name': f'Pinocchio M, h, J, Jdot qd, fk per tick, {label}',
         'value': per_call_us(lambda: pin_model.terms(q, qd), calls), 'unit': 'us'},
        {'name': f'Pinocchio Da, b per tick, {label}',
         'value': per_call_us(lambda: pin_model.decoupling(q, qd), calls), 'unit': 'us'},
        {'name': f'closed-form Da, b per tick, {label} ({kind}, reference)',
         'value': per_call_us(lambda: ref.decoupling(q, qd), calls), 'unit': 'us'},
    ]


def _plant_timings(arm, label, q0, periods):
    tau = [0.1] * arm.params.r
    mj = MujocoPlant(arm, DEFAULT_DT_SUB, seed=0, q0=q0)
    pin_plant = PinPlant(arm, DEFAULT_DT_SUB, seed=0, q0=q0)
    rk4 = Plant(arm.params, DEFAULT_DT_SUB, seed=0, q0=q0)
    kind = 'scalar kernel' if arm.params.n == 3 else 'general numpy'
    return [
        {'name': f'MuJoCo plant per 1 ms period, dt_sub = {DEFAULT_DT_SUB * 1e3:g} ms, {label}',
         'value': per_call_us(lambda: mj.step(tau, DT), periods), 'unit': 'us'},
        {'name': f'RK4 plant on Pinocchio ABA per 1 ms period, {label}',
         'value': per_call_us(lambda: pin_plant.step(tau, DT), periods), 'unit': 'us'},
        {'name': f'RK4 plant per 1 ms period, {label} ({kind}, reference)',
         'value': per_call_us(lambda: rk4.step(tau, DT), max(periods // 10, 20)),
         'unit': 'us'},
    ]


def _closed_loop_per_tick_us(arm, ticks):
    start = time.perf_counter()
    record, trace = run_arm(arm, CircleQuintic(**FOUR_LINK_CIRCLE), FOUR_LINK_Q0,
                            n_ticks=ticks)
    elapsed = time.perf_counter() - start
    if len(trace['t']) != ticks:
        raise RuntimeError('the 4-link closed loop stopped after %d of %d ticks'
                           % (len(trace['t']), ticks))
    return 1e6 * elapsed / ticks


def _pin_agreement(states=200):
    worst = 0.0
    rng = np.random.default_rng(2)
    for case in ('horizontal', 'vertical'):
        pin_model = PinArmModel(paper_arm(case))
        refs = (ArmModel(table1(case)), make_model(table1(case)))
        for _ in range(states):
            q, qd = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-6.0, 6.0, 3)
            for ref in refs:
                for a, b in ((pin_model.mass_matrix(q), ref.mass_matrix(q)),
                             (pin_model.coriolis(q, qd), ref.coriolis(q, qd)),
                             (pin_model.gravity_torque(q), ref.gravity_torque(q)),
                             (pin_model.jacobian(q), ref.jacobian(q)),
                             (pin_model.jdot_qdot(q, qd), ref.jdot_qdot(q, qd)),
                             (pin_model.fk(q), ref.fk(q))):
                    worst = max(worst, float(np.max(np.abs(a - b))))
    return worst


def _closed_loop_agreement_mm(case):
    _, rk4 = offline.run_case(case, 'robust', 0, record_trace=True)
    arm = paper_arm(case)
    original = offline.Plant
    offline.Plant = lambda params, dt_sub, dist_bound=0.5, seed=0, q0=None: MujocoPlant(
        arm, dt_sub, dist_bound=dist_bound, seed=seed, q0=q0)
    try:
        _, mj = offline.run_case(case, 'robust', 0, record_trace=True)
    finally:
        offline.Plant = original
    return 1e3 * float(np.max(np.hypot(*(mj['p'] - rk4['p']).T)))


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    paper, four = paper_arm('vertical'), four_link_arm('horizontal')
    rows = _model_timings(paper, '3-link Table I URDF', 3000)
    rows += _model_timings(four, '4-link example URDF', 2000)
    rows += _plant_timings(paper, '3-link Table I URDF', offline.initial_state(table1('vertical')),
                           3000)
    rows += _plant_timings(four, '4-link example URDF', FOUR_LINK_Q0, 2000)
    rows.append({'name': 'law + plant per tick, 4-link example (Pinocchio), closed loop',
                 'value': _closed_loop_per_tick_us(four, 2000), 'unit': 'us',
                 'target': '<= 1000'})
    rows.append({'name': 'max |Pinocchio - closed form| (M, Cqd, G, J, Jdot qd, fk), Table I',
                 'value': _pin_agreement(), 'unit': '', 'target': '<= 1e-12'})
    for case in ('horizontal', 'vertical'):
        rows.append({'name': f'closed loop MuJoCo vs RK4 plant, paper circle, {case}',
                     'value': _closed_loop_agreement_mm(case), 'unit': 'mm',
                     'target': '<= 1e-6'})
    for row in rows:
        row.setdefault('target', None)
    return rows


def main():
    """Print the table."""
    print_rows(run(), width=72)


if __name__ == '__main__':
    main()
