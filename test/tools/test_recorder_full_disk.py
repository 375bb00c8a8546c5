"""
A full disk: the bag stays readable up to the error, and is still finalised.

Every message that did not reach the file is counted lost for its topic.

The disk is a small tmpfs mounted for the test (needs root or CAP_SYS_ADMIN; the test says
so and does not run otherwise) and always unmounted at the end.
"""
import os
import re
import signal
import subprocess
import time

import pytest
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
PUBLISHER = os.path.join(HERE, '..', 'nodes', 'tools_publisher.py')
TICK_TOPICS = ('/clock', '/joint_states', '/setpoints', '/controller_state')


@pytest.fixture
def small_disk(tmp_path):
    """Mount a tmpfs of the given size (bytes) and give its path; unmount it at the end."""
    mounted = []

    def mount(size):
        point = tmp_path / ('disk%d' % len(mounted))
        point.mkdir()
        done = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=%d' % size, 'tmpfs',
                               str(point)], capture_output=True, text=True, timeout=30)
        if done.returncode != 0:
            pytest.skip('cannot mount a tmpfs to fill (needs root or CAP_SYS_ADMIN): %s'
                        % (done.stderr.strip() or 'mount exit %d' % done.returncode))
        mounted.append(point)
        return str(point)

    yield mount
    for point in mounted:
        if subprocess.run(['umount', str(point)], timeout=30).returncode != 0:
            subprocess.run(['umount', '-l', str(point)], timeout=30)


def test_writer_on_a_full_disk_counts_what_did_not_reach_the_file_and_finalises(
        small_disk, make_bag):
    from rosbags.rosbag2 import Reader

    from freejoint_tools.bagfile import BagWriter, default_qos_dict, open_bag
    path = os.path.join(small_disk(1 << 20), 'full')
    writer = BagWriter(path, {'case': 'horizontal'}, chunk_size=32 * 1024)
    topics = {name: writer.add_topic(name, 'std_msgs/msg/String', '', '',
                                     [default_qos_dict()]) for name in ('/a', '/b')}
    sent = {name: [] for name in topics}
    for k in range(20000):
        for name, channel in topics.items():
            data = b'\x00\x01\x00\x00' + k.to_bytes(4, 'little') + bytes(60)
            writer.write(channel, k * 1000, data)
            sent[name].append(data)
        if k % 500 == 0:
            writer.flush()
    assert writer.error.startswith('disk full')
    assert not os.path.exists(os.path.join(path, 'metadata.yaml'))
    unfinished = open_bag(path)                # readable up to the error, before closing
    writer.close()
    bag = open_bag(path)
    assert bag.finalised
    with open(os.path.join(path, 'metadata.yaml')) as fh:
        info = yaml.safe_load(fh)['rosbag2_bagfile_information']
    listed = {t['topic_metadata']['name']: t['message_count']
              for t in info['topics_with_message_count']}
    for name, channel in topics.items():
        in_file = [data for topic, _, _, data in bag.messages() if topic == name]
        assert 1000 < len(in_file) < 20000
        assert in_file == sent[name][:len(in_file)]          # what is there, in order
        assert writer.count(channel) == len(in_file) == listed[name]
        assert writer.lost(channel) == 20000 - len(in_file)  # the rest is counted lost
        assert unfinished.topics[name].count == len(in_file)
    with Reader(path) as reader:
        assert reader.message_count == bag.message_count
    assert sorted(os.listdir(path)) == ['full_0.mcap', 'metadata.yaml']   # reserve freed


