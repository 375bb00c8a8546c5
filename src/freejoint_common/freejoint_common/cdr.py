"""
The per-tick messages of the controller and the simulator as serialized CDR, without rclpy.

rclpy converts every message it takes into Python objects (a ``JointState`` with its name
list, a ``Header``, arrays) and every message it publishes back into C structures field by
field, a ``Float64MultiArray``'s layout and labelled dimension included: per tick that is
more CPU than the control law (docs/performance.md, "The nodes against a bare rclpy
echo"). The controller takes ``joint_states`` serialized (``raw=True``) and publishes its
command and ``ControllerState`` serialized (``Publisher.publish(bytes)``), the simulator the
other way round (``joint_states`` and ``ee_position`` out, commands in): this module reads
and writes those bytes with one ``struct`` call per field group, no message object.

The encoding is the one rmw_fastrtps and rmw_cyclonedds use for ROS 2 messages: an
encapsulation header ``00 01 00 00`` (CDR, little-endian, XCDR1), then the fields in
declaration order, each primitive aligned to its size counted from the end of that
header, a sequence or string as a ``uint32`` count then its elements (a string's count
includes its terminating NUL; an empty sequence adds no alignment). A message in another
encapsulation (big-endian, XCDR2) is not read here: the readers raise :class:`CdrError` and
the caller falls back to rclpy's ``deserialize_message`` (``contract.read_serialized``). The
tests compare every function with rclpy's own ``serialize_message`` /
``deserialize_message`` (test/interfaces/test_cdr.py).
"""

import struct

ENCAPSULATION = b'\x00\x01\x00\x00'
"""CDR, little-endian, XCDR1 (the encapsulation rmw_fastrtps writes for ROS 2 messages)."""
MAX_SEQUENCE = 4096
"""Longest array, name list or layout a message read here may carry; a longer one is refused."""

_U32 = struct.Struct('<I')
_HEADER = struct.Struct('<iII')     # stamp.sec, stamp.nanosec, frame_id's length


class CdrError(ValueError):
    """A serialized message this module cannot read (short, malformed, other encoding)."""


class _Format:
    """A struct format built field by field, CDR alignment inserted as pad bytes."""

    def __init__(self):
        self.parts = ['<4s']        # the encapsulation header, then offset 0
        self.offset = 0

    def primitive(self, code, size, count=1):
        pad = -self.offset % size
        if pad:
            self.parts.append('%dx' % pad)
        self.parts.append('%d%s' % (count, code))
        self.offset += pad + size * count

    def sequence(self, count):
        """Add a float64[] of ``count`` values: its count (an argument), then the values."""
        self.primitive('I', 4)
        if count:
            self.primitive('d', 8, count)

    def string(self, length):
        """Add a string of ``length`` bytes (UTF-8, no NUL): count, then bytes and NUL."""
        self.primitive('I', 4)
        self.parts.append('%ds' % (length + 1))     # struct pads the bytes with the NUL
        self.offset += length + 1

    def blob(self, data):
        """Add bytes serialized at a 4-aligned offset (a string sequence): one argument."""
        pad = -self.offset % 4
        if pad:
            self.parts.append('%dx' % pad)
        self.parts.append('%ds' % len(data))
        self.offset += pad + len(data)

    def build(self):
        pad = -self.offset % 4          # the payload a whole number of 4-byte words
        return struct.Struct(''.join(self.parts) + ('%dx' % pad if pad else ''))


def string_sequence(strings):
    """
    Return a ``string[]`` serialized from a 4-aligned offset (its count and strings).

    Parameters
    ----------
    strings : sequence of str
        The strings, in order.

    Returns
    -------
    bytes
        The same at any 4-aligned offset: a string needs only 4-byte alignment.

    """
    out = bytearray(_U32.pack(len(strings)))
    for i, text in enumerate(strings):
        data = text.encode('utf-8')
        out += _U32.pack(len(data) + 1) + data + b'\x00'
        if i + 1 < len(strings):
            out += bytes(-len(out) % 4)
    return bytes(out)


def _plain(values):
    """Return ``values`` as a list or tuple (a numpy array's ``tolist()``)."""
    return values if type(values) in (list, tuple) else values.tolist()


