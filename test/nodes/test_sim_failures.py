"""
The simulator's joint failures in its own process, driven by this test.

Every published state is compared with ``freejoint_core.plant.Plant`` stepped here with the
same commands and the same failures (``Plant.fail_joint``).
"""
import os

from freejoint_core.arm import table1
from freejoint_core.offline import initial_state
from freejoint_core.plant import Plant
from freejoint_tools.harness import load_source
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PARAMS = os.path.join(ROOT, 'config', 'sim.yaml')
DT = 0.001


def _sim_test_helpers():
    """Return test_sim_node.py as a module (its ``Controller``: this test as controller)."""
    return load_source(os.path.join(os.path.dirname(__file__), 'test_sim_node.py'),
                       'sim_node_test_helpers')


def _call_fail_joint(ros_node, joint):
    import rclpy
    from freejoint_common.contract import FAIL_JOINT
    client = ros_node.create_client(FAIL_JOINT.srv_type, FAIL_JOINT.of('sim_node'))
    assert client.wait_for_service(timeout_sec=15.0), 'no ~/fail_joint service'
    future = client.call_async(FAIL_JOINT.srv_type.Request(joint=joint))
    rclpy.spin_until_future_complete(ros_node, future, timeout_sec=15.0)
    assert future.done()
    return future.result()


def test_a_scheduled_and_a_requested_failure_leave_the_joint_limp_reading_zero_effort(
        procs, ros_node, wait):
    from freejoint_common.contract import JOINT_FAILURES
    proc = procs.start_node('freejoint_sim', 'sim_node', 'sim',
                            ['--ros-args', '--params-file', PARAMS, '-p',
                             'fail_joint:=joint2@0.004', '-p', 'report_failures:=true'])
    notices = []
    ros_node.create_subscription(JOINT_FAILURES.msg_type, JOINT_FAILURES.name,
                                 lambda m: notices.append(m.data), JOINT_FAILURES.qos)
    ctl = _sim_test_helpers().Controller(ros_node, wait)
    ctl.connect(proc, procs)
    params = table1('horizontal')
    plant = Plant(params, 0.0005, dist_bound=0.5, seed=0, q0=initial_state(params))
    plant.fail_joint(1, 0.004)
    tau = (3.0, -2.0)
    for k in range(8):
        ctl.command(tau, k)
        msg = ctl.state(k + 1)
        plant.step(tau, DT)
        assert list(msg.position) == plant.q.tolist()
        assert list(msg.velocity) == plant.qd.tolist()
        # joint 2 got no torque over the steps from 4 ms on: its effort reads 0
        assert list(msg.effort) == [3.0, -2.0 if k < 4 else 0.0, 0.0]
    wait(lambda: notices == ['joint2'], 10.0, 'the notice on joint_failures',
         spin=ctl.spin)
    refused = _call_fail_joint(ros_node, 'elbow')
    assert not refused.success and 'elbow' in refused.message
    done = _call_fail_joint(ros_node, 'joint1')
    assert done.success and abs(done.at - 0.008) < 1e-12
    plant.fail_joint(0, 0.008)
    for k in range(8, 12):
        ctl.command(tau, k)
        msg = ctl.state(k + 1)
        plant.step(tau, DT)
        assert list(msg.position) == plant.q.tolist()
        assert list(msg.effort) == [0.0, 0.0, 0.0]
    wait(lambda: any('joint1 at 0.008 s' in d[2].get('failed joints', '')
                     for d in ctl.diagnostics), 10.0, 'the failure on /diagnostics',
         spin=ctl.spin)
    assert procs.stop(proc) == 0
    with open(proc.log_path) as f:
        log = f.read()
    assert 'joint2 failed at t = 0.004 s (parameter fail_joint)' in log
    assert 'joint1 failed at t = 0.008 s (service ~/fail_joint)' in log


def test_a_bad_fail_joint_parameter_is_refused_naming_it():
    from freejoint_core.errors import FreejointValueError
    from freejoint_sim.params import SCHEMA
    values = SCHEMA.yaml_values(PARAMS)
    for bad, why in (('joint3@1.0', 'passive'), ('elbow@1', 'not a joint'),
                     ('joint2', 'expected'), ('joint2@-1', 'expected')):
        with pytest.raises(FreejointValueError, match='fail_joint: .*' + why):
            SCHEMA.config(dict(values, fail_joint=bad))
    assert SCHEMA.config(dict(values, fail_joint='joint1@0.5,joint2@1')).fail_joint
