"""ControllerState's generic law state reads back with rosbags (what the analysis decodes)."""
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MSG = os.path.join(ROOT, 'src', 'freejoint_msgs', 'msg', 'ControllerState.msg')
TYPE = 'freejoint_msgs/msg/ControllerState'


@pytest.mark.parametrize('names', [(), ('theta_hat[0]', 'theta_hat[1]', 'theta_hat[2]',
                                        'theta_hat[3]', 'theta_hat[4]', 'rho_hat',
                                        'delta_v[0]', 'delta_v[1]')],
                         ids=['stateless law', 'robust'])
def test_the_controllers_state_of_any_law_reads_back_with_rosbags(names):
    from rclpy.serialization import serialize_message
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores

    from freejoint_msgs.msg import ControllerState
    store = get_typestore(Stores.ROS2_JAZZY)
    with open(MSG) as fh:
        store.register(get_types_from_msg(fh.read(), TYPE))
    msg = ControllerState()
    # As the controller fills it: m = 2 task values each, the law's names and values.
    msg.error, msg.error_rate, msg.sliding = [1e-3, -2e-3], [0.1, 0.2], [0.15, 0.1]
    msg.position, msg.position_desired = [0.2, 0.0], [0.2, 1e-3]
    msg.law_state_names = list(names)
    msg.law_state = [0.5 * i for i in range(len(names))]
    msg.effort, msg.joint_names = [3.0, -1.0], ['joint1', 'joint2']
    msg.message, msg.dt = 'near singular', 1e-3
    back = store.deserialize_cdr(serialize_message(msg), TYPE)
    assert list(back.law_state_names) == list(names)
    assert back.law_state.tolist() == list(msg.law_state)
    assert back.effort.tolist() == [3.0, -1.0] and back.position.tolist() == [0.2, 0.0]
    assert back.message == 'near singular' and back.dt == 1e-3
