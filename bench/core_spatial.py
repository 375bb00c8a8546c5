"""
Benchmark: spatial arms from URDFs, per tick and per singularity sample.

Figures (printed; nothing is asserted):

* ``SpatialArm.terms`` (M, Minv, h, J, Jdot qd, placement; one Pinocchio pass) and
  ``decoupling`` (Da, b, M~aa) per tick, UR5 (wrist_2 free) and Panda (joint 7 free);
* the spatial law's step (``make_law('spatial')``) per tick (m = 3, weighted inverse,
  null-space damping), and the RK4 step of the plant on Pinocchio's ABA (4 ABA calls) at
  the same arms;
* the singularity criterion per sample: ``terms`` + ``decoupling`` +
  ``task_conditioning`` (kappa), and ``task_conditioning`` alone.

Timings: ``core_timing.per_call_us``.
Usage: ``python bench/core_spatial.py`` in the workspace (``. tools/env.sh``).
"""

from core_timing import per_call_us, print_rows
from freejoint_core.internal import NullSpace
from freejoint_core.laws import make_law
from freejoint_core.spatial_law import task_conditioning
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_offline import CASES
from freejoint_core.spatial_plant import SpatialPlant
import numpy as np

CALLS = 300


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
    print_rows(rows)


if __name__ == '__main__':
    main()
