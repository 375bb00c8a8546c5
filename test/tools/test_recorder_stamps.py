"""
The recorder names the first stamp it got per topic and, on a grid, the ticks it missed.

A recorder started after the run (the README's manual way, recorder last) used to miss the
first ticks and report ``lost (middleware) 0``: nothing said they were missing.
"""
import os
import re
import time

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
PUBLISHER = os.path.join(HERE, '..', 'nodes', 'tools_publisher.py')
MS = 1_000_000


def _grid(stamps):
    from freejoint_tools.recorder import StampGrid
    grid = StampGrid()
    for t in stamps:
        grid.add(t)
    return grid


def test_a_lockstep_stream_from_tick_0_misses_nothing():
    grid = _grid([0, 0, 0] + [k * MS for k in range(1, 500)])   # tick 0 republished
    assert grid.on_grid() and grid.step == MS
    assert grid.missed() == (0, [])
    assert grid.describe() == 'first stamp 0.000000 s = tick 0 (grid 1 ms), missed 0 ticks'


def test_a_stream_joined_late_misses_the_ticks_before_its_first_stamp():
    grid = _grid([k * MS for k in range(100, 600)])
    assert grid.missed() == (100, [(0, 99)])
    assert grid.describe() == ('first stamp 0.100000 s = tick 100 (grid 1 ms), missed 100 '
                               'ticks: 0-99')


def test_holes_inside_the_stream_are_named_tick_by_tick_and_counted_exactly():
    ticks = [k for k in range(0, 300) if k not in (7, 150, 151, 152)]
    grid = _grid([k * 2 * MS for k in ticks])                   # a 2 ms grid
    assert grid.step == 2 * MS
    assert grid.missed() == (4, [(7, 7), (150, 152)])
    assert grid.describe().endswith('(grid 2 ms), missed 4 ticks: 7, 150-152')


def test_a_hole_right_after_the_first_stamp_is_still_counted():
    grid = _grid([0, 2 * MS] + [k * MS for k in range(3, 50)])
    assert grid.missed() == (1, [(1, 1)])


def test_system_time_stamps_are_not_a_grid_and_are_named_from_the_first_stamp():
    t0 = 1_763_000_000_123_456_789
    grid = _grid([t0 + k * MS + (k * 7919) % 50_000 for k in range(200)])
    assert grid.off_grid and not grid.on_grid() and grid.missed() is None
    # last stamp: k = 199, 199 ms + (199 * 7919) % 50000 ns = 199.025881 ms after t0
    assert grid.describe() == ('first stamp +0.000000 s, last +0.199026 s (from the first '
                               'stamp recorded)')


def test_a_real_time_stream_on_a_1_ms_wall_grid_counts_no_ticks():
    # a real-time run: stamps of the wall clock, each a whole millisecond
    t0 = 1_795_695_095_917 * MS
    grid = _grid([t0 + k * MS for k in range(500)])
    assert grid.system_time() and not grid.on_grid()
    assert grid.missed() is None
    assert grid.describe(origin=t0 - 41 * MS) == (
        'first stamp +0.041000 s, last +0.540000 s (from the first stamp recorded)')


def test_the_origin_of_a_recording_is_the_first_system_time_stamp_of_any_stream():
    from freejoint_tools.recorder import first_system_stamp
    t0 = 1_795_695_095_917 * MS
    streams = [_grid([t0 + 5 * MS + k * MS for k in range(20)]),
               _grid([t0 + 2 * MS + k * MS for k in range(20)]),
               _grid([k * MS for k in range(20)]), _grid([])]   # sim time, no stamp
    assert first_system_stamp(streams) == t0 + 2 * MS
    assert first_system_stamp(streams[2:]) is None


def test_too_few_stamps_or_stamps_going_back_are_not_a_grid():
    assert _grid([0, MS, 2 * MS]).missed() is None
    assert _grid([k * MS for k in range(50)] + [10 * MS]).missed() is None
    assert _grid([]).describe() == 'no stamp'


@pytest.mark.ros
def test_a_recorder_started_after_the_run_names_the_first_tick_and_the_ticks_it_missed(
        procs, wait, ros_node, tmp_path):
    import rclpy
    from std_srvs.srv import Trigger

    from freejoint_common.records import stamp_ns
    from freejoint_tools.bagfile import open_bag
    from freejoint_tools.recorder import received_count
    publisher = procs.start_script(PUBLISHER, 'publisher', [
        '--ticks', '0', '--rate', '1000', '--subscribers', '0'])
    wait(lambda: 'publishing' in procs.log(publisher) or publisher.poll() is not None, 30.0,
         'the publisher to start (%s)' % procs.log(publisher))
    time.sleep(1.0)                                # the run goes on without a recorder
    bag_path = str(tmp_path / 'late')
    recorder = procs.start_node('freejoint_tools', 'recorder', 'recorder', [
        '--ros-args', '-p', 'output:=%s' % bag_path,
        '-p', 'topics:=[/joint_states, /controller_state]'])
    client = ros_node.create_client(Trigger, '/recorder/status')

    def received():
        if not client.service_is_ready():
            return 0
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(ros_node, future, timeout_sec=5.0)
        return (received_count(future.result().message) if future.done() else 0) or 0

    wait(lambda: received() > 1000, 60.0, 'the recorder to receive the run',
         spin=lambda: rclpy.spin_once(ros_node, timeout_sec=0.1))
    assert procs.stop(recorder) == 0
    procs.stop(publisher)
    log = procs.log(recorder)
    bag = open_bag(bag_path)
    for topic in ('/joint_states', '/controller_state'):
        first = stamp_ns(bag.decode(topic)[0][1])
        k = first // MS
        assert k > 100, (topic, k)                 # it did join late
        summary = re.search(r'  %s: received .*' % re.escape(topic), log).group(0)
        head = 'first stamp %.6f s = tick %d (grid 1 ms), missed ' % (first * 1e-9, k)
        assert head in summary, summary
        missed = re.search(r'missed (\d+) ticks: 0-%d(, |$)' % (k - 1), summary)
        assert missed, summary
        # on a loaded machine a publisher's history can overrun while the recorder is
        # starved: such holes are named too, and the middleware reported them lost
        lost = int(re.search(r'lost \(middleware\) (\d+)', summary).group(1))
        assert k <= int(missed.group(1)) <= k + lost, summary
        assert '%s %s ticks: 0-%d' % (topic, missed.group(1), k - 1) in \
            bag.metadata['custom_data']['recorder_missed_ticks']
