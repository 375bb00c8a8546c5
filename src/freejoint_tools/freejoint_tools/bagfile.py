"""
rosbag2 bags with MCAP storage, written and read without rosbag2 (no ROS imports here).

Layout (what ``ros2 bag record -s mcap`` of ROS 2 Jazzy writes, rosbag2 version 9)::

    <bag>/metadata.yaml          rosbag2_bagfile_information, version 9 (written on close)
    <bag>/<bag name>_0.mcap      MCAP, profile 'ros2': one schema per type (encoding
                                 'ros2msg', the full definition text with its
                                 dependencies), one channel per topic (encoding 'cdr',
                                 metadata 'offered_qos_profiles' (YAML) and
                                 'topic_type_hash' (RIHS01)), messages as received
                                 (log_time = receive time, publish_time = send time), and on
                                 close a metadata record 'rosbag2' with the serialized bag
                                 information, then the MCAP summary (statistics, indexes).

Crash safety: the writer closes the current MCAP chunk and hands the file to the operating
system on every :meth:`BagWriter.flush` (the recorder calls it periodically), so a process
killed without warning (SIGKILL) leaves a file that is complete up to its last flushed
chunk. Such a bag has no ``metadata.yaml`` and no MCAP summary; :func:`open_bag` reads it up
to the last complete record and reports it as not finalised. A bag that *has* a
``metadata.yaml`` but whose MCAP file is cut short or disagrees with it is corrupt and
refused.

Run information (case, variant, seed, ...) given to the recorder is written twice: at once,
as an MCAP metadata record ``freejoint_run`` (so a killed bag still has it), and on close as
``custom_data`` of ``metadata.yaml`` (what ``ros2 bag record --custom-data`` writes).
"""

import io
import os
import struct

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema,
                          Statistics)
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer
import yaml

VERSION = 9
STORAGE = 'mcap'
MAGIC = b'\x89MCAP0\r\n'
LIBRARY = 'freejoint_tools (rosbag2 v9 layout)'
RUN_RECORD = 'freejoint_run'
METADATA_FILE = 'metadata.yaml'
# rosbag2 writes an infinite duration as this (sec, nsec) pair.
INFINITE = (9223372036, 854775807)


class BagError(Exception):
    """
    A bag that cannot be read or written; ``str()`` is one line naming the file.

    Attributes
    ----------
    path : str
        The file or directory at fault.
    problem : str
        What is wrong with it.

    """

    def __init__(self, path, problem):
        self.path = str(path)
        self.problem = problem
        super().__init__('%s: %s' % (self.path, problem))


def default_qos_dict(reliability='reliable', durability='volatile', history='keep_last',
                     depth=0):
    """Return a QoS profile as rosbag2 version 9 writes it (plain dict, infinite times)."""
    inf = {'sec': INFINITE[0], 'nsec': INFINITE[1]}
    return {
        'history': history, 'depth': int(depth), 'reliability': reliability,
        'durability': durability, 'deadline': dict(inf), 'lifespan': dict(inf),
        'liveliness': 'automatic', 'liveliness_lease_duration': dict(inf),
        'avoid_ros_namespace_conventions': False,
    }


def _dump_yaml(data):
    return yaml.safe_dump(data, default_flow_style=False, sort_keys=False)


