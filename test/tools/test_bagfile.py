"""The bag files freejoint_tools writes are rosbag2 v9 MCAP bags that rosbags reads back."""
import os

import pytest
import yaml

TICK_TOPICS = ('/joint_states', '/setpoints', '/controller_state', '/clock')


def _read_with_rosbags_only_stored_definitions(path):
    """Decode every message with a type store built from the bag's definitions alone."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores
    store = get_typestore(Stores.EMPTY)
    out = {}
    with Reader(path) as reader:
        for conn in reader.connections:
            store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(store.deserialize_cdr(raw, conn.msgtype))
        counts = {c.topic: c.msgcount for c in reader.connections}
    return out, counts


def test_finalised_bag_has_version_9_metadata_listing_every_topic(tmp_path, make_bag):
    bag = str(tmp_path / 'run')
    written = make_bag(bag, 50, custom_data={'case': 'vertical', 'seed': '3'})
    with open(os.path.join(bag, 'metadata.yaml')) as fh:
        info = yaml.safe_load(fh)['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['run_0.mcap']
    listed = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert set(listed) == set(written)
    for name, msgs in written.items():
        meta = listed[name]['topic_metadata']
        assert listed[name]['message_count'] == len(msgs)
        cls = msgs[0].__class__
        assert meta['type'] == cls.__module__.split('.')[0] + '/msg/' + cls.__name__
        assert meta['serialization_format'] == 'cdr'
        assert meta['type_description_hash'].startswith('RIHS01_')
        assert isinstance(meta['offered_qos_profiles'], list)
    assert listed['/semi_singular_map']['topic_metadata']['offered_qos_profiles'][0][
        'durability'] == 'transient_local'
    assert info['message_count'] == sum(len(m) for m in written.values())
    assert info['custom_data'] == {'case': 'vertical', 'seed': '3'}


def test_rosbags_reads_every_message_back_with_the_stored_definitions_only(tmp_path,
                                                                           make_bag):
    bag = str(tmp_path / 'run')
    written = make_bag(bag, 30)
    decoded, counts = _read_with_rosbags_only_stored_definitions(bag)
    assert counts == {name: len(msgs) for name, msgs in written.items()}
    last = decoded['/controller_state'][-1]
    sent = written['/controller_state'][-1]
    assert list(last.law_state) == list(sent.law_state)
    assert list(last.effort) == list(sent.effort)
    assert last.message == sent.message and last.det_dd == sent.det_dd
    assert last.STATUS_BAD_INPUT == 16             # constants travel with the definition
    assert [m.header.stamp.nanosec for m in decoded['/joint_states']] == \
        [m.header.stamp.nanosec for m in written['/joint_states']]


def test_stored_definitions_hash_to_the_compiled_types_hash(tmp_path, make_bag):
    """The definition text in the bag describes exactly the type the nodes were built with."""
    import json

    from ament_index_python.packages import get_package_share_directory
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores

    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'run')
    make_bag(path, 2)
    for topic in open_bag(path).topics.values():
        pkg, _, name = topic.type.split('/')
        with open(os.path.join(get_package_share_directory(pkg), 'msg', name + '.json')) as fh:
            compiled = json.load(fh)['type_hashes'][0]['hash_string']
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(topic.msgdef, topic.type))
        assert store.hash_rihs01(topic.type) == compiled == topic.type_hash, topic.name


def test_open_bag_reads_topics_messages_and_run_info_in_file_order(tmp_path, make_bag):
    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'run')
    written = make_bag(path, 20, custom_data={'case': 'horizontal', 'variant': 'robust'})
    bag = open_bag(path)
    assert bag.finalised and bag.notes == []
    assert bag.custom_data == {'case': 'horizontal', 'variant': 'robust'}
    assert {n: t.count for n, t in bag.topics.items()} == {
        n: len(m) for n, m in written.items()}
    order = [name for name, _, _, _ in bag.messages()]
    assert order[:2] == ['/semi_singular_map', '/planned_path']
    assert order[2:6] == ['/clock', '/joint_states', '/setpoints', '/controller_state']
    got = [data for name, _, _, data in bag.messages() if name == '/setpoints']
    assert got == make_bag.data['/setpoints']


def test_bag_of_a_killed_writer_reads_up_to_its_last_flushed_chunk(tmp_path, make_bag):
    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'killed')
    make_bag(path, 250, finalise=False, chunk_size=1 << 30, flush_every=100)
    assert not os.path.exists(os.path.join(path, 'metadata.yaml'))
    bag = open_bag(path)
    assert not bag.finalised
    assert len(bag.notes) == 1 and 'not finalised' in bag.notes[0]
    # ticks 0..199 were flushed (two chunks), 200..249 were still in the writer's memory
    assert bag.topics['/joint_states'].count == 200
    assert bag.topics['/semi_singular_map'].count == 1


def test_bag_cut_inside_a_chunk_keeps_the_complete_chunks_before_it(tmp_path, make_bag):
    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'cut')
    make_bag(path, 300, finalise=False, chunk_size=1 << 30, flush_every=100)
    mcap = os.path.join(path, 'cut_0.mcap')
    size = os.path.getsize(mcap)
    with open(mcap, 'r+b') as fh:
        fh.truncate(size - 20000)         # the third chunk (~60 kB + index) loses its end
    bag = open_bag(path)
    assert bag.topics['/controller_state'].count == 200
    assert 'up to byte' in bag.notes[0]


@pytest.mark.parametrize('damage,problem', [
    ('missing', 'no such bag'),
    ('foreign', 'not a rosbag2 bag'),
    ('truncated', 'truncated at byte'),
    ('not_mcap', 'not an MCAP file'),
    ('bad_yaml', 'not rosbag2 metadata'),
    ('sqlite', "storage 'sqlite3' is not supported"),
    ('count', 'metadata.yaml lists'),
])
def test_bad_bags_raise_one_line_errors_naming_the_file(tmp_path, make_bag, damage, problem):
    from freejoint_tools.bagfile import BagError, open_bag
    path = str(tmp_path / 'bag')
    meta = os.path.join(path, 'metadata.yaml')
    mcap = os.path.join(path, 'bag_0.mcap')
    if damage != 'missing' and damage != 'foreign':
        make_bag(path, 20)
    if damage == 'foreign':
        os.makedirs(path)
        (tmp_path / 'bag' / 'notes.txt').write_text('hello')
    elif damage == 'truncated':
        os.truncate(mcap, os.path.getsize(mcap) // 2)
    elif damage == 'not_mcap':
        with open(mcap, 'wb') as fh:
            fh.write(b'PK\x03\x04 this is a zip file' * 10)
    elif damage == 'bad_yaml':
        with open(meta, 'w') as fh:
            fh.write('just: [a, list]\n')
    elif damage in ('sqlite', 'count'):
        with open(meta) as fh:
            text = fh.read()
        text = text.replace('storage_identifier: mcap', 'storage_identifier: sqlite3') \
            if damage == 'sqlite' else text.replace('message_count: 20\n',
                                                    'message_count: 21\n', 1)
        with open(meta, 'w') as fh:
            fh.write(text)
    with pytest.raises(BagError, match=problem) as info:
        open_bag(path)
    message = str(info.value)
    assert '\n' not in message
    expected = {'missing': path, 'foreign': path, 'truncated': mcap, 'not_mcap': mcap,
                'bad_yaml': meta, 'sqlite': meta, 'count': mcap}[damage]
    assert message.startswith(expected + ': ')


def test_writer_refuses_to_overwrite_an_existing_bag(tmp_path, make_bag):
    from freejoint_tools.bagfile import BagError, BagWriter
    path = str(tmp_path / 'run')
    make_bag(path, 1)
    with pytest.raises(BagError, match='exists already, not overwriting'):
        BagWriter(path)


def test_definitions_come_from_the_installed_msg_files_for_custom_types():
    from freejoint_tools.typedefs import DefinitionError, Definitions
    defs = Definitions()
    text, digest = defs.lookup('freejoint_msgs/msg/ControllerState')
    assert 'float64[] law_state' in text and 'MSG: std_msgs/Header' in text
    assert digest.startswith('RIHS01_')
    with pytest.raises(DefinitionError, match='no_such_pkg'):
        defs.lookup('no_such_pkg/msg/Thing')


def test_overwrite_removes_only_a_directory_of_bag_files(tmp_path, make_bag):
    from freejoint_tools.bagfile import BagError
    from freejoint_tools.recorder import _remove_old_bag
    old = str(tmp_path / 'old')
    make_bag(old, 5)
    (tmp_path / 'old' / 'fig3_old.png').write_bytes(b'png')
    (tmp_path / 'old' / 'metrics.json').write_text('[]')
    _remove_old_bag(old)
    assert not os.path.exists(old)
    mine = tmp_path / 'mine'
    mine.mkdir()
    (mine / 'thesis.tex').write_text('precious')
    with pytest.raises(BagError, match='holds thesis.tex, which is not a bag file'):
        _remove_old_bag(str(mine))
    assert (mine / 'thesis.tex').exists()


def _chunk_compressions(mcap):
    from mcap.reader import make_reader
    with open(mcap, 'rb') as fh:
        return {c.compression for c in make_reader(fh).get_summary().chunk_indexes}


def test_zstd_bag_round_trips_every_message_through_every_reader(tmp_path, make_bag):
    """Chunks zstd-compressed: open_bag, rosbags and mcap's make_reader read all of it back."""
    from mcap.reader import make_reader

    from freejoint_tools.bagfile import open_bag
    plain, packed = str(tmp_path / 'plain'), str(tmp_path / 'packed')
    make_bag(plain, 300, flush_every=100)
    written = make_bag(packed, 300, flush_every=100, compression='zstd')
    mcap = os.path.join(packed, 'packed_0.mcap')
    assert _chunk_compressions(mcap) == {'zstd'}
    assert _chunk_compressions(os.path.join(plain, 'plain_0.mcap')) == {''}
    assert os.path.getsize(mcap) < 0.7 * os.path.getsize(os.path.join(plain, 'plain_0.mcap'))
    with open(os.path.join(packed, 'metadata.yaml')) as fh:
        info = yaml.safe_load(fh)['rosbag2_bagfile_information']
    # storage (chunk) compression: rosbag2's own file/message compression fields stay empty
    assert info['compression_format'] == '' and info['compression_mode'] == ''
    sent = make_bag.data
    bag = open_bag(packed)
    assert bag.finalised and bag.notes == []
    own = {}
    for name, _, _, data in bag.messages():
        own.setdefault(name, []).append(data)
    assert own == sent
    assert [data for _, _, _, data in bag.messages('/setpoints')] == sent['/setpoints']
    by_plain = [(n, t) for n, t, _, _ in open_bag(plain).messages()]
    assert [(n, t) for n, t, _, _ in bag.messages()] == by_plain
    with open(mcap, 'rb') as fh:
        by_mcap = {}
        for _, channel, msg in make_reader(fh, validate_crcs=True).iter_messages(
                log_time_order=False):
            by_mcap.setdefault(channel.topic, []).append(bytes(msg.data))
    assert by_mcap == sent
    decoded, counts = _read_with_rosbags_only_stored_definitions(packed)
    assert counts == {name: len(msgs) for name, msgs in written.items()}
    assert [m.header.stamp.nanosec for m in decoded['/joint_states']] == \
        [m.header.stamp.nanosec for m in written['/joint_states']]


