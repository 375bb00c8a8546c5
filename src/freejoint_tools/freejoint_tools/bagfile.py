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
                                 Chunks plain or zstd-compressed (BagWriter ``compression``,
                                 rosbag2's MCAP storage option ``compression: Zstd``).

Reading (:func:`open_bag`) is mcap's: the indexed reader's summary for a finalised file, the
StreamReader for one cut short; the messages are read chunk by chunk, never the whole bag.

Crash safety: the writer closes the current MCAP chunk and hands the file to the operating
system on every :meth:`BagWriter.flush` (the recorder calls it periodically), so a process
killed without warning (SIGKILL) leaves a file that is complete up to its last flushed
chunk. Such a bag has no ``metadata.yaml`` and no MCAP summary; :func:`open_bag` reads it up
to its last complete chunk and reports it as not finalised. A bag that *has* a
``metadata.yaml`` but whose MCAP file is cut short or disagrees with it is corrupt and
refused.

Run information (case, variant, seed, ...) given to the recorder is written twice: at once,
as an MCAP metadata record ``freejoint_run`` (so a killed bag still has it), and on close as
``custom_data`` of ``metadata.yaml`` (what ``ros2 bag record --custom-data`` writes).

Write errors (a full disk): what the mcap writer produces is handed to the file in whole
records (every chunk with its message indexes); a write that fails is cut off again
(``ftruncate`` to the last complete record), so the file stays readable up to the error.
From then on nothing more is written and every message is counted lost for its topic
(:meth:`BagWriter.lost`); :meth:`BagWriter.close` still finalises the bag: it frees the
space it kept in reserve (a ``.reserve`` file next to the MCAP file, sized for the summary),
and writes the summary of the complete records in place (:func:`finalise_mcap`) and
``metadata.yaml``. :func:`finalise_mcap` also repairs the bag of a killed recorder (the
``reindex`` command).
"""

import errno
import os
import struct
import zlib

from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader, NonSeekingReader
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message,
                          MessageIndex, Metadata, MetadataIndex, Schema, Statistics,
                          SummaryOffset)
from mcap.stream_reader import breakup_chunk, get_chunk_data_stream, StreamReader
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
RESERVE_SUFFIX = '.reserve'
# BagWriter's compression values: the MCAP chunk compression each one writes.
COMPRESSIONS = {'none': CompressionType.NONE, 'zstd': CompressionType.ZSTD}
# Space kept free for finalising (summary, metadata record, metadata.yaml): this much plus
# twice the size the chunk indexes have reached.
RESERVE_BASE = 256 * 1024
_NO_TIME = 1 << 63
SYSTEM_TIME_NS = 10 ** 18
"""Stamps (ns) from this one on (2001-09-09, 1e9 s of Unix time) are system time: a
real-time run's, never a sim clock's (sim time starts at 0; a lockstep run would need 31
years to get there). The recorder counts ticks and the analysis keeps the stamps as
they are only below it; above it both use the time from the first stamp."""


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


def bag_information(file_name, topics, counts, start_ns, end_ns, custom_data, ros_distro):
    """
    Return the rosbag2 version 9 bag information (the dict under the root key).

    Parameters
    ----------
    file_name : str
        The MCAP file, relative to the bag directory.
    topics : sequence of dict
        ``name``, ``type``, ``qos`` (list of dict), ``hash`` (str) per topic.
    counts : sequence of int
        Messages in the file per topic, in the order of ``topics``.
    start_ns, end_ns : int or None
        Log times (ns) of the first and last message in the file (None: no message).
    custom_data : dict of str to str
        Run information (None or empty: none).
    ros_distro : str
        Written as ``ros_distro``.

    """
    start = start_ns or 0
    duration = (end_ns - start_ns) if start_ns is not None else 0
    total = sum(counts)
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
             'message_count': n}
            for t, n in zip(topics, counts)],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{'path': file_name,
                   'starting_time': {'nanoseconds_since_epoch': start},
                   'duration': {'nanoseconds': duration},
                   'message_count': total}],
        'custom_data': dict(custom_data) if custom_data else None,
        'ros_distro': ros_distro,
    }


def write_metadata_yaml(path, info):
    """Write ``<path>/metadata.yaml`` (via a temporary file); raise BagError if it cannot."""
    tmp = os.path.join(path, METADATA_FILE + '.tmp')
    try:
        with open(tmp, 'w', encoding='utf-8') as fh:
            fh.write(_dump_yaml({'rosbag2_bagfile_information': info}))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, os.path.join(path, METADATA_FILE))
    except OSError as exc:
        try:
            os.remove(tmp)
        except OSError:
            pass
        raise BagError(os.path.join(path, METADATA_FILE),
                       'cannot write: %s' % (exc.strerror or exc))


class _Sink:
    """
    The mcap writer's output stream: bytes gathered in memory, handed to the file by commit.

    The writer only ever leaves complete records here when one of its calls returns, so a
    commit that fails can be cut off again and the file always ends on a record boundary.
    """

    def __init__(self, fd):
        self.fd = fd
        self._parts = []
        self.pending = 0       # bytes written by the mcap writer, not yet in the file
        self.committed = 0     # bytes in the file
        self.error = None      # the OSError of the first failed commit

    def write(self, data):
        if self.error is None:
            self._parts.append(bytes(data))
        self.pending += len(data)
        return len(data)

    def tell(self):
        return self.committed + self.pending

    def flush(self):
        """Do nothing: :meth:`commit` hands the data to the file."""

    def commit(self):
        """Write what is pending to the file; on an error cut it off and return False."""
        if self.error is not None:
            self._parts, self.pending = [], 0
            return False
        if not self.pending:
            return True
        data = b''.join(self._parts)
        self._parts = []
        view = memoryview(data)
        done = 0
        try:
            while done < len(data):
                done += os.write(self.fd, view[done:])
        except OSError as exc:
            self.error = exc
            self.pending = 0
            try:
                os.ftruncate(self.fd, self.committed)
                os.lseek(self.fd, self.committed, os.SEEK_SET)
            except OSError:
                pass
            return False
        self.committed += len(data)
        self.pending = 0
        return True


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
        MCAP chunk size (bytes, before compression); a chunk is also closed by every
        :meth:`flush`.
    ros_distro : str
        Written as ``ros_distro`` in the metadata.
    compression : {'none', 'zstd'}
        Chunk compression: what rosbag2's MCAP storage writes with the storage option
        ``compression: Zstd``. The file stays indexed and every MCAP reader decompresses
        the chunks itself; metadata.yaml keeps ``compression_format`` and
        ``compression_mode`` empty as rosbag2 does for it (they describe rosbag2's own
        file or message compression, which readers undo before the storage).

    Raises
    ------
    ValueError
        If ``compression`` is not one of :data:`COMPRESSIONS`.
    BagError
        If the bag directory or file cannot be created.

    Notes
    -----
    A message is in the file once the chunk holding it is: when the chunk fills up
    (``chunk_size``), at :meth:`flush` and at :meth:`close`. If the file system refuses a
    write (``error`` is then set), that chunk and every later message are counted lost
    for their topics (:meth:`lost`) and the file keeps what was written before.

    """

    def __init__(self, path, custom_data=None, chunk_size=256 * 1024, ros_distro='jazzy',
                 compression='none'):
        if compression not in COMPRESSIONS:
            raise ValueError('compression must be one of %s, got %r'
                             % (', '.join(COMPRESSIONS), compression))
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
        try:
            self._fd = os.open(self.mcap_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as exc:
            raise BagError(self.mcap_path, 'cannot create: %s' % exc.strerror)
        self._reserve_path = os.path.join(self.path, '.' + name + RESERVE_SUFFIX)
        self._reserved = 0
        self._keep_reserve(RESERVE_BASE)
        self._sink = _Sink(self._fd)
        self._writer = Writer(self._sink, chunk_size=int(chunk_size),
                              compression=COMPRESSIONS[compression])
        self._writer.start(profile='ros2', library=LIBRARY)
        if self.custom_data:
            self._writer.add_metadata(RUN_RECORD, dict(self.custom_data))
        self._schemas = {}
        self.topics = {}       # channel id -> dict(name, type, qos, hash)
        self._counts = {}      # channel id -> messages in the file
        self._pending = {}     # channel id -> messages handed to the writer, not in the file
        self._lost = {}        # channel id -> messages that did not reach the file
        self._pend_first = _NO_TIME  # log times of the pending messages
        self._pend_last = -_NO_TIME
        self._stopped = False        # closed or failed: nothing more reaches the file
        self._chunks = 0
        self.start_ns = None
        self.end_ns = None
        self.closed = False
        self.error = None      # str: the write error that stopped the bag (None: none)
        self.error_at = None   # bytes in the file when it happened
        self._commit()

    # -- reserve ------------------------------------------------------------------------
    def _keep_reserve(self, size):
        """Grow the reserve file to ``size`` bytes (best effort: a full disk stops it)."""
        if size <= self._reserved:
            return
        try:
            fd = os.open(self._reserve_path, os.O_WRONLY | os.O_CREAT, 0o644)
            try:
                os.posix_fallocate(fd, 0, size)
                self._reserved = size
            finally:
                os.close(fd)
        except OSError:
            pass

    def _free_reserve(self):
        try:
            os.remove(self._reserve_path)
        except FileNotFoundError:
            pass
        self._reserved = 0

    # -- writing ------------------------------------------------------------------------
    def _commit(self):
        """Hand what the mcap writer produced to the file; account its messages."""
        if self.error is None and self._sink.commit():
            first, last = self._pend_first, self._pend_last
            if first <= last:
                if self.start_ns is None or first < self.start_ns:
                    self.start_ns = first
                if self.end_ns is None or last > self.end_ns:
                    self.end_ns = last
            for channel, n in self._pending.items():
                self._counts[channel] += n
        else:
            if self.error is None:
                exc = self._sink.error
                self.error = exc.strerror or str(exc)
                self.error_at = self._sink.committed
                if exc.errno == errno.ENOSPC:
                    self.error = 'disk full (%s)' % self.error
                self._stopped = True
            for channel, n in self._pending.items():
                self._lost[channel] += n
        for channel in self._pending:
            self._pending[channel] = 0
        self._pend_first, self._pend_last = _NO_TIME, -_NO_TIME

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
        self._pending[channel] = 0
        self._lost[channel] = 0
        return channel

    def write(self, channel, log_time, data, publish_time=None):
        """Write serialized ``data`` (CDR bytes) received at ``log_time`` (ns)."""
        if self._stopped:
            self._lost[channel] += 1
            return
        pending = self._pending
        sink = self._sink
        before = sink.pending
        self._writer.add_message(channel, log_time, data,
                                 log_time if publish_time is None else publish_time,
                                 (self._counts[channel] + pending[channel]) & 0xffffffff)
        pending[channel] += 1
        if log_time > self._pend_last:
            self._pend_last = log_time
        if log_time < self._pend_first:
            self._pend_first = log_time
        if sink.pending != before:            # a chunk closed: every message is in it
            self._chunks += 1
            self._commit()

    def count(self, channel):
        """Return the number of messages of ``channel`` in the file."""
        return self._counts[channel]

    def lost(self, channel):
        """Return the number of messages of ``channel`` that did not reach the file."""
        return self._lost[channel]

    def flush(self):
        """Close the current chunk and hand everything written to the operating system."""
        if self.closed or self.error is not None:
            return
        if any(self._pending.values()):
            self._chunks += 1
        self._writer.flush()
        self._commit()
        self._keep_reserve(RESERVE_BASE + 2 * self._chunks * (80 + 10 * len(self.topics)))

    def metadata(self):
        """Return the rosbag2 version 9 bag information of what is in the file now."""
        channels = list(self.topics)
        return bag_information(self.file_name, [self.topics[c] for c in channels],
                               [self._counts[c] for c in channels], self.start_ns,
                               self.end_ns, self.custom_data, self.ros_distro)

    def close(self):
        """
        Finalise: metadata record, MCAP summary and footer, then metadata.yaml.

        After a write error (or if the summary itself cannot be written) the summary of what
        the file holds is written in place (:func:`finalise_mcap`) once the reserve is freed.

        Raises
        ------
        BagError
            If the bag cannot be finalised (the disk is full even without the reserve).

        """
        if self.closed:
            return
        self.closed = True
        self._stopped = True
        self._free_reserve()
        if self.error is None:
            self._writer.flush()
            if any(self._pending.values()):
                self._chunks += 1
            self._commit()
        if self.error is None:
            info = self.metadata()
            self._writer.add_metadata('rosbag2', {'serialized_metadata': _dump_yaml(info)})
            self._writer.finish()
            if self._sink.commit():
                self._finish_file()
                write_metadata_yaml(self.path, info)
                return
        try:
            os.close(self._fd)
        except OSError:
            pass
        info = self.metadata()
        finalise_mcap(self.mcap_path, {'serialized_metadata': _dump_yaml(info)})
        write_metadata_yaml(self.path, info)

    def _finish_file(self):
        try:
            os.fsync(self._fd)
        except OSError:
            pass
        os.close(self._fd)

    def abandon(self):
        """Close the file as it is (no summary, no metadata.yaml, the reserve), as a crash."""
        if not self.closed:
            self._sink.commit()
            os.close(self._fd)
            self.closed = self._stopped = True


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
    A bag opened by :func:`open_bag`: its topics and counts; the messages read on demand.

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

    """

    def __init__(self, path):
        self.path = path
        self.files = []
        self.finalised = True
        self.notes = []
        self.metadata = None
        self.custom_data = {}
        self.topics = {}
        self._sources = []

    @property
    def message_count(self):
        """Return the number of readable messages."""
        return sum(t.count for t in self.topics.values())

    def topics_of_type(self, msgtype):
        """Return the names of the topics of type ``msgtype``, sorted."""
        return sorted(n for n, t in self.topics.items() if t.type == msgtype)

    def messages(self, topics=None):
        """
        Yield the messages in file order, one chunk in memory at a time.

        Parameters
        ----------
        topics : str or iterable of str, optional
            Only these topics (default: all); chunks without them are not read.

        Yields
        ------
        tuple
            ``(topic name, log_time ns, publish_time ns, data bytes)``.

        Raises
        ------
        BagError
            Naming the file, if a chunk cannot be read (a CRC mismatch, a damaged record).

        """
        wanted = None if topics is None else (
            {topics} if isinstance(topics, str) else set(topics))
        for source in self._sources:
            yield from source.messages(wanted)

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
        return self.decode_topics([topic], store)[topic]

    def decode_topics(self, topics, store=None):
        """
        Return ``{topic: [(log_time ns, message), ...]}`` of ``topics``, in one pass.

        As :meth:`decode` for each topic, reading the bag once for all of them.
        """
        for topic in topics:
            if topic not in self.topics:
                raise BagError(self.path, 'no topic %s in the bag' % topic)
        store = store or self.typestore()
        types = {topic: self.topics[topic].type for topic in topics}
        out = {topic: [] for topic in topics}
        for topic, log_time, _, data in self.messages(topics):
            try:
                out[topic].append((log_time, store.deserialize_cdr(data, types[topic])))
            except Exception as exc:  # malformed CDR raises various errors
                raise BagError(self.files[0], 'message %d of %s does not decode as %s: %s'
                               % (len(out[topic]), topic, types[topic], exc))
        return out


_READ_ERRORS = (McapError, struct.error, ValueError, UnicodeDecodeError, KeyError, EOFError)


class _McapFile:
    """
    The readable part of one MCAP file: its channels and its complete chunks.

    ``chunks`` are ``(chunk start offset, channel ids in it or None: unknown)`` in file
    order: from the chunk indexes of the summary (finalised file), or from what
    :func:`scan_mcap` found up to where the file is cut; None: a finalised file without
    chunks (every message in the data section), read through with mcap's stream reader.
    """

    def __init__(self, path, topics, chunks):
        self.path = path
        self.topics = topics            # channel id -> topic name
        self.chunks = chunks

    def messages(self, wanted):
        ids = None if wanted is None else {c for c, t in self.topics.items() if t in wanted}
        if ids is not None and not ids:
            return
        try:
            with open(self.path, 'rb') as fh:
                if self.chunks is None:
                    for _, channel, msg in NonSeekingReader(fh, validate_crcs=True) \
                            .iter_messages(wanted, log_time_order=False):
                        yield channel.topic, msg.log_time, msg.publish_time, bytes(msg.data)
                    return
                for start, channels in self.chunks:
                    if ids is not None and channels is not None and ids.isdisjoint(channels):
                        continue
                    fh.seek(start + 9)                          # opcode, record length
                    chunk = Chunk.read(ReadDataStream(fh))
                    for _, channel_id, log_time, publish_time, data in _chunk_messages(chunk):
                        if ids is None or channel_id in ids:
                            yield self.topics[channel_id], log_time, publish_time, data
        except OSError as exc:
            raise BagError(self.path, 'cannot read: %s' % (exc.strerror or exc))
        except _READ_ERRORS as exc:
            raise BagError(self.path, 'corrupt MCAP data: %s'
                           % (str(exc).splitlines()[0] if str(exc) else type(exc).__name__))


_MESSAGE_HEAD = struct.Struct('<HIQQ')
"""A Message record's fields before its data: channel id, sequence, log and publish time."""


def _chunk_messages(chunk):
    """
    Yield ``(offset, channel id, log_time, publish_time, data bytes)`` of a Chunk's Messages.

    ``offset``: where the Message record starts in the chunk's uncompressed records (what
    MCAP's message index holds).

    The chunk is decompressed and its CRC checked as mcap's ``breakup_chunk`` does; the
    records are then cut from its bytes with one unpack each (mcap's record classes read
    each field through a stream: most of the time of reading a bag). Other records (the
    Schema and Channel records a chunk may hold) are skipped.

    Raises
    ------
    ValueError
        A record runs past the end of the chunk, or a Message record is shorter than its
        fields (a damaged chunk); mcap's CRC error is a ValueError too.
    struct.error
        A record's header or a Message's fields are cut short.

    """
    stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    data = stream.read(size)
    unpack_length = struct.Struct('<BQ').unpack_from
    unpack_head = _MESSAGE_HEAD.unpack_from
    head = _MESSAGE_HEAD.size
    pos = 0
    while pos < size:
        opcode, length = unpack_length(data, pos)
        pos += 9
        end = pos + length
        if end > size:
            raise ValueError('record of %d bytes at %d runs past its chunk of %d bytes'
                             % (length, pos - 9, size))
        if opcode == Opcode.MESSAGE:
            if length < head:
                raise ValueError('message record of %d bytes at %d, shorter than its %d-byte '
                                 'fields' % (length, pos - 9, head))
            channel_id, _, log_time, publish_time = unpack_head(data, pos)
            yield pos - 9, channel_id, log_time, publish_time, data[pos + head:end]
        pos = end


def _check_magic(path):
    try:
        with open(path, 'rb') as fh:
            if fh.read(len(MAGIC)) != MAGIC:
                raise BagError(path, 'not an MCAP file (no MCAP magic at the start)')
    except OSError as exc:
        raise BagError(path, 'cannot read: %s' % exc.strerror)


def _read_summary(path):
    """
    Return ``(header, summary, run record or None)`` of a finalised MCAP file.

    With mcap's indexed reader (``make_reader``: footer, summary, metadata index). Raise
    BagError naming where the file is cut short if it has no readable summary.
    """
    try:
        with open(path, 'rb') as fh:
            reader = make_reader(fh, validate_crcs=True)
            header = reader.get_header()
            summary = reader.get_summary()
            if summary is not None:
                run = [dict(m.metadata) for m in reader.iter_metadata()
                       if m.name == RUN_RECORD]
                return header, summary, run[0] if run else None
    except OSError as exc:
        raise BagError(path, 'cannot read: %s' % exc.strerror)
    except _READ_ERRORS:
        pass
    contents = scan_mcap(path)
    raise BagError(path, 'truncated at byte %d of %d (the bag claims to be finalised)'
                   % (contents.end, contents.size))


def _add_topic(bag, topic_name, schema, channel, count):
    topic = bag.topics.get(topic_name)
    if topic is None:
        topic = bag.topics[topic_name] = Topic(
            topic_name, schema.name if schema else '',
            schema.data.decode('utf-8', 'replace') if schema else '',
            channel.metadata.get('topic_type_hash', ''),
            _qos_list(channel.metadata.get('offered_qos_profiles', '')))
    topic.count += count


def _open_finalised(bag, path):
    """Add a finalised MCAP file to ``bag``: topics and counts from its summary."""
    header, summary, run = _read_summary(path)
    _check_profile(path, header)
    counts = summary.statistics.channel_message_counts if summary.statistics else None
    chunks = sorted((c.chunk_start_offset, set(c.message_index_offsets) or None)
                    for c in summary.chunk_indexes) or None
    topics = {}
    for cid, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        if channel.schema_id and schema is None:
            raise BagError(path, 'channel %s has no schema' % channel.topic)
        topics[cid] = channel.topic
        _add_topic(bag, channel.topic, schema, channel, 0)
    source = _McapFile(path, topics, chunks)
    if counts is None:                       # no statistics: count them
        for name, _, _, _ in source.messages(None):
            bag.topics[name].count += 1
    else:
        for cid, n in counts.items():
            if cid not in topics:
                raise BagError(path, 'statistics count messages on unknown channel %d' % cid)
            bag.topics[topics[cid]].count += n
    if run is not None:
        bag.custom_data.update(run)
    bag._sources.append(source)


def _open_cut(bag, path):
    """
    Add an MCAP file without summary to ``bag``: its complete chunks (mcap's StreamReader).

    The last chunk counts too if the file ends in its message indexes (the chunk itself is
    whole and its CRC checked; reindex cuts it off, the indexed readers need the indexes).
    """
    contents = scan_mcap(path)
    _check_profile(path, contents.header)
    schemas, channels = dict(contents.schemas), dict(contents.channels)
    counts = dict(contents.counts)
    chunks = [(c.chunk_start_offset, set(c.message_index_offsets) or None)
              for c in contents.chunk_indexes]
    end = contents.end
    tail = contents.tail
    if tail is not None:
        for record in tail.records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
        chunks.append((tail.index.chunk_start_offset, tail.channels))
        end = tail.end
    topics = {}
    for cid, channel in sorted(channels.items()):
        topics[cid] = channel.topic
        _add_topic(bag, channel.topic, schemas.get(channel.schema_id), channel,
                   counts.get(cid, 0))
    bag.custom_data.update(contents.run_record())
    bag._sources.append(_McapFile(path, topics, chunks))
    if not contents.finalised:
        bag.finalised = False
        bag.notes.append('%s: not finalised (recorder stopped without closing the bag?); '
                         'read %d messages up to byte %d of %d'
                         % (path, sum(counts.values()), end, contents.size))


def _check_profile(path, header):
    if header.profile != 'ros2':
        raise BagError(path, "MCAP profile is %r, not 'ros2' (not a ROS 2 bag)"
                       % header.profile)


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
    Open a rosbag2 bag with MCAP storage (a directory, or one of its ``.mcap`` files).

    Only the summaries are read here; :meth:`Bag.messages` and :meth:`Bag.decode` read
    the messages chunk by chunk. A finalised bag (metadata.yaml, MCAP summary) is read
    with mcap's indexed reader and must agree with its metadata. A bag without
    metadata.yaml (its recorder was killed) is read with mcap's StreamReader up to its last
    complete chunk (a chunk with all its message indexes, what :func:`scan_mcap` keeps);
    ``finalised`` is False and ``notes`` says so.

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
    for f in files:
        _check_magic(f)
        if bag.metadata is not None:
            _open_finalised(bag, f)
        else:
            _open_cut(bag, f)
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


class McapContents:
    """
    What :func:`scan_mcap` found in an MCAP file: its complete records and where they end.

    Attributes
    ----------
    schemas, channels : dict of int to mcap record
        By id, from the complete chunks (and the summary of a finalised file).
    counts : dict of int to int
        Messages per channel id in the complete chunks.
    start_ns, end_ns : int or None
        Log times of the first and last message (None: no message).
    chunk_indexes : list of mcap.records.ChunkIndex
        One per complete chunk (a chunk with all its message indexes).
    metadata : list of tuple
        ``(name, dict, offset, length)`` of the metadata records.
    end : int
        Byte offset just past the last complete record of the data section.
    size : int
        File size (bytes).
    finalised : bool
        The file has its summary and footer.
    tail : _PendingChunk or None
        The last chunk if the file ends in its message indexes (whole, CRC checked, but
        not counted above: an indexed reader needs its indexes).

    """

    def __init__(self):
        self.header = None
        self.schemas = {}
        self.channels = {}
        self.counts = {}
        self.start_ns = None
        self.end_ns = None
        self.chunk_indexes = []
        self.metadata = []
        self.end = len(MAGIC)
        self.size = 0
        self.finalised = False
        self.tail = None

    @property
    def message_count(self):
        """Return the number of messages in the complete chunks."""
        return sum(self.counts.values())

    def run_record(self):
        """Return the run information record (``freejoint_run``) as a dict ({} if none)."""
        for name, data, _, _ in self.metadata:
            if name == RUN_RECORD:
                return dict(data)
        return {}

    def topics(self):
        """Return ``[(channel id, dict(name, type, qos, hash))]`` in channel id order."""
        out = []
        for cid in sorted(self.channels):
            channel = self.channels[cid]
            schema = self.schemas.get(channel.schema_id)
            out.append((cid, {'name': channel.topic, 'type': schema.name if schema else '',
                              'qos': _qos_list(channel.metadata.get('offered_qos_profiles',
                                                                    '')),
                              'hash': channel.metadata.get('topic_type_hash', '')}))
        return out


class _PendingChunk:
    """A chunk read whole, waiting for its message indexes (``chunk``: the Chunk record)."""

    def __init__(self, index, records, chunk=None):
        self.index = index
        self.records = records
        self.chunk = chunk
        self.channels = {r.channel_id for r in records if isinstance(r, Message)}
        self.indexed = set()
        self.end = index.chunk_start_offset + index.chunk_length

    def complete(self):
        return self.channels <= self.indexed


def _message_indexes(chunk):
    """
    Return the MessageIndex records of a Chunk record, rebuilt from its messages.

    One per channel, in the order the messages appear: ``(log_time, offset)`` with the
    offset of the message record in the chunk's uncompressed records (MCAP's message
    index, what a writer writes after each chunk).
    """
    entries = {}
    for offset, channel_id, log_time, _, _ in _chunk_messages(chunk):
        entries.setdefault(channel_id, []).append((log_time, offset))
    return [MessageIndex(channel_id=cid, records=rows) for cid, rows in entries.items()]


def index_tail(path, contents):
    """
    Give the whole last chunk of a cut MCAP file its message indexes, in place.

    A writer stopped while it wrote a chunk's message indexes leaves the chunk whole (its
    CRC checked) but not indexed (``contents.tail`` of :func:`scan_mcap`): the partial
    indexes are cut off and the ones rebuilt from the chunk's own messages are written after
    it, so the chunk is kept, as :func:`open_bag` reads the cut file. ``contents`` is updated
    as if the chunk had been complete. Return whether a chunk was indexed (False: no such
    tail, or it does not follow the last complete record: it is cut off with the rest).

    Raises
    ------
    BagError
        If the file cannot be written.

    """
    if _indexable_tail(contents) is None:
        return False
    try:
        with open(path, 'r+b') as fh:
            _index_tail(fh, contents)
    except OSError as exc:
        raise BagError(path, 'cannot index its last chunk: %s' % (exc.strerror or exc))
    return True


def _indexable_tail(contents):
    """Return ``contents.tail`` if :func:`index_tail` can keep it (it follows the rest)."""
    tail = contents.tail
    if tail is None or tail.chunk is None or tail.index.chunk_start_offset != contents.end:
        return None
    return tail


def _index_tail(fh, contents):
    """:func:`index_tail` on the open file ``fh`` (nothing without an indexable tail)."""
    tail = _indexable_tail(contents)
    if tail is None:
        return
    indexes = _message_indexes(tail.chunk)
    fh.truncate(tail.end)
    fh.seek(tail.end)
    builder = RecordBuilder()
    for index in indexes:
        start = tail.end + builder.count
        index.write(builder)
        tail.index.message_index_offsets[index.channel_id] = start
    tail.index.message_index_length = builder.count
    fh.write(builder.end())
    tail.indexed = set(tail.index.message_index_offsets)
    _accept_chunk(contents, tail)
    contents.tail = None


def _accept_chunk(contents, chunk):
    for record in chunk.records:
        if isinstance(record, Schema):
            contents.schemas[record.id] = record
        elif isinstance(record, Channel):
            contents.channels[record.id] = record
        elif isinstance(record, Message):
            contents.counts[record.channel_id] = contents.counts.get(record.channel_id, 0) + 1
            t = record.log_time
            if contents.start_ns is None or t < contents.start_ns:
                contents.start_ns = t
            if contents.end_ns is None or t > contents.end_ns:
                contents.end_ns = t
    contents.chunk_indexes.append(chunk.index)
    contents.end = chunk.end + chunk.index.message_index_length


def scan_mcap(path):
    """
    Read an MCAP file with mcap's StreamReader up to its end or to where it is cut short.

    A chunk counts only with all its message indexes (what the readers of an indexed
    file need); a chunk cut short, or whose indexes are, ends the usable part.

    Returns
    -------
    McapContents

    Raises
    ------
    BagError
        If the file cannot be read or is not an MCAP file.

    """
    contents = McapContents()
    try:
        contents.size = os.path.getsize(path)
        fh = open(path, 'rb')
    except OSError as exc:
        raise BagError(path, 'cannot read: %s' % exc.strerror)
    with fh:
        if fh.read(len(MAGIC)) != MAGIC:
            raise BagError(path, 'not an MCAP file (no MCAP magic at the start)')
        fh.seek(0)
        records = StreamReader(fh, emit_chunks=True, record_size_limit=contents.size).records
        pos = 0
        pending = None
        data_end = False
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except (McapError, struct.error, ValueError, UnicodeDecodeError):
                break                                  # cut short (or damaged) here
            start = len(MAGIC) if pos == 0 else pos
            pos = fh.tell()
            if isinstance(record, Header):
                contents.header = record
                contents.end = pos
                continue
            if contents.header is None:
                raise BagError(path, 'not an MCAP file (first record is not a header)')
            if data_end:                                # the summary section
                if isinstance(record, Schema):
                    contents.schemas.setdefault(record.id, record)
                elif isinstance(record, Channel):
                    contents.channels.setdefault(record.id, record)
                elif isinstance(record, Footer):
                    contents.finalised = True
                continue
            if isinstance(record, MessageIndex) and pending is not None:
                pending.index.message_index_offsets[record.channel_id] = start
                pending.index.message_index_length = pos - pending.end
                pending.indexed.add(record.channel_id)
                continue
            if pending is not None:
                if pending.complete():
                    _accept_chunk(contents, pending)
                pending = None
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except (McapError, struct.error, ValueError, UnicodeDecodeError):
                    break                               # a damaged chunk ends it
                pending = _PendingChunk(ChunkIndex(
                    message_start_time=record.message_start_time,
                    message_end_time=record.message_end_time, chunk_start_offset=start,
                    chunk_length=pos - start, message_index_offsets={},
                    message_index_length=0, compression=record.compression,
                    compressed_size=len(record.data),
                    uncompressed_size=record.uncompressed_size), inner, record)
            elif isinstance(record, Metadata):
                contents.metadata.append((record.name, dict(record.metadata), start,
                                          pos - start))
                contents.end = pos
            elif isinstance(record, DataEnd):
                data_end = True
            elif isinstance(record, Schema):          # outside chunks (other writers)
                contents.schemas[record.id] = record
                contents.end = pos
            elif isinstance(record, Channel):
                contents.channels[record.id] = record
                contents.end = pos
        if pending is not None:
            if pending.complete():
                _accept_chunk(contents, pending)
            else:
                contents.tail = pending
    if contents.header is None:
        raise BagError(path, 'MCAP file cut short before its header (%d bytes)' % contents.size)
    return contents


def _summary_records(contents, metadata, summary_start):
    """Return the summary section bytes (schemas ... summary offsets) and its offsets start."""
    builder = RecordBuilder()
    offsets = []

    def group(opcode, records):
        begin = builder.count
        for record in records:
            record.write(builder)
        offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + begin,
                                     group_length=builder.count - begin))

    counts = {cid: contents.counts.get(cid, 0) for cid in contents.channels}
    statistics = Statistics(
        attachment_count=0, channel_count=len(contents.channels),
        channel_message_counts=counts, chunk_count=len(contents.chunk_indexes),
        message_count=contents.message_count,
        metadata_count=len(metadata),
        message_start_time=contents.start_ns or 0, message_end_time=contents.end_ns or 0,
        schema_count=len(contents.schemas))
    group(Opcode.SCHEMA, [contents.schemas[k] for k in sorted(contents.schemas)])
    group(Opcode.CHANNEL, [contents.channels[k] for k in sorted(contents.channels)])
    group(Opcode.STATISTICS, [statistics])
    group(Opcode.CHUNK_INDEX, contents.chunk_indexes)
    group(Opcode.METADATA_INDEX, [MetadataIndex(offset=offset, length=length, name=name)
                                  for name, _, offset, length in metadata])
    offsets_start = summary_start + builder.count
    for offset in offsets:
        offset.write(builder)
    return builder.end(), offsets_start