def _encoded(text):
    return text if isinstance(text, bytes) else text.encode('utf-8')


class CommandWriter:
    """
    Serialize the controller's command, a ``std_msgs/Float64MultiArray``.

    One dimension labelled with the stamp answered (``contract.stamp_label``) and sized by
    the joints commanded (size and stride ``n``), ``data_offset`` 0, the ``n`` efforts.

    Parameters
    ----------
    n : int
        Number of joints commanded.

    """

    def __init__(self, n):
        self.n = int(n)
        self._formats = {}

    def __call__(self, label, effort):
        """
        Return the serialized command.

        Parameters
        ----------
        label : str or bytes
            The dimension's label.
        effort : sequence of float, shape (n,)
            Efforts [N m] in the order of the joints commanded.

        Returns
        -------
        bytes

        """
        label = _encoded(label)
        key = len(label)
        fmt = self._formats.get(key)
        if fmt is None:
            f = _Format()
            f.primitive('I', 4)             # layout.dim: one dimension
            f.string(key)
            f.primitive('I', 4, 3)          # size, stride, layout.data_offset
            f.sequence(self.n)
            fmt = self._formats[key] = f.build()
        n = self.n
        return fmt.pack(ENCAPSULATION, 1, key + 1, label, n, n, 0, n, *effort)


class ControllerStateWriter:
    """
    Serialize a ``freejoint_msgs/ControllerState`` from a control loop ``Result``.

    The joint and law-state names, fixed per writer, are serialized once; a format per set
    of array lengths and message length is compiled once and reused.

    Parameters
    ----------
    joint_names, law_state_names : sequence of str

    """

    def __init__(self, joint_names, law_state_names):
        self._joints = string_sequence(joint_names)
        self._law_names = string_sequence(law_state_names)
        self._formats = {}

    def __call__(self, stamp, setpoint_stamp, res, message):
        """
        Return the serialized ``ControllerState`` of ``res``.

        Parameters
        ----------
        stamp, setpoint_stamp : tuple of int
            ``header.stamp`` and ``setpoint_stamp`` as ``(sec, nanosec)``.
        res : freejoint_control.loop.Result
            Its ``error``, ``error_rate``, ``sliding``, ``law_state_values``, ``effort``,
            ``position``, ``position_desired``, ``position_planned`` (sequences of float: lists,
            tuples or numpy arrays; ``position_planned`` may be empty), ``det_dd``,
            ``status``, ``setpoint_age``, ``dt``, ``state_age``.
        message : bytes
            ``res.message`` UTF-8 encoded.

        Returns
        -------
        bytes

        """
        # numpy arrays as lists first: unpacking an array makes a numpy scalar per value
        e, ed, s = _plain(res.error), _plain(res.error_rate), _plain(res.sliding)
        law, eff = _plain(res.law_state_values), _plain(res.effort)
        p, pd = _plain(res.position), _plain(res.position_desired)
        pp = _plain(res.position_planned)
        key = (len(e), len(ed), len(s), len(law), len(eff), len(p), len(pd), len(pp),
               len(message))
        fmt = self._formats.get(key)
        if fmt is None:
            fmt = self._formats[key] = self._compile(key)
        sec, nanosec = stamp
        sp_sec, sp_nsec = setpoint_stamp
        return fmt.pack(ENCAPSULATION, sec, nanosec, 1, b'',
                        key[0], *e, key[1], *ed, key[2], *s, self._law_names,
                        key[3], *law, key[4], *eff, self._joints, res.det_dd,
                        key[5], *p, key[6], *pd, key[7], *pp, res.status, key[8] + 1, message,
                        res.state_age, sp_sec, sp_nsec, res.setpoint_age, res.dt)

    def _compile(self, key):
        n_e, n_ed, n_s, n_law, n_eff, n_p, n_pd, n_pp, n_msg = key
        f = _Format()
        f.primitive('i', 4)                 # header.stamp.sec
        f.primitive('I', 4)                 # header.stamp.nanosec
        f.string(0)                         # header.frame_id: ''
        for count in (n_e, n_ed, n_s):      # error, error_rate, sliding
            f.sequence(count)
        f.blob(self._law_names)
        f.sequence(n_law)                   # law_state
        f.sequence(n_eff)                   # effort
        f.blob(self._joints)
        f.primitive('d', 8)                 # det_dd
        f.sequence(n_p)                     # position
        f.sequence(n_pd)                    # position_desired
        f.sequence(n_pp)                    # position_planned
        f.primitive('H', 2)                 # status
        f.string(n_msg)                     # message
        f.primitive('d', 8)                 # state_age
        f.primitive('i', 4)                 # setpoint_stamp.sec
        f.primitive('I', 4)                 # setpoint_stamp.nanosec
        f.primitive('d', 8, 2)              # setpoint_age, dt
        return f.build()


