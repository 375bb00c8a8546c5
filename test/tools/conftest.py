"""Fixtures of the freejoint_tools tests: bags written in-process, the test publisher."""
import bisect
import math
import os
import re
import subprocess
import sys

from freejoint_common.contract import to_ns
from freejoint_tools.harness import load_source
import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
PUBLISHER = os.path.join(HERE, '..', 'nodes', 'tools_publisher.py')


def _load_publisher():
    return load_source(PUBLISHER, 'tools_publisher')


@pytest.fixture(scope='session')
def publisher_module():
    """Give the test publisher module (its ``tick_messages(k)``, ``latched_messages()``)."""
    return _load_publisher()


class BagMaker:
    """Write bags of a lockstep-like run in-process with BagWriter (no recorder process)."""

    def __init__(self, module):
        self.module = module

    def __call__(self, path, ticks, custom_data=None, finalise=True, chunk_size=64 * 1024,
                 flush_every=0, compression='none', t0_ns=0, extra=(), joints=None):
        """
        Write ``ticks`` ticks (joint_states, setpoints, controller_state, /clock) and the map.

        ``t0_ns`` > 0: a real-time run's bag instead: every stamp and log time shifted by
        it (system time), no /clock. ``extra``: ``(topic, type, transient local, message)``
        written first (e.g. /robot_description). ``joints``: ``(all, active)`` joint names
        of another arm (joint states padded with zero positions, one effort per active).

        Returns the dict topic -> list of the rclpy messages written, in order; the bytes
        written (their serialization: CDR padding bytes are not reproducible from one
        serialization to the next) are left in ``self.data``, topic -> list of bytes.
        """
        from rclpy.serialization import serialize_message

        from freejoint_common.contract import stamp_from_ns
        from freejoint_tools.bagfile import BagWriter, default_qos_dict
        from freejoint_tools.typedefs import Definitions
        defs = Definitions()
        writer = BagWriter(path, custom_data, chunk_size=chunk_size, compression=compression)
        grid, marker = self.module.latched_messages()
        topics = [(name, msgtype, 'transient_local' if latched else 'volatile')
                  for name, msgtype, latched, _ in extra]
        topics += [('/joint_states', 'sensor_msgs/msg/JointState', 'volatile'),
                   ('/setpoints', 'freejoint_msgs/msg/CartesianSetpoints', 'transient_local'),
                   ('/controller_state', 'freejoint_msgs/msg/ControllerState', 'volatile'),
                   ('/semi_singular_map', 'nav_msgs/msg/OccupancyGrid', 'transient_local'),
                   ('/planned_path', 'visualization_msgs/msg/Marker', 'transient_local')]
        if not t0_ns:
            topics.insert(len(extra) + 3, ('/clock', 'rosgraph_msgs/msg/Clock', 'volatile'))
        channels = {}
        for name, msgtype, durability in topics:
            text, digest = defs.lookup(msgtype)
            channels[name] = writer.add_topic(name, msgtype, text, digest,
                                              [default_qos_dict(durability=durability)])
        written = {name: [] for name, _, _ in topics}
        self.data = {name: [] for name, _, _ in topics}

        def put(name, t_ns, msg):
            data = serialize_message(msg)
            writer.write(channels[name], t_ns, data)
            written[name].append(msg)
            self.data[name].append(data)

        for name, _, _, msg in extra:
            put(name, t0_ns, msg)
        put('/semi_singular_map', t0_ns, grid)
        put('/planned_path', t0_ns, marker)
        from rosgraph_msgs.msg import Clock
        for k in range(ticks):
            js, sp, cs = self.module.tick_messages(k)
            if joints is not None:
                names, active = joints
                js.name = list(names)
                js.position = (list(js.position) + [0.0] * len(names))[:len(names)]
                js.velocity = js.effort = [0.0] * len(names)
                cs.joint_names = list(active)
                cs.effort = (list(cs.effort) * len(active))[:len(active)]
            t_ns = t0_ns + k * self.module.DT_NS
            if t0_ns:
                for msg in (js, sp, cs):
                    stamp_from_ns(t_ns, msg.header.stamp)
                sp.stamps = [t_ns]
            else:
                clock = Clock()
                clock.clock = js.header.stamp
                put('/clock', t_ns, clock)
            put('/joint_states', t_ns, js)
            put('/setpoints', t_ns, sp)
            put('/controller_state', t_ns, cs)
            if flush_every and (k + 1) % flush_every == 0:
                writer.flush()
        if finalise:
            writer.close()
        else:
            writer.abandon()
        return written


@pytest.fixture
def make_bag(publisher_module):
    """Give the bag maker (path, ticks, custom_data=None, finalise=True, ...)."""
    return BagMaker(publisher_module)


