"""The loop sizes the task-space terms by the law's model and refuses setpoints of other sizes."""
import os

from freejoint_control.loop import ControlLoop, STATUS_HOLDING
from freejoint_control.params import SCHEMA
from freejoint_core.control import STATUS_STALE_SETPOINT

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FILE = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'))
DT_NS = 1_000_000
NAMES = ['joint1', 'joint2', 'joint3']
Q0 = [-1.369438, 1.691679, 2.094395]
QD0 = [0.05, -0.1, 0.3]


def _loop(**given):
    values = dict(FILE)
    values.update(given)
    logs = []
    loop = ControlLoop(SCHEMA.config(values), lambda *line: logs.append(line))
    return loop, logs


def test_the_task_dimension_and_the_law_state_names_come_from_the_model_and_the_law():
    loop, _ = _loop()
    assert loop.task_dim == loop.law.model.task_dim == 2
    assert loop.result.law_state_names == tuple(loop.law.state_names)
    assert loop.result.position == loop.result.error == (0.0, 0.0)


def test_a_setpoint_of_another_size_is_refused_counted_and_named_in_the_hold():
    loop, logs = _loop(lockstep=False, readiness_guard=False)   # the guard: test_readiness
    assert loop.on_setpoint(0, (0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0, 100.0) is None
    assert loop.refused_setpoints == 1
    assert logs[-1][2] == ('setpoint stamped 0 ns refused: 9 values, expected 6 (position, '
                           'velocity, acceleration of 2 each); dropped')
    loop.refuse_setpoint(DT_NS, 'position, velocity, acceleration have 3, 2, 2 values, the '
                         'task dimension is 2')
    assert loop.refused_setpoints == 2
    res = loop.on_state(DT_NS, NAMES, Q0, QD0, DT_NS, 100.001)
    assert res.status & STATUS_HOLDING and not res.status & STATUS_STALE_SETPOINT
    assert 'last setpoint refused: position, velocity, acceleration have 3, 2, 2' in res.message
    assert len(res.position_desired) == len(res.error) == len(res.sliding) == 2
    assert len(res.law_state_values) == len(res.law_state_names) == 8


def test_the_gain_parameters_take_as_many_values_as_the_task_dimension():
    values = dict(FILE, K=[100.0, 100.0, 100.0])
    assert SCHEMA.reason(values) == ("K: expected 2 values (the task dimension of the arm's "
                                     'model), got [100.0, 100.0, 100.0]')
    assert SCHEMA.reason(dict(FILE, R=[-1.0, 1.0])).startswith('R: values must be finite and > 0')
    cfg = SCHEMA.config(dict(FILE))
    assert cfg.gains.task_dim == 2 and cfg.gains.K == tuple(FILE['K'])
