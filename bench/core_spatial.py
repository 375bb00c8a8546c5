"""
Benchmark: spatial arms from URDFs, per tick and per singularity sample.

Figures (printed; nothing is asserted):

* ``SpatialArm.terms`` (M, Minv, h, J, Jdot qd, placement; one Pinocchio pass) and
  ``decoupling`` (Da, b, M~aa) per tick, UR5 (wrist_2 free) and Panda (joint 7 free);
* the spatial law's step (``make_law('spatial')``) per tick (m = 3, weighted inverse,
  null-space damping), and the RK4 step of the plant on Pinocchio's ABA (4 ABA calls) at
  the same arms;
* the singularity criterion per sample: ``terms`` + ``decoupling`` +
  ``task_conditioning`` (kappa), and ``task_conditioning`` alone;
* the controller's tick on the UR5 (``config/ur5``, real time, the readiness guard off):
  ``ControlLoop.on_setpoint`` + ``on_state`` per state, the law's step and the loop's
  checks, limits and Result (needs the workspace: ``freejoint_control``).

Timings: ``core_timing.per_call_us``.
Usage: ``python bench/core_spatial.py`` in the workspace (``. tools/env.sh``).
"""

import os

from core_timing import per_call_us, print_rows
from freejoint_core.internal import NullSpace
from freejoint_core.laws import make_law
from freejoint_core.spatial_law import task_conditioning
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_offline import CASES
from freejoint_core.spatial_plant import SpatialPlant
import numpy as np

CALLS = 300
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def loop_tick_rows():
    """Return the row of the UR5 controller loop's tick (none without the workspace)."""
    try:
        from freejoint_control.loop import ControlLoop
        from freejoint_control.params import SCHEMA
        from freejoint_tools.arm_twin import arm_configs
    except ImportError:
        return []
    sim, ctl, _ = arm_configs(os.path.join(ROOT, 'config', 'ur5'), os.path.join(ROOT, 'config'))
    loop = ControlLoop(SCHEMA.config(dict(ctl.values, lockstep=False, readiness_guard=False)))
    names = list(ctl.joint_names)
    rng = np.random.default_rng(0)
    states = [((np.array(sim.q0) + 0.01 * rng.standard_normal(6)).tolist(),
               (0.1 * rng.standard_normal(6)).tolist()) for _ in range(CALLS)]
    hold = sim.arm.spatial.fk(np.array(sim.q0)).tolist() + [0.0] * 6
    tick = [0]

    def one():
        k = tick[0] = tick[0] + 1
        ns = k * 1_000_000
        q, qd = states[k % CALLS]
        loop.on_setpoint(ns, hold, ns, 0.0)
        loop.on_state(ns, names, q, qd, ns + 300_000, 0.0)

    return [{'name': 'ur5: controller loop tick (real time, guard off)',
             'value': per_call_us(one, CALLS), 'unit': 'us', 'target': None}]


def main():
    """Print the figures."""
    rows = []
    for case, (name, free, plan) in sorted(CASES.items()):
        arm = known_arm(name, [free])
        q = np.array(plan)
        qd = np.full(arm.n, 0.1)
        terms = arm.terms(q, qd)
        da, _, maa = arm.decoupling(terms)
        law = make_law('spatial', arm.nominal(0.7), None, nullspace=NullSpace(
            kd=20.0, inverse='weighted', projector='dynamic'))
        p_d = arm.fk(q)
        zero3 = np.zeros(3)
        plant = SpatialPlant(arm, 5e-4, 0.5, 0, q)
        tau = np.zeros(arm.r)

        def sample(q=q):
            t = arm.terms(q, np.zeros(arm.n))
            d, _, w = arm.decoupling(t)
            return task_conditioning(d, w, 1.0)

        for label, fun in (
                ('terms', lambda: arm.terms(q, qd)),
                ('terms + decoupling', lambda: arm.decoupling(arm.terms(q, qd))),
                ('SpatialLaw.step (m = 3)', lambda: law.step(q, qd, p_d, zero3, zero3, 5e-4)),
                ('plant period of 1 ms (2 RK4 steps, 8 ABA)', lambda: plant.step(tau, 1e-3)),
                ('kappa per sample (terms + decoupling + kappa)', sample),
                ('task_conditioning alone', lambda: task_conditioning(da, maa, 1.0))):
            rows.append({'name': f'{case}: {label}', 'value': per_call_us(fun, CALLS),
                         'unit': 'us', 'target': None})
    print_rows(rows + loop_tick_rows())


if __name__ == '__main__':
    main()