class _Reader:
    """
    What the readers share: the encapsulation check, strings, float64 arrays, errors.

    A ``struct`` error (a short message) becomes a :class:`CdrError` naming ``topic``.
    """

    topic = ''

    def __init__(self):
        self._doubles = {}          # struct of n float64 per n

    def _read(self, buf, fields):
        """Return ``fields(buf)`` of a CDR little-endian message; raise CdrError if not one."""
        if not buf.startswith(ENCAPSULATION):
            raise CdrError('%s: encapsulation %r, not CDR little-endian (XCDR1)'
                           % (self.topic, bytes(buf[:4])))
        try:
            return fields(buf)
        except struct.error as exc:
            raise CdrError('%s: message short or malformed (%s)' % (self.topic, exc)) \
                from None

    def _count_at(self, buf, at, what):
        """Return the ``uint32`` count at ``at``; above MAX_SEQUENCE raise, ``what % count``."""
        (count,) = _U32.unpack_from(buf, at)
        if count > MAX_SEQUENCE:
            raise CdrError('%s: %s (at most %d)' % (self.topic, what % count, MAX_SEQUENCE))
        return count

    def _string_at(self, buf, at, noun, decode=True):
        """
        Return ``(text, end)`` of the string at ``at`` (``end``: past its NUL, unaligned).

        ``decode`` False: only checked as a string, ``text`` None (not decoded).
        """
        (length,) = _U32.unpack_from(buf, at)
        end = at + 4 + length
        if length < 1 or end > len(buf) or buf[end - 1] != 0:
            raise CdrError('%s: a %s is malformed' % (self.topic, noun))
        if not decode:
            return None, end
        try:
            return buf[at + 4:end - 1].decode('utf-8'), end
        except UnicodeDecodeError:
            raise CdrError('%s: a %s is not UTF-8' % (self.topic, noun)) from None

    def _doubles_at(self, buf, at):
        """Return ``(values, end)`` of the float64[] at ``at`` (a tuple of float)."""
        count = self._count_at(buf, at, 'an array of %d values')
        at += 4
        if not count:
            return (), at
        at += -(at - 4) % 8
        fmt = self._doubles.get(count)
        if fmt is None:
            fmt = self._doubles[count] = struct.Struct('<%dd' % count)
        return fmt.unpack_from(buf, at), at + 8 * count


