"""
The graph split over two hosts: two network namespaces joined by a veth pair.

The simulator and the controller run in one namespace, the planner and the recorder in the
other, each namespace with its own address on a private /30 of the veth pair and nothing
else but loopback: the nodes find each other with the default discovery (multicast over
the veth, ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``, not localhost-only) on a domain of
their own, over UDP only (Fast DDS's shared-memory transport, which would bypass the
network between processes of one machine, is switched off with
``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``).  The lockstep run, recorded in the planner's
namespace, equals the offline runner at every tick.

Creating namespaces needs ``ip`` (iproute2) and CAP_NET_ADMIN with CAP_SYS_ADMIN (root);
without them the test is skipped, naming what is missing.  The namespaces (and with them
the veth pair and its addresses) are removed at the end, whatever happened.
"""
import os
import shutil
import subprocess
import sys

from freejoint_common.contract import NEVER_QUIET_TOPICS
from freejoint_common.records import arrays_from_messages, stamp_ns
from freejoint_core.offline import run_case
from freejoint_tools.harness import load_source
import numpy as np
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
DRIVER = os.path.join(ROOT, 'test', 'graph', 'netns_driver.py')
TICKS = 1000
DT_NS = 1_000_000
CAP_NET_ADMIN = 12
CAP_SYS_ADMIN = 21


def _missing(status='/proc/self/status'):
    """Return why network namespaces cannot be made here, or None."""
    if shutil.which('ip') is None:
        return 'no `ip` command (iproute2; Debian/Ubuntu: apt-get install iproute2)'
    try:
        with open(status) as f:
            caps = int(next(line for line in f if line.startswith('CapEff:')).split()[1], 16)
    except (OSError, StopIteration, ValueError):
        caps = -1 if os.geteuid() == 0 else 0
    lacking = [name for bit, name in ((CAP_NET_ADMIN, 'CAP_NET_ADMIN'),
                                      (CAP_SYS_ADMIN, 'CAP_SYS_ADMIN'))
               if not caps & (1 << bit)]
    if lacking:
        return ('creating network namespaces needs root with CAP_NET_ADMIN and '
                'CAP_SYS_ADMIN (this process: uid %d, without %s)'
                % (os.geteuid(), ' and '.join(lacking)))
    return None


