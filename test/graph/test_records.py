"""The graph's per-tick arrays from messages (shared by the demo and the bag analysis)."""
from types import SimpleNamespace as NS

from freejoint_common.contract import stamp_from_ns
from freejoint_common.records import arrays_from_messages, stamp_ns, theta_hat
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


ROBUST_NAMES = ['theta_hat[%d]' % i for i in range(5)] + ['rho_hat', 'delta_v[0]', 'delta_v[1]']


def test_theta_hat_is_read_from_the_generic_law_state_by_name_or_from_the_old_field():
    new = NS(law_state_names=ROBUST_NAMES, law_state=[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
    assert theta_hat(new) == (1.0, 2.0, 3.0, 4.0, 5.0)
    shuffled = NS(law_state_names=['z'] + ROBUST_NAMES[::-1],
                  law_state=[9.0, 8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0])
    assert theta_hat(shuffled) == (1.0, 2.0, 3.0, 4.0, 5.0)
    assert theta_hat(NS(law_state_names=['z[0]'], law_state=[1.0])) == (0.0,) * 5
    assert theta_hat(NS(theta_hat=[0.5] * 5)) == (0.5,) * 5          # the old layout


def test_new_layout_states_give_the_same_arrays_as_old_layout_states():
    old = [_state(k) for k in range(3)]
    new = []
    for k in range(3):
        s = _state(k)
        del s.theta_hat
        s.law_state_names = ROBUST_NAMES
        s.law_state = [0.1 * k] * 5 + [0.0, 0.0, 0.0]
        new.append(s)
    joints = [_joints(k) for k in range(3)]
    a, b = arrays_from_messages(old, joints, 'joint3'), arrays_from_messages(new, joints, 'joint3')
    assert set(a) == set(b) and all(np.array_equal(a[key], b[key]) for key in a)
