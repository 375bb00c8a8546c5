"""
What delay and share of missed states a spatial arm's real-time law tolerates, offline.

``bench/guard_margin.py`` for a spatial arm (``config/ur5``, ``config/panda`` or a directory
of ``fj arm init``): the law the real-time controller builds from the arm's files
(``freejoint_control.loop.config_law``, ``lockstep: false``: the null-space damping capped
for the readiness guard's delay), the arm's twin plant (``SpatialPlant``: its disturbance,
free-joint damping, RK4 step), the planner's circle then a hold, as
``freejoint_core.spatial_offline.run_twin`` runs them, but each command acting from tick
``k + delay + j_k`` (``j_k`` uniform in ``0 .. jitter``; the newest command arrived is
applied, a late one held) and states not answered in bursts (``freejoint_core.offline``'s
loss pattern: the previous command held one more period per state missed; the law's next
step takes the stamps' gap as dt, at most 4 periods, as the node clamps it). A setting is
tolerated when every seed stays within the bound ``make soak`` judges the arm by (1.5 x the
worst max error of the lockstep twin over the seeds) and every joint below the speed the
controller's state reader refuses (``joint_velocity_limit``: the URDF's, wide on a free
joint; a light wrist spinning in the null space hardly moves the tip). Prints a row per
setting; nothing asserted; figures depend on the machine only through the last bits.

    python bench/guard_margin_spatial.py                       # config/ur5, seeds 0-2
    python bench/guard_margin_spatial.py --arm config/panda --delays 1 2 --rates 0.05

Exit code 0 whatever the figures (a benchmark).
"""

import argparse
import os
import sys
import time

from freejoint_control.loop import config_law
from freejoint_control.params import SCHEMA
from freejoint_core.errors import FreejointValueError
from freejoint_core.offline import loss_pattern, pipeline_step
from freejoint_core.spatial_offline import circle
from freejoint_core.spatial_plant import SpatialPlant
from freejoint_planner.spatial_planning import plane_normal
from freejoint_tools.arm_twin import arm_configs, arm_info
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BOUND_FACTOR = 1.5
"""The soak's bound: 1.5 x the lockstep twin's worst max error over the seeds."""
DIVERGED_M = 0.5
"""Tip error [m] at which a run stops as diverged (the offline runners' 0.5 m)."""


def run(arm, seed, delay=0, jitter=0, rate=0.0, burst=1, hold_s=1.0, lockstep=False):
    """
    Return ``(max error [mm], diverged, worst joint speed / the controller's limit)`` of a run.

    ``delay`` = 0 with no jitter and no loss and ``lockstep``: the lockstep twin's run
    (the law without the real-time cap, each command acting over its own tick).
    """
    sim, ctl, plan = arm_configs(arm, os.path.join(ROOT, 'config'))
    cfg = SCHEMA.config(dict(ctl.values, lockstep=lockstep))
    law = config_law(cfg)
    vlim = np.asarray(cfg.velocity_limit, dtype=float)     # what the state reader refuses
    real, dt = sim.arm.spatial, sim.dt
    plant = SpatialPlant(real, sim.dt_sub, sim.dist_bound, seed, sim.q0,
                         passive_damping=sim.passive_damping)
    p0 = real.fk(np.asarray(sim.q0, dtype=float))
    duration, radius = float(plan['duration']), float(plan['radius'])
    normal = plane_normal(plan['plane_normal'])
    n = int(round((duration + hold_s) / dt))
    missed = loss_pattern(rate, burst, n, seed)
    jit = np.random.default_rng([7919, seed]).integers(0, jitter + 1, n).tolist() \
        if jitter else [0] * n
    tau_buf, arrive, applied = [None] * n, [], []
    worst = speed = 0.0
    last_k = 0
    for k in range(n):
        q, qd = plant.q, plant.qd
        p_d, v_d, a_d = circle(p0, radius, k * dt, duration, normal)
        if k in missed:
            tau_buf[k] = tau_buf[k - 1]
            err = float(np.linalg.norm(real.fk(q) - p_d))
        else:
            dt_law = min(k - last_k, 4) * dt if k else dt
            last_k = k
            out = law.step(q.tolist(), qd.tolist(), p_d.tolist(), v_d.tolist(), a_d.tolist(),
                           dt_law)
            tau_buf[k] = out.tau
            err = float(np.linalg.norm(out.e))
        worst = max(worst, err)
        if err > DIVERGED_M:
            return 1e3 * worst, True, speed
        try:
            if delay or jitter or missed:
                pipeline_step(plant, tau_buf, arrive, applied, k, delay + jit[k], dt)
            else:
                plant.step(tau_buf[k], dt)
        except FreejointValueError:
            return 1e3 * worst, True, speed
        speed = max(speed, float(np.max(np.abs(plant.qd) / vlim)))
    return 1e3 * worst, False, speed


def main(argv=None):
    ap = argparse.ArgumentParser(prog='guard_margin_spatial',
                                 description=__doc__.strip().splitlines()[0])
    ap.add_argument('--arm', default=os.path.join(ROOT, 'config', 'ur5'))
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--delays', nargs='+', type=int, default=[1, 2, 3],
                    help='least delays [periods] (1: a command acts the period after its state)')
    ap.add_argument('--jitter', type=int, default=0, help='0..J periods more (default 0)')
    ap.add_argument('--rates', nargs='+', type=float, default=[0.0, 0.05, 0.1, 0.2])
    ap.add_argument('--bursts', nargs='+', type=int, default=[1, 5])
    ap.add_argument('--hold', type=float, default=1.0, help='hold after the circle [s]')
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    seeds = range(args.seeds)
    base = [run(args.arm, s, hold_s=args.hold, lockstep=True) for s in seeds]
    bound = BOUND_FACTOR * max(b[0] for b in base)
    print('%s: lockstep twin worst max %.3f mm over seeds 0-%d (circle + %g s hold): bound '
          '%.3f mm' % (arm_info(args.arm)['spatial'], bound / BOUND_FACTOR, args.seeds - 1,
                       args.hold, bound))
    for delay in args.delays:
        for rate in args.rates:
            for burst in (args.bursts if rate else [1]):
                recs = [run(args.arm, s, delay, args.jitter, rate, burst, args.hold)
                        for s in seeds]
                within = sum(not d and mx <= bound and v < 1.0 for mx, d, v in recs)
                print('delay %d-%d periods, %3.0f %% missed in bursts of %2d: worst max %9.3f '
                      'mm, %d diverged, peak speed %.2f of the limit, %d/%d within' % (
                          delay, delay + args.jitter, rate * 100, burst,
                          max(r[0] for r in recs), sum(r[1] for r in recs),
                          max(r[2] for r in recs), within, len(recs)), flush=True)
    print('%.0f s wall' % (time.perf_counter() - t0))
    return 0


if __name__ == '__main__':
    sys.exit(main())