def _ip(*args):
    done = subprocess.run(['ip', *args], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, 'ip %s: %s' % (' '.join(args), done.stderr.strip())


class Hosts:
    """Two namespaces ``a`` and ``b`` joined by a veth pair, each a host of the graph."""

    def __init__(self, procs):
        tag = os.getpid() % 100000
        self.procs = procs
        self.names = {'a': 'fjnsa%d' % tag, 'b': 'fjnsb%d' % tag}
        # A private /30 per run (10.77.x.y), only on the veth pair inside the namespaces.
        base = 4 * (tag % 16384)
        net = '10.77.%d.%d' % (base // 256, base % 256)
        self.addresses = {'a': '10.77.%d.%d/30' % (base // 256, base % 256 + 1),
                          'b': '10.77.%d.%d/30' % (base // 256, base % 256 + 2)}
        self.net = net
        self.env = {'ROS_DOMAIN_ID': str(101 + os.getpid() % 100),
                    'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
                    'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}
        self.made = []

    def create(self):
        for side in ('a', 'b'):
            _ip('netns', 'add', self.names[side])
            self.made.append(self.names[side])
        veth = {side: 'fjv%s%d' % (side, os.getpid() % 100000) for side in ('a', 'b')}
        _ip('link', 'add', veth['a'], 'netns', self.names['a'], 'type', 'veth',
            'peer', 'name', veth['b'], 'netns', self.names['b'])
        for side in ('a', 'b'):
            ns = self.names[side]
            _ip('-n', ns, 'link', 'set', 'lo', 'up')
            _ip('-n', ns, 'addr', 'add', self.addresses[side], 'dev', veth[side])
            _ip('-n', ns, 'link', 'set', veth[side], 'up')
            _ip('-n', ns, 'route', 'add', '224.0.0.0/4', 'dev', veth[side])   # discovery

    def remove(self):
        for ns in self.made:
            subprocess.run(['ip', 'netns', 'del', ns], capture_output=True, timeout=30)
        self.made = []

    def start(self, side, cmd, name):
        proc = self.procs.start(name, ['ip', 'netns', 'exec', self.names[side], *cmd],
                                env=self.env)
        return proc

    def node(self, side, pkg, exe, name, *args):
        path = os.path.join(ROOT, 'install', pkg, 'lib', pkg, exe)   # what `ros2 run` runs
        return self.start(side, [path, '--ros-args', *args], name)


@pytest.fixture
def hosts(procs):
    """Give the test two fresh namespaces; stop their processes and remove them after."""
    reason = _missing()
    if reason is not None:
        pytest.skip('network-namespace test cannot run: ' + reason)
    made = Hosts(procs)
    try:
        made.create()
        yield made
    finally:
        procs.stop_all()
        made.remove()
        left = subprocess.run(['ip', 'netns', 'list'], capture_output=True, text=True)
        assert not any(ns in left.stdout for ns in made.names.values()), left.stdout


def test_without_ip_or_the_privilege_the_netns_test_is_skipped_saying_why(
        monkeypatch, tmp_path):
    status = tmp_path / 'status'
    status.write_text('Name:\tpython\nCapEff:\t0000000000001000\n')     # CAP_NET_ADMIN only
    monkeypatch.setattr(shutil, 'which', lambda name: '/usr/sbin/ip')
    assert _missing(str(status)) == (
        'creating network namespaces needs root with CAP_NET_ADMIN and CAP_SYS_ADMIN (this '
        'process: uid %d, without CAP_SYS_ADMIN)' % os.geteuid())
    status.write_text('CapEff:\t0000000000201000\n')
    assert _missing(str(status)) is None
    monkeypatch.setattr(shutil, 'which', lambda name: None)
    assert _missing(str(status)) == ('no `ip` command (iproute2; Debian/Ubuntu: apt-get '
                                     'install iproute2)')


def test_lockstep_graph_over_two_network_namespaces_equals_the_offline_runner(
        hosts, procs, wait, tmp_path):
    from freejoint_tools.bagfile import open_bag
    demo = load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'freejoint_demo')

    bag_path = str(tmp_path / 'netns')
    recorder = hosts.node('b', 'freejoint_tools', 'recorder', 'recorder',
                          '-p', 'output:=%s' % bag_path, '-p', 'topics:=[]',
                          '-p', 'exclude:=[%s]' % ', '.join(NEVER_QUIET_TOPICS),
                          '-p', 'use_sim_time:=true', '-p',
                          'custom_data:=[case=horizontal, variant=robust, seed=0, '
                          'max_ticks=%d]' % TICKS)
    wait(lambda: 'recording into' in procs.log(recorder) or recorder.poll() is not None, 60.0,
         'the recorder (log %s)' % recorder.log_path)
    assert recorder.poll() is None, procs.log(recorder)
    params = ('--params-file',)
    nodes = [
        hosts.node('a', 'freejoint_sim', 'sim_node', 'sim', *params,
                   os.path.join(CONFIG, 'sim.yaml'), '-p', 'max_steps:=%d' % TICKS),
        hosts.node('a', 'freejoint_control', 'controller_node', 'controller', *params,
                   os.path.join(CONFIG, 'controller.yaml')),
        hosts.node('b', 'freejoint_planner', 'planner_node', 'planner', *params,
                   os.path.join(CONFIG, 'planner.yaml'), '-p', 'autostart:=false'),
    ]
    driver = hosts.start('b', [sys.executable, DRIVER, os.path.join(CONFIG, 'planner.yaml'),
                               str(TICKS)], 'driver')

    def logs():
        return {os.path.basename(p.log_path): procs.log(p)[-400:]
                for p in (*nodes, recorder, driver)}

    wait(lambda: driver.poll() is not None, 300.0, 'the run to end (%s)' % (logs(),))
    assert driver.returncode == 0, logs()
    assert 'driver: drained' in procs.log(driver)
    for proc in reversed(nodes):
        assert procs.stop(proc) == 0, logs()
    assert procs.stop(recorder) == 0, logs()
    sim_log = procs.log(nodes[0])
    assert 'simulator stopped at step %d' % TICKS in sim_log
    assert '0 command timeouts, 0 refused commands, 0 divergences' in sim_log

    bag = open_bag(bag_path)
    assert bag.finalised
    states = [m for _, m in bag.decode('/controller_state')]
    joints = [m for _, m in bag.decode('/joint_states')]
    ee = [m for _, m in bag.decode('/ee_position')]
    assert min(stamp_ns(m) for m in states) == 0
    arrays = arrays_from_messages(states, joints, 'joint3', max_ticks=TICKS)
    _, trace = run_case('horizontal', 'robust', 0, record_trace=True,
                        **demo.offline_settings(CONFIG))
    k = np.rint(arrays['t'] * 1e9 / DT_NS).astype(int)
    assert k.tolist() == list(range(TICKS))
    for key in ('p', 'p_d', 'tau', 'theta', 'det'):
        assert np.max(np.abs(arrays[key] - trace[key][k])) <= 1e-9, key
    assert np.max(np.abs(arrays['q_passive'] - trace['q'][k, 2])) <= 1e-9
    assert np.max(np.abs(demo.ee_trajectory(ee, DT_NS, TICKS) - trace['p'][:TICKS])) <= 1e-9
