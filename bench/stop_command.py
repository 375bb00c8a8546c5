"""
What a driver holding one command does to the arm: the stop command against the others.

Offline, no ROS. From the states of the paper's circle (robust, seed 0, every 0.25 s) the
real Table I arm is integrated for 2 s under one command held constant - the last tracking
command, zero, the nominal model's gravity load of the active joints (the controller's
stop command, ``freejoint_core.guards.hold_effort``), the exact load - and under the
damped joint hold answered live (``readiness_action: damp``, ``stop_hold_time`` 0.1 s:
``freejoint_core.guards.damped_hold_effort`` on the nominal load and inertia) with 30 % of
the states missed and a 1-3 ms delay. Prints per case and
command the end effector's largest travel from where it was and the fastest joint
(docs/real-time.md, "Stopping").

    python bench/stop_command.py
"""

import sys

from freejoint_core.arm import ArmModel, table1
from freejoint_core.arm_gains import active_inertia
from freejoint_core.guards import damped_hold_effort, hold_effort
from freejoint_core.offline import run_case
from freejoint_core.plant import Plant
import numpy as np

DT = 1e-3
HELD_S = 2.0
HOLD_TIME = 0.1


def held(real, q, qd, command, seed):
    """Return (largest end-effector travel [m], fastest joint [rad/s]) under ``command``."""
    model = ArmModel(real)
    plant = Plant(real, dist_bound=0.0, seed=seed, q0=q.tolist(), qd0=qd.tolist())
    p0 = model.fk(q)
    travel = fastest = 0.0
    for k in range(round(HELD_S / DT)):
        try:
            plant.step(command(k, plant), DT)
        except (ArithmeticError, ValueError):
            return float('inf'), float('inf')
        travel = max(travel, float(np.linalg.norm(model.fk(plant.q) - p0)))
        fastest = max(fastest, float(np.max(np.abs(plant.qd))))
    return travel, fastest


def damped(nominal, q_stop, rng):
    """Return the command of the damped joint hold, 30 % missed, a 1-3 ms delay."""
    model = ArmModel(nominal)
    sent = []

    def command(k, plant):
        if not sent or rng.random() > 0.3:
            q, qd = plant.q, plant.qd
            sent.append(damped_hold_effort(model.gravity_torque(q).tolist(), (0, 1),
                                           active_inertia(model, q), q, qd, q_stop,
                                           HOLD_TIME))
        else:
            sent.append(sent[-1])
        lag = 1 + int(rng.integers(0, 3))
        return sent[max(0, len(sent) - 1 - lag)]
    return command


def main():
    rng = np.random.default_rng(1)
    for case in ('horizontal', 'vertical'):
        _, trace = run_case(case, 'robust', 0, record_trace=True)
        real = table1(case)
        nominal = real.scaled(0.7)
        worst = {}
        for k in range(0, 5000, 250):
            q, qd, tau = trace['q'][k], trace['qd'][k], trace['tau'][k].tolist()
            loads = {'nominal load (stop command)': ArmModel(nominal), 'exact load':
                     ArmModel(real)}
            commands = {'last tracking command': lambda i, p: tau,
                        'zero': lambda i, p: [0.0, 0.0]}
            for name, model in loads.items():
                load = hold_effort(model.gravity_torque(q).tolist(), (0, 1))
                commands[name] = lambda i, p, load=load: load
            commands['damped joint hold, live'] = damped(nominal, q[:2].tolist(), rng)
            for name, command in commands.items():
                travel, fastest = held(real, q, qd, command, k)
                old = worst.get(name, (0.0, 0.0))
                worst[name] = (max(old[0], travel), max(old[1], fastest))
        for name, (travel, fastest) in worst.items():
            print('%-10s %-28s largest travel %6.0f mm, fastest joint %6.1f rad/s'
                  % (case, name, travel * 1e3, fastest))
    return 0


if __name__ == '__main__':
    sys.exit(main())