def finalise_mcap(path, rosbag2_record=None, contents=None):
    """
    Give an MCAP file whose writer stopped early its summary and footer, in place.

    The file is cut after its last complete record (a chunk counts with all its message
    indexes; a whole last chunk whose indexes were cut short gets them rebuilt from its
    messages), then gets the metadata record ``rosbag2`` (if given), the data end, the
    summary (schemas, channels, statistics, chunk and metadata indexes, summary offsets)
    and the footer: what mcap's writer writes on finish. A finalised file is left alone.

    Parameters
    ----------
    path : str
        The MCAP file.
    rosbag2_record : dict of str to str, optional
        Content of the ``rosbag2`` metadata record (``serialized_metadata``).
    contents : McapContents, optional
        The file's :func:`scan_mcap` (scanned here if not given).

    Returns
    -------
    McapContents
        What the finalised file holds.

    Raises
    ------
    BagError
        If the file cannot be read or written.

    """
    if contents is None:
        contents = scan_mcap(path)
    if contents.finalised:
        return contents
    try:
        with open(path, 'r+b') as fh:
            _index_tail(fh, contents)
            fh.truncate(contents.end)
            fh.seek(contents.end)
            builder = RecordBuilder()
            metadata = list(contents.metadata)
            if rosbag2_record is not None:
                Metadata(name='rosbag2', metadata=dict(rosbag2_record)).write(builder)
                metadata.append(('rosbag2', dict(rosbag2_record), contents.end,
                                 builder.count))
            DataEnd(data_section_crc=0).write(builder)
            summary_start = contents.end + builder.count
            summary, offsets_start = _summary_records(contents, metadata, summary_start)
            crc = zlib.crc32(summary)
            crc = zlib.crc32(struct.pack('<BQQQ', Opcode.FOOTER, 8 + 8 + 4, summary_start,
                                         offsets_start), crc)
            footer = RecordBuilder()
            Footer(summary_start=summary_start, summary_offset_start=offsets_start,
                   summary_crc=crc).write(footer)
            fh.write(builder.end() + summary + footer.end() + MAGIC)
            fh.flush()
            os.fsync(fh.fileno())
    except OSError as exc:
        try:                                    # leave it as it was (a later try can work)
            os.truncate(path, contents.end)
        except OSError:
            pass
        raise BagError(path, 'cannot finalise: %s' % (exc.strerror or exc))
    contents.metadata = metadata
    contents.finalised = True
    return contents