def test_killed_zstd_bag_reads_up_to_its_last_flushed_chunk(tmp_path, make_bag):
    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'killed')
    make_bag(path, 250, finalise=False, chunk_size=1 << 30, flush_every=100,
             compression='zstd')
    bag = open_bag(path)
    assert not bag.finalised and 'not finalised' in bag.notes[0]
    assert bag.topics['/joint_states'].count == 200
    assert sum(1 for name, _, _, _ in bag.messages() if name == '/joint_states') == 200


def test_writer_refuses_an_unknown_compression_naming_it(tmp_path):
    from freejoint_tools.bagfile import BagWriter
    with pytest.raises(ValueError, match="compression must be one of none, zstd, got 'lz4'"):
        BagWriter(str(tmp_path / 'run'), compression='lz4')
    assert not os.path.exists(str(tmp_path / 'run'))


def test_decode_topics_reads_several_topics_in_one_pass_as_decode_does_each(tmp_path,
                                                                            make_bag):
    from freejoint_tools.bagfile import BagError, open_bag
    path = str(tmp_path / 'run')
    written = make_bag(path, 30, flush_every=10)
    bag = open_bag(path)
    both = bag.decode_topics(['/joint_states', '/semi_singular_map'])
    assert set(both) == {'/joint_states', '/semi_singular_map'}
    for topic, got in both.items():
        alone = bag.decode(topic)
        assert [t for t, _ in got] == [t for t, _ in alone]
        assert len(got) == len(written[topic])
    assert [m.header.stamp.nanosec for _, m in both['/joint_states']] == \
        [m.header.stamp.nanosec for m in written['/joint_states']]
    with pytest.raises(BagError, match='no topic /nothing in the bag'):
        bag.decode_topics(['/joint_states', '/nothing'])


