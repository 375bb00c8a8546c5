"""Bags of the ControllerState layout before the law's state was generic still analyse."""
import json
import math
import os

import numpy as np

# ControllerState's fields as main had them before the generic law state and the task-sized
# vectors (the CDR of every bag recorded until then); constants and comments left out, they
# do not change the serialization.
OLD_CONTROLLER_STATE = """\
std_msgs/Header header
float64[2] error
float64[2] error_rate
float64[2] sliding
float64[5] theta_hat
float64 rho_hat
float64[2] delta_v
float64[] effort
string[] joint_names
float64 det_dd
float64[2] position
float64[2] position_desired
uint16 status
string message
float64 state_age
builtin_interfaces/Time setpoint_stamp
float64 setpoint_age
float64 dt
"""
STATE_TYPE = 'freejoint_msgs/msg/ControllerState'
DT_NS = 1_000_000


def _old_store():
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(OLD_CONTROLLER_STATE, STATE_TYPE))
    return store


def _tick(k):
    """Return (p, p_d, tau, theta, det, q3) of tick k: smooth, hand-made values."""
    p_d = (0.2 * math.cos(k / 50.0), 0.2 * math.sin(k / 50.0))
    p = (p_d[0] + 1e-3 * math.sin(k / 7.0), p_d[1] - 2e-3 * math.cos(k / 11.0))
    tau = (2.0 * math.sin(k / 13.0), -1.5 * math.cos(k / 17.0))
    theta = (1e-5 * k, 2e-5 * k, 0.0, 1e-6 * k, 0.5)
    return p, p_d, tau, theta, 1e-3 + 1e-4 * math.sin(k / 3.0), 0.3 * math.sin(k / 20.0)


def _write_old_bag(path, ticks):
    """Write an old-layout bag: its ControllerState serialized and described as before."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from freejoint_common.contract import stamp_from_ns
    from freejoint_tools.bagfile import BagWriter, default_qos_dict
    from freejoint_tools.typedefs import Definitions
    store = _old_store()
    text, _ = store.generate_msgdef(STATE_TYPE, ros_version=2)
    writer = BagWriter(path, {'case': 'horizontal', 'variant': 'robust', 'seed': '3'})
    states = writer.add_topic('/controller_state', STATE_TYPE, text,
                              store.hash_rihs01(STATE_TYPE), [default_qos_dict()])
    js_text, js_digest = Definitions().lookup('sensor_msgs/msg/JointState')
    joints = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState', js_text,
                              js_digest, [default_qos_dict()])
    types = store.types
    Header, Time = types['std_msgs/msg/Header'], types['builtin_interfaces/msg/Time']
    Old = types[STATE_TYPE]
    for k in range(ticks):
        ns = k * DT_NS
        p, p_d, tau, theta, det, q3 = _tick(k)
        ros_stamp = stamp_from_ns(ns)
        stamp = Time(sec=ros_stamp.sec, nanosec=ros_stamp.nanosec)
        e = np.subtract(p, p_d)
        msg = Old(header=Header(stamp=stamp, frame_id='base_link'), error=e,
                  error_rate=np.zeros(2), sliding=np.zeros(2), theta_hat=np.array(theta),
                  rho_hat=0.25, delta_v=np.array([-0.1, 0.1]), effort=np.array(tau),
                  joint_names=['joint1', 'joint2'], det_dd=det, position=np.array(p),
                  position_desired=np.array(p_d), status=0, message='', state_age=0.0,
                  setpoint_stamp=stamp, setpoint_age=0.0, dt=1e-3)
        writer.write(states, ns, bytes(store.serialize_cdr(msg, STATE_TYPE)))
        js = JointState()
        stamp_from_ns(ns, js.header.stamp)
        js.name = ['joint1', 'joint2', 'joint3']
        js.position = [0.1, 1.0, q3]
        js.velocity = [0.0, 0.0, 0.0]
        js.effort = [0.0, 0.0, 0.0]   # rosbags refuses the CDR padding of an empty last array
        writer.write(joints, ns, serialize_message(js))
    writer.close()


def _expected_record(ticks):
    """Return the record of the values written, computed without any message."""
    from freejoint_core.metrics import compute_record
    rows = [_tick(k) for k in range(ticks)]
    return compute_record(
        'horizontal', 'robust', 3, t=np.arange(ticks) * 1e-3,
        p=np.array([r[0] for r in rows]), p_d=np.array([r[1] for r in rows]),
        tau=np.array([r[2] for r in rows]), theta=np.array([r[3] for r in rows]),
        q_passive=np.array([r[5] for r in rows]), det=np.array([r[4] for r in rows]),
        source='graph')


def test_the_old_definition_is_the_one_the_bag_stores_and_reads_back(tmp_path):
    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'old')
    _write_old_bag(path, 5)
    bag = open_bag(path)
    assert 'float64[5] theta_hat' in bag.topics['/controller_state'].msgdef
    last = bag.decode('/controller_state')[-1][1]
    assert list(last.theta_hat) == list(_tick(4)[3]) and not hasattr(last, 'law_state')


def test_an_old_layout_bag_analyses_to_the_record_of_its_values(tmp_path, analyze,
                                                                same_record):
    path = str(tmp_path / 'horizontal')
    _write_old_bag(path, 300)
    done = analyze(path, '--no-plots')
    assert done.returncode == 0, done.stderr
    with open(os.path.join(path, 'metrics.json')) as fh:
        records = json.load(fh)
    expected = _expected_record(300)
    same_record(records[0], expected)
    assert records[0]['theta_final'] == list(_tick(299)[3])


def test_an_old_layout_bag_draws_its_figure(tmp_path, analyze):
    path = str(tmp_path / 'runs' / 'horizontal')
    _write_old_bag(path, 100)
    done = analyze(path)
    assert done.returncode == 0, done.stderr
    assert os.path.isfile(os.path.join(path, 'fig3_horizontal.png'))