class BagWriter:
    """
    Write a rosbag2 (version 9) bag with MCAP storage.

    Parameters
    ----------
    path : str
        Bag directory to create (must not exist, or be an empty directory).
    custom_data : dict of str to str, optional
        Run information, stored at once in the MCAP file and on close in metadata.yaml.
    chunk_size : int
        MCAP chunk size (bytes); a chunk is also closed by every :meth:`flush`.
    ros_distro : str
        Written as ``ros_distro`` in the metadata.

    """

    def __init__(self, path, custom_data=None, chunk_size=256 * 1024, ros_distro='jazzy'):
        self.path = os.fspath(path)
        if os.path.exists(self.path) and not (os.path.isdir(self.path)
                                              and not os.listdir(self.path)):
            raise BagError(self.path, 'exists already, not overwriting')
        try:
            os.makedirs(self.path, exist_ok=True)
        except OSError as exc:
            raise BagError(self.path, 'cannot create the bag directory: %s' % exc.strerror)
        name = os.path.basename(os.path.normpath(self.path))
        self.file_name = name + '_0.mcap'
        self.mcap_path = os.path.join(self.path, self.file_name)
        self.custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self.ros_distro = ros_distro
        self._file = open(self.mcap_path, 'xb')
        self._writer = Writer(self._file, chunk_size=int(chunk_size),
                              compression=CompressionType.NONE)
        self._writer.start(profile='ros2', library=LIBRARY)
        if self.custom_data:
            self._writer.add_metadata(RUN_RECORD, dict(self.custom_data))
        self._schemas = {}
        self.topics = {}       # channel id -> dict(name, type, qos, hash, count)
        self._counts = {}      # channel id -> messages written
        self.start_ns = None
        self.end_ns = None
        self.closed = False
        self._file.flush()

    def add_topic(self, topic, msgtype, msgdef, type_hash='', qos_profiles=()):
        """
        Register a topic; return its channel id for :meth:`write`.

        Parameters
        ----------
        topic : str
            Fully qualified topic name.
        msgtype : str
            ``pkg/msg/Type``.
        msgdef : str
            Full ``ros2msg`` definition text (with ``MSG:`` sections for dependencies);
            empty if unknown.
        type_hash : str
            RIHS01 type description hash, empty if unknown.
        qos_profiles : sequence of dict
            Offered QoS profiles (:func:`default_qos_dict` format).

        """
        for info in self.topics.values():
            if info['name'] == topic:
                raise BagError(self.mcap_path, 'topic %s added twice' % topic)
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._writer.register_schema(
                msgtype, 'ros2msg' if msgdef else '', msgdef.encode('utf-8'))
        qos = [dict(p) for p in qos_profiles]
        channel = self._writer.register_channel(
            topic, 'cdr', self._schemas[msgtype],
            {'offered_qos_profiles': _dump_yaml(qos) if qos else '',
             'topic_type_hash': type_hash or ''})
        self.topics[channel] = {'name': topic, 'type': msgtype, 'qos': qos,
                                'hash': type_hash or ''}
        self._counts[channel] = 0
        return channel

    def write(self, channel, log_time, data, publish_time=None):
        """Write serialized ``data`` (CDR bytes) received at ``log_time`` (ns)."""
        n = self._counts[channel]
        sent = log_time if publish_time is None else publish_time
        self._writer.add_message(channel, log_time, data, sent, n & 0xffffffff)
        self._counts[channel] = n + 1
        if self.start_ns is None or log_time < self.start_ns:
            self.start_ns = log_time
        if self.end_ns is None or log_time > self.end_ns:
            self.end_ns = log_time

    def count(self, channel):
        """Return the number of messages written on ``channel``."""
        return self._counts[channel]

    def flush(self):
        """Close the current chunk and hand everything written to the operating system."""
        if not self.closed:
            self._writer.flush()

    def metadata(self):
        """Return the rosbag2 version 9 bag information (the dict under the root key)."""
        start = self.start_ns or 0
        duration = (self.end_ns - self.start_ns) if self.start_ns is not None else 0
        total = sum(self._counts.values())
        return {
            'version': VERSION,
            'storage_identifier': STORAGE,
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': total,
            'topics_with_message_count': [
                {'topic_metadata': {'name': t['name'], 'type': t['type'],
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': t['qos'],
                                    'type_description_hash': t['hash']},
                 'message_count': self._counts[c]}
                for c, t in self.topics.items()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.file_name],
            'files': [{'path': self.file_name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': total}],
            'custom_data': dict(self.custom_data) if self.custom_data else None,
            'ros_distro': self.ros_distro,
        }

    def close(self):
        """Finalise: metadata record, MCAP summary and footer, then metadata.yaml."""
        if self.closed:
            return
        info = self.metadata()
        self._writer.add_metadata('rosbag2', {'serialized_metadata': _dump_yaml(info)})
        self._writer.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()
        self.closed = True
        tmp = os.path.join(self.path, METADATA_FILE + '.tmp')
        with open(tmp, 'w', encoding='utf-8') as fh:
            fh.write(_dump_yaml({'rosbag2_bagfile_information': info}))
        os.replace(tmp, os.path.join(self.path, METADATA_FILE))

    def abandon(self):
        """Close the file as it is (no summary, no metadata.yaml), like a crash would."""
        if not self.closed:
            self._file.close()
            self.closed = True


class Topic:
    """
    One topic of a bag.

    Attributes
    ----------
    name, type : str
        Topic name and ``pkg/msg/Type``.
    msgdef : str
        Message definition stored in the bag (``ros2msg`` text).
    type_hash : str
        RIHS01 hash stored in the bag (may be empty).
    qos : list of dict
        Offered QoS profiles as recorded.
    count : int
        Messages of this topic readable in the bag.

    """

    def __init__(self, name, msgtype, msgdef, type_hash, qos):
        self.name = name
        self.type = msgtype
        self.msgdef = msgdef
        self.type_hash = type_hash
        self.qos = qos
        self.count = 0

    def __repr__(self):
        return 'Topic(%r, %r, count=%d)' % (self.name, self.type, self.count)


class Bag:
    """
    A bag read by :func:`open_bag` (all messages in memory, in file order).

    Attributes
    ----------
    path : str
        Bag directory.
    files : list of str
        MCAP files read.
    finalised : bool
        True if the bag has its metadata.yaml and every MCAP file its summary and footer.
    notes : list of str
        What was found wrong but tolerated (a bag not finalised), one line each.
    metadata : dict or None
        ``rosbag2_bagfile_information`` of metadata.yaml (None if absent).
    custom_data : dict
        Run information (metadata.yaml ``custom_data``, else the MCAP run record).
    topics : dict of str to Topic
        By topic name.
    messages : list of tuple
        ``(topic name, log_time ns, publish_time ns, data bytes)`` in file order.

    """

    def __init__(self, path):
        self.path = path
        self.files = []
        self.finalised = True
        self.notes = []
        self.metadata = None
        self.custom_data = {}
        self.topics = {}
        self.messages = []

    @property
    def message_count(self):
        """Return the number of readable messages."""
        return len(self.messages)

    def topics_of_type(self, msgtype):
        """Return the names of the topics of type ``msgtype``, sorted."""
        return sorted(n for n, t in self.topics.items() if t.type == msgtype)

    def typestore(self):
        """
        Return a rosbags type store built from the definitions stored in the bag only.

        Raises
        ------
        BagError
            If a stored definition cannot be parsed or two definitions disagree.

        """
        from rosbags.typesys import get_types_from_msg, get_typestore, Stores
        store = get_typestore(Stores.EMPTY)
        for topic in self.topics.values():
            if not topic.msgdef:
                continue
            try:
                store.register(get_types_from_msg(topic.msgdef, topic.type))
            except Exception as exc:  # rosbags raises several kinds here
                raise BagError(self.files[0] if self.files else self.path,
                               'stored definition of %s (topic %s) unusable: %s'
                               % (topic.type, topic.name, str(exc).splitlines()[0]))
        return store

    def decode(self, topic, store=None):
        """
        Return ``[(log_time ns, message), ...]`` of ``topic``, decoded with the bag's types.

        The messages are rosbags dataclasses with the field names of the ROS message.
        """
        if topic not in self.topics:
            raise BagError(self.path, 'no topic %s in the bag' % topic)
        store = store or self.typestore()
        msgtype = self.topics[topic].type
        out = []
        for name, log_time, _, data in self.messages:
            if name == topic:
                try:
                    out.append((log_time, store.deserialize_cdr(data, msgtype)))
                except Exception as exc:  # malformed CDR raises various errors
                    raise BagError(self.files[0], 'message %d of %s does not decode as %s: %s'
                                   % (len(out), topic, msgtype, exc))
        return out


_RECORDS = {
    Opcode.HEADER: Header, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
    Opcode.METADATA: Metadata, Opcode.DATA_END: DataEnd, Opcode.FOOTER: Footer,
    Opcode.STATISTICS: Statistics, Opcode.CHUNK: Chunk,
}


class _Scan:
    """What one pass over an MCAP file found."""

    def __init__(self):
        self.header = None
        self.schemas = {}
        self.channels = {}
        self.messages = []          # (channel id, log_time, publish_time, data)
        self.metadata = {}
        self.statistics = None
        self.footer = False
        self.truncated_at = None    # byte offset of the first incomplete record
        self.size = 0


def _parse(opcode, body):
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    cls = _RECORDS.get(opcode)
    return cls.read(stream) if cls else None


def _take(scan, record):
    if isinstance(record, Schema):
        scan.schemas[record.id] = record
    elif isinstance(record, Channel):
        scan.channels[record.id] = record
    elif isinstance(record, Message):
        scan.messages.append((record.channel_id, record.log_time, record.publish_time,
                              bytes(record.data)))
    elif isinstance(record, Metadata):
        scan.metadata[record.name] = dict(record.metadata)
    elif isinstance(record, Statistics):
        scan.statistics = record
    elif isinstance(record, Header):
        scan.header = record


def _scan_mcap(path):
    """Read every complete record of an MCAP file in order; note where it is cut short."""
    scan = _Scan()
    try:
        scan.size = os.path.getsize(path)
        fh = open(path, 'rb')
    except OSError as exc:
        raise BagError(path, 'cannot read: %s' % exc.strerror)
    with fh:
        if fh.read(8) != MAGIC:
            raise BagError(path, 'not an MCAP file (no MCAP magic at the start)')
        offset = 8
        while True:
            head = fh.read(9)
            if not head:
                break                                   # ends on a record boundary
            if len(head) < 9:
                scan.truncated_at = offset
                break
            opcode, length = struct.unpack('<BQ', head)
            if length > scan.size - offset - 9:
                scan.truncated_at = offset
                break
            body = fh.read(length)
            try:
                record = _parse(opcode, body)
                if isinstance(record, Chunk):
                    for inner in breakup_chunk(record, validate_crc=True):
                        _take(scan, inner)
                else:
                    _take(scan, record)
            except (McapError, struct.error, UnicodeDecodeError, ValueError, KeyError) as exc:
                raise BagError(path, 'corrupt MCAP record (opcode 0x%02x) at byte %d: %s'
                               % (opcode, offset, str(exc) or type(exc).__name__))
            if scan.header is None:
                raise BagError(path, 'not an MCAP file (first record is not a header)')
            offset += 9 + length
            if isinstance(record, Footer):
                scan.footer = fh.read(8) == MAGIC
                if not scan.footer:
                    scan.truncated_at = offset
                break
    if scan.header is None:
        raise BagError(path, 'MCAP file cut short before its header (%d bytes)' % scan.size)
    if scan.header.profile != 'ros2':
        raise BagError(path, "MCAP profile is %r, not 'ros2' (not a ROS 2 bag)"
                       % scan.header.profile)
    return scan


def _load_metadata(path):
    meta_path = os.path.join(path, METADATA_FILE)
    try:
        with open(meta_path, encoding='utf-8') as fh:
            data = yaml.safe_load(fh)
    except OSError as exc:
        raise BagError(meta_path, 'cannot read: %s' % exc.strerror)
    except yaml.YAMLError as exc:
        raise BagError(meta_path, 'not valid YAML (%s)' % str(exc).splitlines()[0])
    if not isinstance(data, dict) or not isinstance(
            data.get('rosbag2_bagfile_information'), dict):
        raise BagError(meta_path, 'not rosbag2 metadata (no rosbag2_bagfile_information)')
    info = data['rosbag2_bagfile_information']
    storage = info.get('storage_identifier')
    if storage != STORAGE:
        raise BagError(meta_path, 'storage %r is not supported (only mcap)' % storage)
    files = info.get('relative_file_paths')
    if not isinstance(files, list) or not files or not all(isinstance(f, str) for f in files):
        raise BagError(meta_path, 'relative_file_paths missing or empty')
    if info.get('compression_mode'):
        raise BagError(meta_path, 'compressed bags (%s) are not supported'
                       % info.get('compression_mode'))
    return info


def _qos_list(text):
    if not text:
        return []
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return []
    return value if isinstance(value, list) else []


def open_bag(path):
    """
    Read a rosbag2 bag with MCAP storage (a directory, or one of its ``.mcap`` files).

    A finalised bag (metadata.yaml, MCAP summary) must agree with its metadata. A bag
    without metadata.yaml (its recorder was killed) is read up to the last complete
    record of its MCAP file; ``finalised`` is False and ``notes`` says so.

    Returns
    -------
    Bag

    Raises
    ------
    BagError
        Naming the file: missing, not a rosbag2/MCAP bag, truncated or corrupt.

    """
    path = os.fspath(path)
    if os.path.isfile(path) and path.endswith('.mcap'):
        path = os.path.dirname(path) or '.'
    if not os.path.exists(path):
        raise BagError(path, 'no such bag (directory does not exist)')
    if not os.path.isdir(path):
        raise BagError(path, 'not a rosbag2 bag (not a directory)')
    bag = Bag(path)
    meta_path = os.path.join(path, METADATA_FILE)
    if os.path.exists(meta_path):
        bag.metadata = _load_metadata(path)
        files = [os.path.join(path, f) for f in bag.metadata['relative_file_paths']]
        for f in files:
            if not os.path.isfile(f):
                raise BagError(f, 'listed in metadata.yaml but missing')
    else:
        files = sorted(os.path.join(path, f) for f in os.listdir(path) if f.endswith('.mcap'))
        if not files:
            raise BagError(path, 'not a rosbag2 bag (no metadata.yaml and no .mcap file)')
        bag.finalised = False
    bag.files = files
    by_channel = {}
    for f in files:
        scan = _scan_mcap(f)
        if bag.metadata is not None and (scan.truncated_at is not None or not scan.footer):
            raise BagError(f, 'truncated at byte %d of %d (the bag claims to be finalised)'
                           % (scan.truncated_at or scan.size, scan.size))
        if scan.truncated_at is not None or not scan.footer:
            bag.finalised = False
            bag.notes.append('%s: not finalised (recorder stopped without closing the bag?); '
                             'read %d messages up to byte %d of %d'
                             % (f, len(scan.messages), scan.truncated_at or scan.size,
                                scan.size))
        if RUN_RECORD in scan.metadata:
            bag.custom_data.update(scan.metadata[RUN_RECORD])
        for cid, channel in scan.channels.items():
            schema = scan.schemas.get(channel.schema_id)
            if channel.schema_id and schema is None:
                raise BagError(f, 'channel %s has no schema' % channel.topic)
            if channel.topic not in bag.topics:
                bag.topics[channel.topic] = Topic(
                    channel.topic, schema.name if schema else '',
                    schema.data.decode('utf-8', 'replace') if schema else '',
                    channel.metadata.get('topic_type_hash', ''),
                    _qos_list(channel.metadata.get('offered_qos_profiles', '')))
            by_channel[(f, cid)] = channel.topic
        for cid, log_time, pub_time, data in scan.messages:
            topic = by_channel.get((f, cid))
            if topic is None:
                raise BagError(f, 'message on unknown channel %d' % cid)
            bag.topics[topic].count += 1
            bag.messages.append((topic, log_time, pub_time, data))
        if scan.statistics is not None and scan.statistics.message_count != len(scan.messages):
            raise BagError(f, 'holds %d messages, its statistics say %d'
                           % (len(scan.messages), scan.statistics.message_count))
    if bag.metadata is not None:
        bag.custom_data.update(bag.metadata.get('custom_data') or {})
        _check_counts(bag, meta_path)
    elif not bag.notes:
        bag.notes.append('%s: no metadata.yaml (bag not finalised)' % path)
    return bag


def _check_counts(bag, meta_path):
    listed = {}
    for entry in bag.metadata.get('topics_with_message_count') or []:
        try:
            listed[entry['topic_metadata']['name']] = int(entry['message_count'])
        except (KeyError, TypeError, ValueError):
            raise BagError(meta_path, 'malformed topics_with_message_count entry')
    for name, topic in bag.topics.items():
        if name in listed and listed[name] != topic.count:
            raise BagError(bag.files[0], 'holds %d messages on %s, metadata.yaml lists %d'
                           % (topic.count, name, listed[name]))
    missing = sorted(set(listed) - set(bag.topics))
    if missing:
        raise BagError(meta_path, 'lists topic %s, not in the MCAP file' % missing[0])