def run_analyze(*args, timeout=120.0):
    """Run ``python -m freejoint_tools.analyze args`` (what make analyze runs)."""
    return subprocess.run([sys.executable, '-m', 'freejoint_tools.analyze', *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def analyze():
    """Give a runner of the analysis command line (args -> CompletedProcess)."""
    return run_analyze


def assert_same_record(bag_record, graph_record, tol=1e-9):
    """Assert two records have the same keys and values (numbers within ``tol``)."""
    assert set(bag_record) == set(graph_record)
    for key, value in graph_record.items():
        if key == 'source':
            continue
        if isinstance(value, (float, list)):
            assert bag_record[key] == pytest.approx(value, abs=tol, rel=0), key
        else:
            assert bag_record[key] == value, key
    assert bag_record['source'] == 'bag'


@pytest.fixture
def same_record():
    """Give the record check: a bag record agrees with a graph record within 1e-9."""
    return assert_same_record


@pytest.fixture
def recorder_drained(ros_node):
    """
    Give the test a wait (quiet s, timeout s) for a steady ``/recorder/status`` count.

    Call it once the graph is silent (the simulator holds at ``max_steps``); it returns
    ``(count or None, wall s)`` (``ServiceCalls.recorder_drained``).
    """
    from freejoint_tools.harness import ServiceCalls
    calls = ServiceCalls(ros_node)
    return calls.recorder_drained


@pytest.fixture
def start_circle(ros_node):
    """
    Give the test a function of ``pause`` that starts a run the README's manual way.

    It calls ``/recorder/status`` until it says every graph topic is matched (60 s), ``pause`` wall
    seconds (the publishers' side of the match can lag the recorder's), then the paper's
    horizontal circle through ``/freejoint_planner/plan_circle``, which must be accepted.
    """
    from freejoint_tools.harness import ServiceCalls

    def start(pause):
        calls = ServiceCalls(ros_node)
        ready, message = calls.recorder_ready(60.0)
        assert ready, 'the recorder did not match every graph topic: %s' % message
        calls.spin_until(lambda: False, pause)
        answer = calls.plan_circle({'centre': [0.0, 0.0], 'radius': 0.2, 'duration': 5.0,
                                    'start_angle': 0.0, 'direction': 1})
        assert answer is not None, 'no answer from plan_circle'
        assert answer.accepted, answer.reason
    return start


class PlanCheck:
    """
    An independent check of a bag's figures against the plan.

    Written apart from ``freejoint_core.plan_figures``: per state stamp, the setpoints'
    positions interpolated with ``np.interp`` on integer-ns stamps, a state counted moving
    when the setpoint of its stamp - or either neighbour between two - has a non-zero
    velocity.
    """

    PLAN_LINE = re.compile(r'^plan: (\S+): rms ([0-9.]+) mm, max ([0-9.]+) mm over '
                           r'(\d+) ticks; (?:([0-9.]+) % of the )?(\d+) moving ticks')
    """``make analyze``'s line per bag (groups: bag, rms, max [mm], ticks, share [%], moving)."""

    @staticmethod
    def independent(path, window_ns=None, bound_mm=None):
        """
        Return (rms [m], max [m], ticks, moving ticks, share) of a bag, sample by sample.

        ``window_ns``: only the states stamped in it. ``bound_mm``: for the share (else None).
        """
        from freejoint_tools.bagfile import open_bag
        bag = open_bag(path)
        ee = {}
        for _, msg in bag.decode('/ee_position'):
            ee.setdefault(to_ns(msg.header.stamp), (msg.point.x, msg.point.y, msg.point.z))
        setpoints = {}
        for _, msg in bag.decode('/setpoints'):
            m = len(msg.position) // len(msg.stamps)     # 2 (planar) or 3 (a spatial tip)
            for i, ns in enumerate(msg.stamps):
                setpoints[int(ns)] = (list(msg.position[i * m:i * m + m]),
                                      list(msg.velocity[i * m:i * m + m]))
        sp_ns = sorted(setpoints)
        first = sp_ns[0]
        x = np.array([float(ns - first) for ns in sp_ns])
        axes = [np.array([setpoints[ns][0][j] for ns in sp_ns]) for j in range(m)]
        errors, moving = [], []
        for ns in sorted(ee):
            if window_ns is not None and not window_ns[0] <= ns <= window_ns[1]:
                continue
            if not sp_ns[0] <= ns <= sp_ns[-1]:
                continue
            at = float(ns - first)
            plan = [float(np.interp(at, x, a)) for a in axes]
            error = math.hypot(*(ee[ns][j] - plan[j] for j in range(m)))
            errors.append(error)
            i = bisect.bisect_left(sp_ns, ns)
            around = [sp_ns[i]] if sp_ns[i] == ns else [sp_ns[i - 1], sp_ns[i]]
            moves = any(any(v != 0.0 for v in setpoints[k][1]) for k in around)
            if moves:
                moving.append(error)
        rms = math.sqrt(sum(e * e for e in errors) / len(errors))
        share = None
        if bound_mm is not None and moving:
            share = sum(1 for e in moving if e * 1e3 <= bound_mm) / len(moving)
        return rms, max(errors), len(errors), len(moving), share

    @staticmethod
    def analyze_line(done, name):
        """Return the groups of ``make analyze``'s plan line of bag ``name``."""
        for line in done.stdout.splitlines():
            found = PlanCheck.PLAN_LINE.match(line)
            if found and found.group(1) == name:
                return found
        raise AssertionError('no plan line for %s in:\n%s' % (name, done.stdout))

    @staticmethod
    def assert_printed_equals(found, check, tol_m=1e-6):
        rms, worst, ticks, moving, share = check
        assert abs(float(found.group(2)) * 1e-3 - rms) <= tol_m
        assert abs(float(found.group(3)) * 1e-3 - worst) <= tol_m
        assert (int(found.group(4)), int(found.group(6))) == (ticks, moving)
        if share is not None:
            assert abs(float(found.group(5)) - 100.0 * share) <= 0.05 + 1e-9


@pytest.fixture
def plan_check():
    """Give the independent check of the figures against the plan (:class:`PlanCheck`)."""
    return PlanCheck