def test_a_damaged_chunk_of_a_finalised_bag_fails_the_read_naming_the_file(tmp_path,
                                                                           make_bag):
    """Open reads the summary only; the chunk's CRC fails when its messages are read."""
    from mcap.reader import make_reader

    from freejoint_tools.bagfile import BagError, open_bag
    path = str(tmp_path / 'run')
    make_bag(path, 30, flush_every=10)
    mcap = os.path.join(path, 'run_0.mcap')
    with open(mcap, 'rb') as fh:
        second = make_reader(fh).get_summary().chunk_indexes[1]
    with open(mcap, 'r+b') as fh:                  # a byte of its records, past the header
        fh.seek(second.chunk_start_offset + second.chunk_length - 50)
        byte = fh.read(1)
        fh.seek(-1, os.SEEK_CUR)
        fh.write(bytes([byte[0] ^ 0xff]))
    bag = open_bag(path)
    assert len(bag.decode('/semi_singular_map')) == 1     # only in the first chunk
    with pytest.raises(BagError, match='corrupt MCAP data') as info:
        bag.decode('/joint_states')
    assert str(info.value).startswith(mcap + ': ') and '\n' not in str(info.value)


def _record(opcode, body):
    import struct
    return struct.pack('<BQ', opcode, len(body)) + body


