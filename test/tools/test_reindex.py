"""reindex rebuilds metadata.yaml and the MCAP summary of a bag whose recorder was killed."""
import io
import os
import signal
import subprocess
import sys

import pytest
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
PUBLISHER = os.path.join(HERE, '..', 'nodes', 'tools_publisher.py')
# what `ros2 run freejoint_tools reindex` starts (setup.py console_scripts)
REINDEX = os.path.join(HERE, '..', '..', 'install', 'freejoint_tools', 'lib', 'freejoint_tools',
                       'reindex')


class _Unseekable(io.RawIOBase):
    """A file read as a stream (no seek): mcap's make_reader then reads without the summary."""

    def __init__(self, path):
        self._fh = open(path, 'rb')

    def readable(self):
        return True

    def seekable(self):
        return False

    def readinto(self, buffer):
        data = self._fh.read(len(buffer))
        buffer[:len(data)] = data
        return len(data)

    def close(self):
        self._fh.close()
        super().close()


def _mcap_file(path):
    files = [f for f in os.listdir(path) if f.endswith('.mcap')]
    assert len(files) == 1, files
    return os.path.join(path, files[0])


def _read_everywhere(path):
    """
    Read the bag with rosbags, mcap's make_reader (summary and stream) and open_bag.

    Return the ``(topic, log time, data)`` list of each, in file order; assert that each
    reader's counts agree with metadata.yaml and the MCAP statistics.
    """
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    from freejoint_tools.bagfile import open_bag
    mcap = _mcap_file(path)
    with open(os.path.join(path, 'metadata.yaml')) as fh:
        info = yaml.safe_load(fh)['rosbag2_bagfile_information']
    listed = {t['topic_metadata']['name']: t['message_count']
              for t in info['topics_with_message_count']}
    with Reader(path) as reader:
        assert reader.message_count == info['message_count']
        assert {c.topic: c.msgcount for c in reader.connections} == listed
        by_rosbags = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    with open(mcap, 'rb') as fh:
        seeking = make_reader(fh, validate_crcs=True)
        stats = seeking.get_summary().statistics
        assert stats.message_count == info['message_count']
        by_summary = [(c.topic, m.log_time, bytes(m.data))
                      for _, c, m in seeking.iter_messages(log_time_order=False)]
    stream = io.BufferedReader(_Unseekable(mcap))
    try:
        by_stream = [(c.topic, m.log_time, bytes(m.data))
                     for _, c, m in make_reader(stream, validate_crcs=True).iter_messages()]
    finally:
        stream.close()
    bag = open_bag(path)
    assert bag.finalised, bag.notes
    by_own = [(name, t, data) for name, t, _, data in bag.messages()]
    assert by_summary == by_stream == by_own
    assert sorted(by_rosbags, key=lambda m: m[1]) == sorted(by_own, key=lambda m: m[1])
    return by_own


def _killed_bag(make_bag, path, ticks=300, flush_every=100, compression='none'):
    """Write ``ticks`` ticks, a chunk per ``flush_every``, and stop without finalising."""
    make_bag(path, ticks, custom_data={'case': 'vertical', 'seed': '2'},
             finalise=False, chunk_size=1 << 30, flush_every=flush_every,
             compression=compression)
    return _mcap_file(path)


def test_reindex_of_a_killed_bag_gives_every_flushed_chunk_to_every_reader(
        tmp_path, make_bag):
    from freejoint_tools.bagfile import open_bag
    from freejoint_tools.reindex import reindex
    path = str(tmp_path / 'killed')
    _killed_bag(make_bag, path, ticks=250)     # ticks 200..249 never left the writer
    before = [(n, t, d) for n, t, _, d in open_bag(path).messages()]
    assert not os.path.exists(os.path.join(path, 'metadata.yaml'))
    report = reindex(path)
    assert 'summary rebuilt from 2 complete chunk(s)' in report and 'cut off' not in report
    after = _read_everywhere(path)
    assert after == before
    assert sum(1 for n, _, _ in after if n == '/joint_states') == 200
    bag = open_bag(path)
    assert bag.custom_data == {'case': 'vertical', 'seed': '2'}   # from the MCAP run record
    assert bag.metadata['custom_data'] == {'case': 'vertical', 'seed': '2'}


