"""
Benchmark: control-law tick and plant period cost, and the plant step-size study.

Figures (printed; nothing is asserted):

* the paper's law's step (``make_law('robust')``) per tick for the Table I nominal
  3-link arm (scalar kernel, target 20 us) and the general numpy path (reference);
* ``Plant.step`` per 1 ms control period at ``DEFAULT_DT_SUB`` (scalar kernel,
  target 50 us), at 1 ms, and on the general numpy path (reference);
* step-size study: the change of the results when ``dt_sub`` is made 10x
  finer, for a 5-s free swing with disturbance (vertical, no torque; chaotic,
  so the worst case) and for the 5-s robust closed loop on the paper's circle
  (tracking error, target 1e-6 mm).

Timings: ``core_timing.per_call_us``.  Usage:
``PYTHONPATH=src/freejoint_core python bench/core_law_plant.py``.
"""

import math

from core_timing import per_call_us, print_rows
from freejoint_core.arm import NOMINAL_SCALE, table1
from freejoint_core.control import Gains
from freejoint_core.laws import make_law
from freejoint_core.models import make_model
from freejoint_core.plant import DEFAULT_DT_SUB, Plant
from freejoint_core.trajectory import CircleQuintic
import numpy as np

DT = 1e-3
Q3_0 = math.radians(120.0)


def _tick_timing(use_fast, calls):
    ctl = make_law('robust', table1('vertical').scaled(NOMINAL_SCALE), Gains(),
                   use_fast=use_fast)
    q = np.array([0.3, 1.2, 2.0])
    qd = np.array([0.4, -0.3, 0.8])
    p_d, pd_d, pdd_d = np.array([0.2, 0.05]), np.array([0.1, 0.2]), np.array([0.5, -0.4])
    return per_call_us(lambda: ctl.step(q, qd, p_d, pd_d, pdd_d, DT), calls)


def _plant_timing(dt_sub, use_fast, calls):
    plant = Plant(table1('vertical'), dt_sub, dist_bound=0.5, seed=0,
                  q0=[0.3, 1.2, 2.0], use_fast=use_fast)
    tau = np.array([0.5, -0.2])
    return per_call_us(lambda: plant.step(tau, DT), calls)


def _free_swing(dt_sub, seconds=5.0):
    plant = Plant(table1('vertical'), dt_sub, dist_bound=0.5, seed=3, q0=[0.3, 1.2, -0.8])
    for _ in range(round(seconds / DT)):
        plant.step((0.0, 0.0), DT)
    return np.concatenate([plant.q, plant.qd])


def _closed_loop(case, dt_sub, seconds=5.0, seed=0):
    """Robust controller, 70 % nominal, disturbance, paper circle; returns e(t) (N, 2) [m]."""
    real = table1(case)
    traj = CircleQuintic()
    q0 = make_model(real).ik(traj.sample(0.0)[0], [Q3_0], 1)
    plant = Plant(real, dt_sub, dist_bound=0.5, seed=seed, q0=q0)
    ctl = make_law('robust', real.scaled(NOMINAL_SCALE), Gains())
    errors = []
    for k in range(round(seconds / DT)):
        p, pd, pdd = traj.sample(k * DT)
        out = ctl.step(plant.q, plant.qd, p, pd, pdd, DT)
        errors.append(out.e)
        plant.step(out.tau, DT)
    return np.array(errors)


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    rows = [
        {'name': 'control law tick, 3-link Table I nominal (scalar kernel)',
         'value': _tick_timing(True, 20000), 'unit': 'us', 'target': '<= 20'},
        {'name': 'control law tick, general numpy path (reference)',
         'value': _tick_timing(False, 500), 'unit': 'us', 'target': None},
        {'name': f'plant per 1 ms period, dt_sub = {DEFAULT_DT_SUB * 1e3:g} ms (default)',
         'value': _plant_timing(DEFAULT_DT_SUB, True, 5000), 'unit': 'us', 'target': '<= 50'},
        {'name': 'plant per 1 ms period, dt_sub = 1 ms',
         'value': _plant_timing(1e-3, True, 5000), 'unit': 'us', 'target': None},
        {'name': f'plant per 1 ms period, dt_sub = {DEFAULT_DT_SUB * 1e3:g} ms, general numpy',
         'value': _plant_timing(DEFAULT_DT_SUB, False, 100), 'unit': 'us', 'target': None},
    ]
    for dt_sub in (1e-3, DEFAULT_DT_SUB):
        diff = np.abs(_free_swing(dt_sub) - _free_swing(dt_sub / 10.0)).max()
        rows.append({'name': f'free swing 5 s vertical+dist: |dx| dt_sub {dt_sub * 1e3:g} ms '
                             'vs /10', 'value': float(diff), 'unit': 'rad', 'target': None})
    for case in ('horizontal', 'vertical'):
        for dt_sub in (1e-3, DEFAULT_DT_SUB):
            diff = np.abs(_closed_loop(case, dt_sub) - _closed_loop(case, dt_sub / 10.0)).max()
            target = '<= 1e-6' if dt_sub == DEFAULT_DT_SUB else None
            rows.append({'name': f'closed loop 5 s {case}: max |de| dt_sub {dt_sub * 1e3:g} ms '
                                 'vs /10', 'value': float(diff) * 1e3, 'unit': 'mm',
                         'target': target})
    return rows


def main():
    """Print the table."""
    print_rows(run())


if __name__ == '__main__':
    main()