def test_a_chunks_messages_are_cut_from_its_records_as_mcap_reads_them():
    """Two Message records around a Channel record, by hand; then damaged ones."""
    import struct

    from mcap.records import Chunk
    from mcap.stream_reader import breakup_chunk

    from freejoint_tools.bagfile import _chunk_messages

    def message(channel, seq, log, pub, data):
        return _record(0x05, struct.pack('<HIQQ', channel, seq, log, pub) + data)
    # opcodes: 0x04 Channel (id, schema id, topic, encoding, empty metadata), 0x05 Message
    channel = _record(0x04, struct.pack('<HHI', 3, 0, 2) + b'/a' + struct.pack('<I', 3)
                      + b'cdr' + struct.pack('<I', 0))
    records = message(3, 1, 1000, 1001, b'abc') + channel + message(3, 2, 2000, 2002, b'')

    def chunk(data):
        return Chunk(message_start_time=1000, message_end_time=2000,
                     uncompressed_size=len(data), uncompressed_crc=0, compression='',
                     data=data)
    # offsets: the first message record 9 + 25 bytes, the channel record 9 + 21
    assert list(_chunk_messages(chunk(records))) == [(0, 3, 1000, 1001, b'abc'),
                                                     (64, 3, 2000, 2002, b'')]
    assert [(r.channel_id, r.log_time, r.publish_time, bytes(r.data))
            for r in breakup_chunk(chunk(records)) if type(r).__name__ == 'Message'] == \
        [m[1:] for m in _chunk_messages(chunk(records))]
    # A record whose length runs 1 byte past the chunk: a damaged chunk, named as such
    cut = records[:-31] + struct.pack('<BQ', 0x05, 23) + records[-22:]
    with pytest.raises(ValueError, match='runs past its chunk'):
        list(_chunk_messages(chunk(cut)))
    # A message record of 21 bytes, one short of its fields
    short = records[:-31] + struct.pack('<BQ', 0x05, 21) + records[-22:-1]
    with pytest.raises(ValueError, match='shorter than its 22-byte fields'):
        list(_chunk_messages(chunk(short)))