@pytest.mark.parametrize('compression', ['none', 'zstd'])
@pytest.mark.parametrize('cut', ['in_a_chunk', 'in_its_indexes', 'in_a_record_header'])
def test_a_chunk_cut_short_is_cut_off_and_a_whole_one_gets_its_indexes_rebuilt(
        tmp_path, make_bag, cut, compression):
    """
    Every complete chunk is kept; a whole last chunk whose message indexes were cut short too.

    What the cut file's reader (open_bag) reads, reindex keeps: the third chunk cut in its
    data is lost, the third chunk whole with its indexes cut short is read and kept (its
    indexes rebuilt from its messages).
    """
    from freejoint_tools.bagfile import open_bag, scan_mcap
    from freejoint_tools.reindex import reindex
    path = str(tmp_path / 'cut')
    mcap = _killed_bag(make_bag, path, compression=compression)   # three chunks, flushed
    last = scan_mcap(mcap).chunk_indexes[-1]
    size = os.path.getsize(mcap)
    os.truncate(mcap, {'in_a_chunk': last.chunk_start_offset + last.chunk_length // 2,
                       'in_its_indexes': size - 60, 'in_a_record_header': size - 3}[cut])
    before = [(n, t, d) for n, t, _, d in open_bag(path).messages()]
    report = reindex(path)
    kept = 200 if cut == 'in_a_chunk' else 300
    if cut == 'in_a_chunk':
        assert 'from 2 complete chunk(s), incomplete tail of' in report, report
    else:
        assert ("from 3 complete chunk(s), the last one's message indexes rebuilt"
                in report and 'cut off' not in report), report
    after = _read_everywhere(path)
    assert after == before
    ticks = sorted({t for n, t, _ in after if n == '/joint_states'})
    assert ticks == [k * 1_000_000 for k in range(kept)]
    assert open_bag(path).topics['/semi_singular_map'].count == 1


def test_reindex_twice_and_of_a_finalised_bag_changes_nothing(tmp_path, make_bag):
    from freejoint_tools.reindex import reindex
    done = str(tmp_path / 'done')
    make_bag(done, 20)
    mcap = _mcap_file(done)
    with open(mcap, 'rb') as fh:
        original = fh.read()
    assert 'finalised already' in reindex(done)
    with open(mcap, 'rb') as fh:
        assert fh.read() == original
    killed = str(tmp_path / 'killed')
    mcap = _killed_bag(make_bag, killed)
    reindex(killed)
    with open(mcap, 'rb') as fh:
        once = fh.read()
    assert 'finalised already' in reindex(killed)
    with open(mcap, 'rb') as fh:
        assert fh.read() == once


def test_reindex_command_line_refuses_what_is_not_a_bag_in_one_line(tmp_path):
    from freejoint_tools.reindex import main
    (tmp_path / 'empty').mkdir()
    (tmp_path / 'zip').mkdir()
    (tmp_path / 'zip' / 'zip_0.mcap').write_bytes(b'PK\x03\x04 a zip file' * 10)
    for path, problem in ((tmp_path / 'nothing', 'no such bag directory'),
                          (tmp_path / 'empty', 'no .mcap file'),
                          (tmp_path / 'zip', 'not an MCAP file')):
        done = subprocess.run([sys.executable, '-m', 'freejoint_tools.reindex', str(path)],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 1
        assert done.stderr.count('\n') == 1 and 'Traceback' not in done.stderr
        assert done.stderr.startswith('reindex: error: ') and problem in done.stderr
    assert main([str(tmp_path / 'nothing')]) == 1


@pytest.mark.ros
@pytest.mark.parametrize('compression, grown', [('none', 300_000), ('zstd', 60_000)])
def test_sigkill_then_reindex_gives_a_bag_rosbags_and_mcap_read(procs, wait, tmp_path,
                                                                compression, grown):
    """What a user does after kill -9 of the recorder: ``ros2 run freejoint_tools reindex``."""
    from mcap.reader import make_reader

    from freejoint_tools.bagfile import open_bag
    bag_path = str(tmp_path / 'vertical')
    recorder = procs.start_node('freejoint_tools', 'recorder', 'recorder', [
        '--ros-args', '-p', 'output:=%s' % bag_path, '-p', 'topics:=[]',
        '-p', 'flush_period:=0.2', '-p', 'custom_data:=[case=vertical, seed=2]',
        '-p', 'compression:=%s' % compression])
    publisher = procs.start_script(PUBLISHER, 'publisher', ['--ticks', '0', '--rate', '1000'])
    mcap = os.path.join(bag_path, 'vertical_0.mcap')
    wait(lambda: os.path.exists(mcap) and os.path.getsize(mcap) > grown, 60.0,
         'the bag to grow (publisher: %s)' % procs.log(publisher))
    os.killpg(recorder.pid, signal.SIGKILL)
    recorder.wait(10.0)
    procs.stop(publisher)
    assert not os.path.exists(os.path.join(bag_path, 'metadata.yaml'))
    before = open_bag(bag_path)           # read up to the break (the project's own reader)
    assert not before.finalised
    from rosbags.rosbag2 import Reader
    with pytest.raises(FileNotFoundError, match='metadata'):
        Reader(bag_path)                  # what a user sees: rosbags cannot open it
    done = subprocess.run([REINDEX, bag_path],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(bag_path + ': %d messages' % before.message_count)
    after = _read_everywhere(bag_path)
    assert after == [(n, t, d) for n, t, _, d in before.messages()]
    # Not a trivial bag (the equality above is the check): 197 ticks once with three test
    # workers and another job beside them (the publisher slower than its rate), more when
    # quiet.
    assert sum(1 for n, _, _ in after if n == '/joint_states') >= 50
    assert not [f for f in os.listdir(bag_path) if f.endswith('.reserve')]
    with open(mcap, 'rb') as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    assert {c.compression for c in chunks} == {'' if compression == 'none' else compression}