class JointStateReader(_Reader):
    """
    Read a serialized ``sensor_msgs/JointState``: stamp, names, positions, velocities, efforts.

    The name list of the last message is kept: a message naming the same joints (the
    stream's every message) returns that same list object, compared in place, not decoded.
    """

    topic = 'joint_states'

    def __init__(self):
        super().__init__()
        self._names = []            # the last name list
        self._encoded = ()          # its strings serialized (count + bytes + NUL), each

    def __call__(self, buf):
        """
        Return ``(sec, nanosec, names, position, velocity, effort)`` of the message ``buf``.

        Parameters
        ----------
        buf : bytes
            The serialized message (encapsulation header first).

        Returns
        -------
        tuple
            ``sec``, ``nanosec`` (int: ``header.stamp``), ``names`` (list of str),
            ``position``, ``velocity``, ``effort`` (tuples of float, each as long as the
            message's array).

        Raises
        ------
        CdrError
            ``buf`` is not a CDR little-endian message, or is short or malformed.

        """
        return self._read(buf, self._fields)

    def _fields(self, buf):
        sec, nanosec, length = _HEADER.unpack_from(buf, 4)
        at = 16 + length                # past frame_id (offsets here count the header)
        at += -at % 4
        names, at = self._names_at(buf, at)
        position, at = self._doubles_at(buf, at)
        velocity, at = self._doubles_at(buf, at)
        effort, at = self._doubles_at(buf, at)
        return sec, nanosec, names, position, velocity, effort

    def _names_at(self, buf, at):
        count = self._count_at(buf, at, '%d names')
        known = self._encoded
        pos = at + 4
        if count == len(known):
            for item in known:
                if not buf.startswith(item, pos):
                    break
                pos += len(item)
                pos += -pos % 4
            else:
                return self._names, pos
            pos = at + 4
        names, encoded = [], []
        for _ in range(count):
            name, end = self._string_at(buf, pos, 'name string')
            names.append(name)
            encoded.append(bytes(buf[pos:end]))
            pos = end + (-end % 4)
        self._names, self._encoded = names, tuple(encoded)
        return names, pos


class JointStateWriter:
    """
    Serialize a ``sensor_msgs/JointState`` of fixed joint names and frame.

    Parameters
    ----------
    names : sequence of str
        ``name``.
    frame_id : str, optional
        ``header.frame_id``.

    """

    def __init__(self, names, frame_id=''):
        self._names = string_sequence(names)
        self._frame = frame_id.encode('utf-8')
        self._formats = {}

    def __call__(self, sec, nanosec, position, velocity, effort):
        """
        Return the serialized JointState.

        Parameters
        ----------
        sec, nanosec : int
            ``header.stamp``.
        position, velocity, effort : sequence of float
            The arrays (lists or tuples), each of any length.

        Returns
        -------
        bytes

        """
        key = (len(position), len(velocity), len(effort))
        fmt = self._formats.get(key)
        if fmt is None:
            f = _Format()
            f.primitive('i', 4)
            f.primitive('I', 4)
            f.string(len(self._frame))
            f.blob(self._names)
            for count in key:
                f.sequence(count)
            fmt = self._formats[key] = f.build()
        return fmt.pack(ENCAPSULATION, sec, nanosec, len(self._frame) + 1, self._frame,
                        self._names, key[0], *position, key[1], *velocity, key[2], *effort)


class PointStampedWriter:
    """
    Serialize a ``geometry_msgs/PointStamped`` in a fixed frame.

    Parameters
    ----------
    frame_id : str
        ``header.frame_id``.

    """

    def __init__(self, frame_id):
        self._frame = frame_id.encode('utf-8')
        f = _Format()
        f.primitive('i', 4)
        f.primitive('I', 4)
        f.string(len(self._frame))
        f.primitive('d', 8, 3)
        self._format = f.build()

    def __call__(self, sec, nanosec, x, y, z):
        """Return the serialized PointStamped at ``(x, y, z)`` [m] stamped sec, nanosec."""
        return self._format.pack(ENCAPSULATION, sec, nanosec, len(self._frame) + 1,
                                 self._frame, x, y, z)


class CommandReader(_Reader):
    """Read a serialized ``std_msgs/Float64MultiArray``: its first label and its data."""

    topic = 'command'

    def __call__(self, buf):
        """
        Return ``(label, data)`` of the message ``buf``.

        Parameters
        ----------
        buf : bytes
            The serialized message (encapsulation header first).

        Returns
        -------
        tuple
            ``label``: the first dimension's label (str), None without a dimension;
            ``data``: the values (tuple of float).

        Raises
        ------
        CdrError
            ``buf`` is not a CDR little-endian message, or is short or malformed.

        """
        return self._read(buf, self._fields)

    def _fields(self, buf):
        dims = self._count_at(buf, 4, '%d layout dimensions')
        label = None
        at = 8
        for i in range(dims):
            text, end = self._string_at(buf, at, 'dimension label', decode=i == 0)
            if i == 0:
                label = text
            at = end + (-end % 4) + 8               # then size, stride
        return label, self._doubles_at(buf, at + 4)[0]     # past layout.data_offset
