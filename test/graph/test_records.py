"""The graph's per-tick arrays from messages (shared by the demo and the bag analysis)."""
from types import SimpleNamespace as NS

from freejoint_common.contract import stamp_from_ns
from freejoint_common.records import arrays_from_messages, stamp_ns
from freejoint_core.metrics import compute_record
import numpy as np
import pytest

DT_NS = 1_000_000


def _header(k):
    return NS(stamp=stamp_from_ns(k * DT_NS))


def _state(k, effort=None):
    return NS(header=_header(k), position=[0.2 + k, 0.01 * k], position_desired=[0.2, 0.0],
              effort=effort if effort is not None else [float(k), -float(k)],
              theta_hat=[0.1 * k] * 5, det_dd=1.0 + k)


def _joints(k, names=('joint1', 'joint2', 'joint3'), q3=None):
    pos = {'joint1': -1.0, 'joint2': 1.0, 'joint3': 2.0 + 0.01 * k if q3 is None else q3,
           'gripper': 9.0}
    return NS(header=_header(k), name=list(names), position=[pos[n] for n in names])


def test_ticks_are_paired_by_stamp_in_stamp_order_whatever_the_arrival_order():
    states = [_state(2), _state(0), _state(1)]
    joints = [_joints(1), _joints(0, ('gripper', 'joint3', 'joint1', 'joint2')), _joints(2)]
    arrays = arrays_from_messages(states, joints, 'joint3')
    assert arrays['t'].tolist() == [0.0, 0.001, 0.002]
    assert arrays['q_passive'].tolist() == [2.0, 2.01, 2.02]
    assert arrays['tau'].tolist() == [[0.0, -0.0], [1.0, -1.0], [2.0, -2.0]]
    assert arrays['det'].tolist() == [1.0, 2.0, 3.0]
    assert arrays['theta'].shape == (3, 5) and arrays['p'].shape == (3, 2)
    record = compute_record('horizontal', 'robust', 0, source='graph', **arrays)
    assert record['q3_range_deg'] == pytest.approx(np.degrees([2.0, 2.02]).tolist())
    assert record['tau_peak_nm'] == [2.0, 2.0]


def test_the_first_message_of_a_repeated_stamp_counts_and_unpaired_ticks_are_left_out():
    states = [_state(0), _state(0, effort=[0.0, 0.0]), _state(1), _state(2)]
    joints = [_joints(0), _joints(0, q3=5.0), _joints(1), _joints(3)]
    arrays = arrays_from_messages(states, joints, 'joint3')
    assert arrays['t'].tolist() == [0.0, 0.001]
    assert arrays['tau'][0].tolist() == [0.0, -0.0]
    assert arrays['q_passive'][0] == 2.0
    assert arrays_from_messages(states, joints, 'joint3', max_ticks=1)['t'].tolist() == [0.0]


def test_no_tick_with_the_passive_joint_is_an_error_naming_it():
    with pytest.raises(ValueError, match='no tick has both a ControllerState and a '
                                         "JointState with 'joint9'"):
        arrays_from_messages([_state(0)], [_joints(0)], 'joint9')


def test_stamp_ns_reads_the_header():
    assert stamp_ns(_state(1234)) == 1_234_000_000