@pytest.mark.ros
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_recorder_on_a_full_disk_reports_the_loss_finalises_and_exits_with_one_line(
        procs, wait, ros_node, tmp_path, small_disk, signum):
    from freejoint_tools.bagfile import open_bag
    from freejoint_tools.harness import ServiceCalls
    bag_path = os.path.join(small_disk(3 << 20), 'run')
    recorder = procs.start_node('freejoint_tools', 'recorder', 'recorder', [
        '--ros-args', '-p', 'output:=%s' % bag_path, '-p', 'topics:=[%s]' % ', '.join(
            TICK_TOPICS), '-p', 'ready_topics:=[%s]' % ', '.join(TICK_TOPICS),
        '-p', 'flush_period:=0.1', '-p', 'custom_data:=[case=vertical]'])
    publisher = procs.start_script(PUBLISHER, 'publisher', [
        '--ticks', '0', '--rate', '1000', '--clock', '--recorder', '/recorder'])
    wait(lambda: 'cannot write the bag' in procs.log(recorder), 90.0,
         'the disk to fill (recorder: %s)' % procs.log(recorder)[-2000:])
    # The harness's query sends again when unanswered (a response can be lost:
    # ros2/rmw_fastrtps#390).
    answer = ServiceCalls(ros_node).recorder_answer(30.0)
    assert answer is not None, 'no answer from the recorder status within 30 s'
    assert not answer.success and 'disk full' in answer.message, answer.message
    assert int(re.search(r'; not written (\d+);', answer.message).group(1)) > 0
    time.sleep(0.5)                            # messages keep coming: counted lost
    recorder.send_signal(signum)
    code = recorder.wait(30.0)
    procs.stop(publisher)
    log = procs.log(recorder)
    assert code == 1, log
    assert 'Traceback' not in log
    errors = [line for line in log.splitlines() if line.startswith('recorder: error: ')]
    assert len(errors) == 1 and 'disk full' in errors[0], log
    assert errors[0] == log.rstrip('\n').splitlines()[-1]

    bag = open_bag(bag_path)                   # finalised whatever happened before
    assert bag.finalised
    custom = bag.metadata['custom_data']
    assert custom['case'] == 'vertical' and 'disk full' in custom['recorder_error']
    noted = dict(item.rsplit(' ', 1) for item in custom['recorder_not_written'].split(', '))
    for topic in TICK_TOPICS:
        line = re.search(r'%s: received (\d+), written (\d+), not written (\d+),'
                         % re.escape(topic), log)
        received, written, lost = (int(g) for g in line.groups())
        assert written == bag.topics[topic].count > 100, topic
        assert lost > 0 and received == written + lost, (topic, line.group(0))
        assert int(noted[topic]) == lost
    from freejoint_common.records import stamp_ns
    stamps = [stamp_ns(m) for _, m in bag.decode('/joint_states')]
    assert stamps == sorted(set(stamps))
    holes = (stamps[-1] - stamps[0]) // 1_000_000 + 1 - len(stamps)
    middleware = int(re.search(r'/joint_states: received .* lost \(middleware\) (\d+)',
                               log).group(1))
    assert holes <= middleware          # none, unless the middleware said it lost them


def test_reindex_of_a_killed_bag_on_a_full_disk_uses_the_space_kept_in_reserve(small_disk):
    """A recorder killed after the disk filled up: reindex still finalises its bag."""
    from freejoint_tools.bagfile import BagWriter, default_qos_dict, open_bag
    from freejoint_tools.reindex import reindex
    disk = small_disk(1 << 20)
    path = os.path.join(disk, 'killed')
    # small chunks: a summary larger than the slack of the file's last page
    writer = BagWriter(path, {'case': 'vertical'}, chunk_size=4096)
    channel = writer.add_topic('/a', 'std_msgs/msg/String', '', '', [default_qos_dict()])
    k = 0
    while writer.error is None:
        writer.write(channel, k * 1000,
                     b'\x00\x01\x00\x00' + k.to_bytes(4, 'little') + bytes(60))
        k += 1
    writer.abandon()                           # killed: no summary, the reserve left behind
    with open(os.path.join(disk, 'filler'), 'wb', buffering=0) as fh:
        with pytest.raises(OSError, match='No space left'):   # nothing else fits
            while True:
                fh.write(bytes(4096))
    assert 'summary rebuilt' in reindex(path)
    bag = open_bag(path)
    assert bag.finalised and bag.topics['/a'].count == writer.count(channel) > 1000
    assert bag.custom_data == {'case': 'vertical'}
    assert sorted(os.listdir(path)) == ['killed_0.mcap', 'metadata.yaml']


def test_a_last_chunk_that_does_not_fit_at_close_is_counted_lost_and_the_bag_finalised(
        small_disk):
    from freejoint_tools.bagfile import BagWriter, default_qos_dict, open_bag
    disk = small_disk(2 << 20)
    path = os.path.join(disk, 'last')
    writer = BagWriter(path, chunk_size=1 << 30)           # a chunk per flush only
    channel = writer.add_topic('/a', 'std_msgs/msg/String', '', '', [default_qos_dict()])
    for k in range(1000):
        writer.write(channel, k, bytes(100))
    writer.flush()                                          # in the file: 1000
    with open(os.path.join(disk, 'filler'), 'wb', buffering=0) as fh:
        with pytest.raises(OSError, match='No space left'):
            while True:
                fh.write(bytes(4096))
    for k in range(1000, 6000):                             # ~600 kB: more than the reserve
        writer.write(channel, k, bytes(100))
    assert writer.error is None                             # still in memory
    writer.close()
    assert writer.error.startswith('disk full')
    assert (writer.count(channel), writer.lost(channel)) == (1000, 5000)
    bag = open_bag(path)
    assert bag.finalised and bag.topics['/a'].count == 1000
    assert bag.metadata['message_count'] == 1000
