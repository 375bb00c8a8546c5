"""The player republishes a bag with /clock: a subscriber gets the same messages in order."""
import pytest

pytestmark = pytest.mark.ros

TOPICS = ('/joint_states', '/setpoints', '/controller_state', '/semi_singular_map',
          '/planned_path')


def test_player_republishes_a_bag_in_order_with_its_clock(procs, ros_node, wait, tmp_path,
                                                          make_bag):
    import rclpy
    from rclpy.serialization import deserialize_message, serialize_message

    from freejoint_common.contract import CLOCK, profile, to_ns
    from freejoint_tools.bagfile import open_bag
    from freejoint_tools.typedefs import message_class
    path = str(tmp_path / 'run')
    written = make_bag(path, 300)
    bag = open_bag(path)
    got = {t: [] for t in TOPICS}
    for topic in TOPICS:
        latched = bag.topics[topic].qos[0]['durability'] == 'transient_local'
        qos = profile(1000, latched=latched)
        ros_node.create_subscription(message_class(bag.topics[topic].type), topic,
                                     got[topic].append, qos, raw=True)
    clocks = []
    ros_node.create_subscription(CLOCK.msg_type, CLOCK.name, clocks.append, CLOCK.qos)
    player = procs.start_node('freejoint_tools', 'player', 'player', [
        '--ros-args', '-p', 'bag:=%s' % path, '-p', 'rate:=20.0',
        '-p', 'wait_for_subscribers:=1'])
    wait(lambda: player.poll() is not None, 60.0, 'the player to finish (log: %s)'
         % procs.log(player), spin=lambda: rclpy.spin_once(ros_node, timeout_sec=0.01))
    assert player.returncode == 0, procs.log(player)
    # (/clock too: reliable, but its 300 messages can still be in flight behind the others
    # when the player has exited - on a loaded machine)

    def spin():
        rclpy.spin_once(ros_node, timeout_sec=0.01)

    wait(lambda: all(len(got[t]) == len(written[t]) for t in TOPICS) and len(clocks) >= 300,
         60.0, 'every message and clock', spin=spin)
    for topic in TOPICS:
        cls = message_class(bag.topics[topic].type)
        # compared as decoded (float32 fields round, the wire form may carry padding)
        sent = [deserialize_message(serialize_message(m), cls) for m in written[topic]]
        assert [deserialize_message(d, cls) for d in got[topic]] == sent, topic
    # /clock carries the bag's log times (sim time here), each distinct time once, in order
    assert [to_ns(c.clock) for c in clocks] == \
        [k * 1_000_000 for k in range(300)]
    assert 'played %d messages' % sum(len(written[t]) for t in TOPICS) in procs.log(player)


def test_player_names_a_bad_bag_in_one_line_and_exits_1(procs, wait, tmp_path):
    player = procs.start_node('freejoint_tools', 'player', 'player', [
        '--ros-args', '-p', 'bag:=%s' % (tmp_path / 'nothing')])
    wait(lambda: player.poll() is not None, 30.0, 'the player to exit')
    assert player.returncode == 1
    log = procs.log(player).strip().splitlines()
    assert log == ['player: error: %s: no such bag (directory does not exist)'
                   % (tmp_path / 'nothing')]
