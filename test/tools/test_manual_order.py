"""
The README's manual wiring order records the run from tick 0, and the recorder says so.

The README starts the recorder first, then sim, planner (``autostart:=false``) and
controller, and starts the circle once the recorder's ``~/status`` answers success: the
lockstep run then begins only after every publisher is matched with the recorder (with the
planner's autostart the controller starts the run, and a recorder started first can still
miss the first ticks of a publisher it discovers late: Fast DDS discovery of participants
started together can take seconds).
"""

import os
import re

import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
TICKS = 1500


def test_readme_order_recorder_first_records_the_run_from_tick_0(
        procs, ros_node, wait, tmp_path, start_circle):
    import rclpy
    from std_srvs.srv import Trigger

    from freejoint_common.records import stamp_ns
    from freejoint_tools.bagfile import open_bag
    from freejoint_tools.recorder import received_count, REPAIR_QUIET, wait_drained
    bag_path = str(tmp_path / 'my_run')
    client = ros_node.create_client(Trigger, '/recorder/status')

    def read_status():
        if not client.service_is_ready():
            return None
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(ros_node, future, timeout_sec=5.0)
        return future.result().message if future.done() else None

    def start(pkg, exe, conf, *extra):
        return procs.start_node(pkg, exe, exe, ['--ros-args', '--params-file',
                                                os.path.join(CONFIG, conf), *extra])

    # the README's lines, in its order; the simulator holds after TICKS ticks (ends quiet)
    recorder = procs.start_node('freejoint_tools', 'recorder', 'recorder', [
        '--ros-args', '-p', 'output:=%s' % bag_path, '-p', 'use_sim_time:=true'])
    wait(lambda: 'recording /joint_states' in procs.log(recorder), 30.0, 'the recorder')
    nodes = [start('freejoint_sim', 'sim_node', 'sim.yaml', '-p', 'max_steps:=%d' % TICKS),
             start('freejoint_planner', 'planner_node', 'planner.yaml',
                   '-p', 'autostart:=false'),
             start('freejoint_control', 'controller_node', 'controller.yaml')]
    # `ros2 service call /recorder/status std_srvs/srv/Trigger` until success: true, then
    # the circle (what a user typing the next line gives the middleware: a second or more)
    start_circle(1.0)
    wait(lambda: (received_count(read_status()) or 0) > 4 * TICKS, 120.0,
         'the run (sim: %s)' % procs.log(nodes[0])[-800:],
         spin=lambda: rclpy.spin_once(ros_node, timeout_sec=0.1))
    count, _ = wait_drained(read_status, REPAIR_QUIET, 60.0,
                            lambda: rclpy.spin_once(ros_node, timeout_sec=0.05))
    assert count is not None
    for proc in reversed(nodes):               # controller first: the lockstep pauses
        procs.stop(proc)
    assert procs.stop(recorder) == 0
    log = procs.log(recorder)
    bag = open_bag(bag_path)
    for topic in ('/joint_states', '/controller_state'):
        stamps = sorted({stamp_ns(m) for _, m in bag.decode(topic)})
        assert stamps == [k * 1_000_000 for k in range(len(stamps))], topic   # from tick 0
        assert len(stamps) >= TICKS, topic
        summary = re.search(r'  %s: received .*' % re.escape(topic), log).group(0)
        assert 'first stamp 0.000000 s = tick 0 (grid 1 ms), missed 0 ticks' in summary, \
            summary
    assert 'recorder_missed_ticks' not in (bag.metadata['custom_data'] or {})
