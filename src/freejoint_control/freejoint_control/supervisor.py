"""
controller_supervisor: the controller under a supervisor with respawn, plus a hot spare.

``controller_supervisor [--name N] [--pid-file F] [--stop-timeout S]
[--respawn-delay D] [--] <arguments of controller_node>`` starts two ``controller_node``
processes with the same arguments: the active one, node name ``N`` (default
``controller_node``), and a hot spare with ``-p standby:=true``, node name ``N_spare``.
The names alternate: a spare started after a takeover gets the name that is free, so the
graph always has ``/N`` and ``/N_spare``, and the active one is whichever the last
takeover line and the pid file name. A spare is built, its subscriptions and publishers
discovered, and idle (docs/GRAPH.md, parameter ``standby``).

When a child dies, its death is seen at once (a pidfd per child, no polling, no command
silence): if it was the active one the spare is activated with SIGUSR1 (no DDS involved)
and ``controller <pid> died (signal 9): standby <pid> active (/<name>)`` is logged; a new
spare is started ``--respawn-delay`` (2) s later (the new active controller's recovery
first). A stopped or stalled controller is not dead: it stays active (two controllers
never command at once through the supervisor). A spare not ready yet (``notify_ready``
not received: a ``controller_node`` sends it once its commands and setpoints are matched as
the graph lists them and the setpoint stream has caught up, its SIGUSR1 handler installed)
is activated as soon as it is. A child exiting with status 2 (a bad parameter) stops
everything with status 2: respawning cannot fix a configuration; more than 10 starts within
10 s stop it with status 1.
SIGINT / SIGTERM are forwarded to the children; the supervisor exits when they have
exited (SIGKILL after ``--stop-timeout``, default 5 s) with the active child's status.

The pid file (``--pid-file``), rewritten atomically at every change, is JSON:
``{"supervisor": pid, "active": {"pid", "name"}, "standby": {"pid", "name", "ready"}}``.
Plain Python (no rclpy: the supervisor is not a ROS participant). Run it at the
controller's SCHED_FIFO priority (``chrt -f 50``) so that it reacts at once.

The children talk UDPv4 only (``--transport udp``, the default): a process killed while it
holds Fast DDS shared-memory ports leaves them locked, and a publisher that pushes to them
waits on the dead process's mutex (the real-time simulator stalled 2-6 s after a kill -9
of a shared-memory controller, 57 ms at most without, 335 ms once: performance.md). The supervisor
writes the children's Fast DDS profile at start-up: the environment's profile
(``FASTRTPS_DEFAULT_PROFILES_FILE`` / ``FASTDDS_DEFAULT_PROFILES_FILE``, e.g.
config/fastdds.xml) with its SHM transports removed, or a UDPv4 profile if there is none.
rmw_fastrtps adds a shared-memory transport of its own under
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, so there the children get ``SUBNET`` with the
static peer 127.0.0.1 and their UDPv4 transport bound to 127.0.0.1: the same reach as
LOCALHOST. ``--transport inherit`` leaves the environment as it is.
"""

import argparse
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from xml.etree import ElementTree

READY_FD_ENV = 'FREEJOINT_READY_FD'
"""Environment variable naming the file descriptor a child writes ``ready`` to."""
EXIT_BAD_PARAMETER = 2
MAX_SPAWNS = 10
"""At most this many child starts within :data:`SPAWN_WINDOW` s (a crash loop stops)."""
SPAWN_WINDOW = 10.0


def notify_ready():
    """
    Tell a supervisor the node is ready (its signal handler installed), once.

    Writes ``ready`` to the descriptor named by ``FREEJOINT_READY_FD`` and closes it (as
    systemd's ``sd_notify(READY=1)``); nothing without a supervisor.
    """
    fd = os.environ.pop(READY_FD_ENV, None)
    if fd is None:
        return
    try:
        os.write(int(fd), b'ready\n')
        os.close(int(fd))
    except (OSError, ValueError):
        pass


PROFILE_ENV = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
"""Where Fast DDS 2.x (Jazzy) and 3.x read their XML profiles file from."""
FAST_DDS_RMWS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')
"""``RMW_IMPLEMENTATION`` values that mean Fast DDS ('' = Jazzy's default)."""
PROFILES_NS = 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'
UDP_ONLY = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="%s">
  <participant profile_name="freejoint_udp" is_default_profile="true">
    <rtps/>
  </participant>
</profiles>
""" % PROFILES_NS


def _local(tag):
    return tag.rsplit('}', 1)[-1]


def _children(elem, name):
    return [c for c in elem if _local(c.tag) == name]


def _text(elem, name):
    found = _children(elem, name)
    return (found[0].text or '').strip() if found else ''


def _child(elem, name, index=None):
    """Return ``elem``'s first child ``name``, created (at ``index``) if it has none."""
    found = _children(elem, name)
    if found:
        return found[0]
    ns = elem.tag[:elem.tag.index('}') + 1] if elem.tag.startswith('{') else ''
    new = ElementTree.Element(ns + name)
    elem.insert(len(elem) if index is None else index, new)
    return new


def udp_profile(text, loopback):
    """
    Return a Fast DDS profiles XML text: ``text``'s with its transports UDPv4 only.

    Parameters
    ----------
    text : str or None
        The XML of a Fast DDS profiles file (None: a profile of its own).
    loopback : bool
        Bind the UDPv4 transports to 127.0.0.1 (``interfaceWhiteList``).

    Returns
    -------
    str
        The XML: SHM transport descriptors and their ``userTransports`` entries removed;
        every participant profile with ``useBuiltinTransports`` false and at least one
        UDPv4 transport of the file (one named ``freejoint_supervised_udp`` added if it
        had none); everything else (discovery, QoS) as in ``text``.

    Raises
    ------
    ValueError
        ``text`` is not XML or has no ``profiles`` element.

    """
    try:
        root = ElementTree.fromstring(text if text is not None else UDP_ONLY)
    except ElementTree.ParseError as exc:
        raise ValueError('not a Fast DDS profiles file: %s' % exc) from None
    profiles = root if _local(root.tag) == 'profiles' else next(
        (e for e in root.iter() if _local(e.tag) == 'profiles'), None)
    if profiles is None:
        raise ValueError('not a Fast DDS profiles file: no <profiles> element')
    ns = profiles.tag[:profiles.tag.index('}') + 1] if profiles.tag.startswith('{') else ''
    # Before the participants: Fast DDS resolves their transport ids as it parses them.
    descriptors = _child(profiles, 'transport_descriptors', 0)
    shm, udp = set(), []
    for desc in list(_children(descriptors, 'transport_descriptor')):
        kind, ident = _text(desc, 'type'), _text(desc, 'transport_id')
        if kind == 'SHM':
            shm.add(ident)
            descriptors.remove(desc)
        elif kind == 'UDPv4':
            udp.append((ident, desc))
    if not udp:
        desc = ElementTree.SubElement(descriptors, ns + 'transport_descriptor')
        ElementTree.SubElement(desc, ns + 'transport_id').text = 'freejoint_supervised_udp'
        ElementTree.SubElement(desc, ns + 'type').text = 'UDPv4'
        udp.append(('freejoint_supervised_udp', desc))
    if loopback:
        for _ident, desc in udp:
            for old in _children(desc, 'interfaceWhiteList'):
                desc.remove(old)
            allowed = ElementTree.SubElement(desc, ns + 'interfaceWhiteList')
            ElementTree.SubElement(allowed, ns + 'address').text = '127.0.0.1'
    for participant in _children(profiles, 'participant'):
        rtps = _child(participant, 'rtps')
        _child(rtps, 'useBuiltinTransports').text = 'false'
        users = _child(rtps, 'userTransports')
        for ref in list(_children(users, 'transport_id')):
            if (ref.text or '').strip() in shm:
                users.remove(ref)
        if not any((r.text or '').strip() in {i for i, _ in udp}
                   for r in _children(users, 'transport_id')):
            ElementTree.SubElement(users, ns + 'transport_id').text = udp[0][0]
    if ns:
        ElementTree.register_namespace('', ns[1:-1])    # Fast DDS reads unprefixed tags
    return ElementTree.tostring(root, encoding='unicode')


def read_pid_file(path):
    """
    Return ``{'active': pid, 'spare': pid, 'ready': bool}`` of a supervisor's pid file.

    ``{}`` while there is no file (or an unreadable one) or either child is missing.
    """
    try:
        with open(path) as f:
            doc = json.load(f)
    except (OSError, ValueError):
        return {}
    if not doc.get('active') or not doc.get('standby'):
        return {}
    return {'active': doc['active']['pid'], 'spare': doc['standby']['pid'],
            'ready': doc['standby']['ready']}


def profiles_file(environ):
    """Return the Fast DDS XML profiles file ``environ`` names (None: Fast DDS defaults)."""
    return next((environ[k] for k in PROFILE_ENV if environ.get(k)), None)


def udp_environment(environ, directory):
    """
    Return the environment updates that give a child process UDPv4 transports only.

    Writes the children's profile (:func:`udp_profile` of the environment's profiles
    file) to ``directory``/fastdds_children.xml. Under
    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (where rmw_fastrtps adds a shared-memory
    transport itself) the range becomes ``SUBNET`` with the static peer 127.0.0.1 and the
    transports are bound to 127.0.0.1. Nothing ({}) under another RMW than Fast DDS's
    (``RMW_IMPLEMENTATION``): the profile is Fast DDS's, and SUBNET would widen another
    middleware's reach. Raises OSError / ValueError naming the file.
    """
    if environ.get('RMW_IMPLEMENTATION', '') not in FAST_DDS_RMWS:
        return {}
    source = profiles_file(environ)
    text = None
    if source is not None:
        try:
            with open(source) as f:
                text = f.read()
        except OSError as exc:
            raise OSError('Fast DDS profile %s: %s' % (source, exc.strerror)) from None
    loopback = environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') == 'LOCALHOST'
    try:
        xml = udp_profile(text, loopback)
    except ValueError as exc:
        raise ValueError('Fast DDS profile %s: %s' % (source, exc)) from None
    path = os.path.join(directory, 'fastdds_children.xml')
    with open(path, 'w') as f:
        f.write('<?xml version="1.0" encoding="UTF-8" ?>\n' + xml + '\n')
    updates = {k: path for k in PROFILE_ENV}
    if loopback:
        updates.update(ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET', ROS_STATIC_PEERS='127.0.0.1')
    return updates


def log(level, text):
    """One line on stderr in the format of rcutils' console output."""
    print('[%s] [%.9f] [controller_supervisor]: %s' % (level, time.time(), text),
          file=sys.stderr, flush=True)


def describe(status):
    """Return 'signal 9' / 'exit 0' of a waitpid status."""
    if os.WIFSIGNALED(status):
        return 'signal %d' % os.WTERMSIG(status)
    return 'exit %d' % os.waitstatus_to_exitcode(status)


def controller_command():
    """Return the command starting ``controller_node`` (the sibling console script)."""
    here = os.path.dirname(os.path.abspath(sys.argv[0]))
    exe = os.path.join(here, 'controller_node')
    if os.path.isfile(exe) and os.access(exe, os.X_OK):
        return [exe]
    return [sys.executable, '-c',
            'import sys; from freejoint_control.controller_node import main; sys.exit(main())']


class Child:
    """One controller process: its pid, pidfd, node name, role and readiness pipe."""

    def __init__(self, cmd, name, standby, env_updates=None):
        self.name = name
        self.standby = standby
        read, write = os.pipe()
        env = dict(os.environ)
        env.update(env_updates or {})
        env[READY_FD_ENV] = str(write)
        extra = ['--ros-args', '-r', '__node:=' + name]
        if standby:
            extra += ['-p', 'standby:=true']
        self.proc = subprocess.Popen(cmd + extra, env=env, pass_fds=(write,),
                                     preexec_fn=_child_setup)
        os.close(write)
        self.pid = self.proc.pid
        self.ready_fd = read
        self.ready = False
        self.pidfd = os.pidfd_open(self.pid)
        self.started = time.monotonic()
        self.status = None

    def reap(self):
        """Collect the exit status (the pidfd said it exited); close the descriptors."""
        _, self.status = os.waitpid(self.pid, 0)
        self.proc.returncode = os.waitstatus_to_exitcode(self.status)
        self.close()
        return self.status

    def close(self):
        for fd in (self.pidfd, self.ready_fd):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.pidfd = self.ready_fd = None

    def signal(self, signum):
        """Send ``signum`` unless the child was reaped."""
        if self.status is None:
            try:
                os.kill(self.pid, signum)
            except ProcessLookupError:
                pass


def _child_setup():
    # Until the spare's node installs its handler, SIGUSR1 must not kill it (default
    # action): ignored, inherited across exec; the supervisor waits for 'ready'. A child
    # starts at the default scheduler whatever the supervisor's: its start-up (about 1 CPU-s
    # of imports and discovery) at SCHED_FIFO would eat the real-time budget of the graph
    # (kernel.sched_rt_runtime_us: 95 % of each second) and the kernel would throttle every
    # real-time thread, the simulator's and the active controller's too, for the rest of
    # the period (commands 50 ms late). The node sets its scheduling itself once its
    # modules are loaded (a spare: SCHED_FIFO 1 while idle, thread_priority from its
    # activation on).
    signal.signal(signal.SIGUSR1, signal.SIG_IGN)
    if os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


class Supervisor:
    """The active controller, its spare, the respawn and the takeover (module notes)."""

    def __init__(self, node_args, name='controller_node', pid_file=None, stop_timeout=5.0,
                 respawn_delay=2.0, env_updates=None):
        self.cmd = controller_command() + list(node_args)
        self.env_updates = dict(env_updates or {})
        self.names = (name, name + '_spare')
        self.pid_file = pid_file
        self.stop_timeout = stop_timeout
        self.respawn_delay = respawn_delay
        self.spawn_at = None        # monotonic time of the next spare's start
        self.active = None
        self.spare = None
        self.pending_activation = False
        self.stop_signal = None
        self.spawns = []
        self.code = 0
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        os.set_blocking(self._wake_r, False)

    # -- children ---------------------------------------------------------------
    def _spawn(self, standby):
        now = time.monotonic()
        self.spawns = [t for t in self.spawns if now - t < SPAWN_WINDOW] + [now]
        if len(self.spawns) > MAX_SPAWNS:
            log('ERROR', '%d controller starts within %g s: crash loop, stopping'
                % (len(self.spawns), SPAWN_WINDOW))
            self.code = 1
            self._stop(signal.SIGTERM)
            return None
        used = {c.name for c in (self.active, self.spare) if c is not None}
        name = next(n for n in self.names if n not in used)
        child = Child(self.cmd, name, standby, self.env_updates)
        log('INFO', 'started %s controller %d (/%s)' % ('standby' if standby else 'active',
                                                        child.pid, name))
        return child

    def _write_pid_file(self):
        if not self.pid_file:
            return
        doc = {'supervisor': os.getpid(),
               'active': None if self.active is None else {
                   'pid': self.active.pid, 'name': self.active.name},
               'standby': None if self.spare is None else {
                   'pid': self.spare.pid, 'name': self.spare.name, 'ready': self.spare.ready}}
        tmp = self.pid_file + '.tmp'
        with open(tmp, 'w') as f:
            json.dump(doc, f)
        os.replace(tmp, self.pid_file)

    def _activate_spare(self, dead_pid, how):
        spare = self.spare
        self.spare = None
        self.active = spare
        if spare.ready:
            spare.signal(signal.SIGUSR1)
            log('WARN', 'controller %d died (%s): standby %d active (/%s)'
                % (dead_pid, how, spare.pid, spare.name))
        else:
            self.pending_activation = True
            log('WARN', 'controller %d died (%s): standby %d (/%s) not ready yet: activated '
                'when it is' % (dead_pid, how, spare.pid, spare.name))

    def _on_exit(self, child):
        status = child.reap()
        how = describe(status)
        if self.stop_signal is not None:
            log('INFO', 'controller %d (/%s) exited (%s)' % (child.pid, child.name, how))
            if child is self.active:
                self.code = self.code or max(0, os.waitstatus_to_exitcode(status))
            return
        if os.WIFEXITED(status) and os.WEXITSTATUS(status) == EXIT_BAD_PARAMETER:
            log('ERROR', 'controller %d (/%s) refused its parameters (exit 2): stopping'
                % (child.pid, child.name))
            self.code = EXIT_BAD_PARAMETER
            if child is self.active:
                self.active = None
            else:
                self.spare = None
            self._stop(signal.SIGTERM)
            return
        if child is self.active:
            self.active = None
            self.pending_activation = False
            if self.spare is not None:
                self._activate_spare(child.pid, how)
            else:
                log('ERROR', 'controller %d died (%s) with no standby: starting one'
                    % (child.pid, how))
                self.active = self._spawn(False)
        else:
            self.spare = None
            log('WARN', 'standby controller %d (/%s) died (%s): starting another'
                % (child.pid, child.name, how))
        if self.stop_signal is None and self.spare is None and self.spawn_at is None:
            # Not at once: the new active controller's recovery comes first.
            self.spawn_at = time.monotonic() + self.respawn_delay
        self._write_pid_file()

    def _on_ready(self, child):
        try:
            data = os.read(child.ready_fd, 64)
        except OSError:
            data = b''
        os.close(child.ready_fd)
        child.ready_fd = None
        if not data:
            return      # closed without 'ready' (it died first): its pidfd says so
        child.ready = True
        if child is self.active and self.pending_activation:
            self.pending_activation = False
            child.signal(signal.SIGUSR1)
            log('WARN', 'standby %d ready: active (/%s)' % (child.pid, child.name))
        elif child is self.spare:
            log('INFO', 'standby %d ready (/%s)' % (child.pid, child.name))
        self._write_pid_file()

    # -- stop -------------------------------------------------------------------
    def _on_signal(self, signum, frame):
        if self.stop_signal is None:
            self.stop_signal = signum
        try:
            os.write(self._wake_w, b'.')
        except OSError:
            pass

    def _stop(self, signum):
        if self.stop_signal is None:
            self.stop_signal = signum
        for child in (self.active, self.spare):
            if child is not None:
                child.signal(signum)

    def _children(self):
        return [c for c in (self.active, self.spare) if c is not None and c.status is None]

    # -- loop -------------------------------------------------------------------
    def run(self):
        """Supervise until SIGINT / SIGTERM (or a fatal child exit); return the status."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self._on_signal)
        self.active = self._spawn(False)
        self.spare = self._spawn(True)
        self._write_pid_file()
        forwarded = False
        deadline = None
        while True:
            if self.stop_signal is not None and not forwarded:
                forwarded = True
                log('INFO', 'stopping: signal %d forwarded to the controllers'
                    % self.stop_signal)
                self._stop(self.stop_signal)
                deadline = time.monotonic() + self.stop_timeout
            children = self._children()
            if forwarded and not children:
                break
            timeout = 1.0
            if self.spawn_at is not None and self.stop_signal is None:
                wait = self.spawn_at - time.monotonic()
                if wait <= 0.0:
                    self.spawn_at = None
                    if self.spare is None:
                        self.spare = self._spawn(True)
                        self._write_pid_file()
                    continue
                timeout = min(timeout, wait)
            if deadline is not None:
                timeout = max(0.0, min(timeout, deadline - time.monotonic()))
                if timeout == 0.0:
                    for child in children:
                        log('ERROR', 'controller %d did not stop within %g s: SIGKILL'
                            % (child.pid, self.stop_timeout))
                        child.signal(signal.SIGKILL)
                    deadline = None
                    timeout = 1.0
            fds = {self._wake_r: None}
            for child in children:
                fds[child.pidfd] = ('exit', child)
                if child.ready_fd is not None:
                    fds[child.ready_fd] = ('ready', child)
            readable, _, _ = select.select(list(fds), [], [], timeout)
            # Deaths first: a takeover must not wait behind a readiness note.
            events = sorted((fds[fd] for fd in readable if fds[fd] is not None),
                            key=lambda e: e[0] != 'exit')
            if self._wake_r in readable:
                try:
                    os.read(self._wake_r, 64)
                except BlockingIOError:
                    pass
            for kind, child in events:
                if child.status is not None:
                    continue
                if kind == 'exit':
                    self._on_exit(child)
                elif child.ready_fd is not None:
                    self._on_ready(child)
        if self.pid_file:
            try:
                os.unlink(self.pid_file)
            except OSError:
                pass
        return self.code


def parse(argv):
    """Return the supervisor's options and the controller's arguments."""
    ap = argparse.ArgumentParser(
        prog='controller_supervisor', allow_abbrev=False,
        description='Run controller_node with a hot spare that takes over when it dies.')
    ap.add_argument('--name', default='controller_node',
                    help='node name of the first active controller (the spare: NAME_spare)')
    ap.add_argument('--pid-file', default=None, help='JSON file: active and standby pids')
    ap.add_argument('--stop-timeout', type=float, default=5.0,
                    help='s to wait for the children after SIGINT / SIGTERM (then SIGKILL)')
    ap.add_argument('--respawn-delay', type=float, default=2.0,
                    help='s after a death before the next spare is started (default 2: the '
                    "new active controller's recovery first)")
    ap.add_argument('--transport', choices=('udp', 'inherit'), default='udp',
                    help="the children's Fast DDS transports: udp (default: UDPv4 only, a "
                    'killed child leaves no shared-memory port locked) or inherit (as the '
                    'environment)')
    opts, rest = ap.parse_known_args(argv)
    if rest and rest[0] == '--':
        rest = rest[1:]
    return opts, rest


def main(args=None):
    """Run the supervisor; exit with the active controller's status (2: bad parameter)."""
    opts, node_args = parse(sys.argv[1:] if args is None else args)
    with tempfile.TemporaryDirectory(prefix='controller_supervisor_') as directory:
        updates = {}
        if opts.transport == 'udp':
            try:
                updates = udp_environment(os.environ, directory)
            except (OSError, ValueError) as exc:
                log('FATAL', "the children's Fast DDS profile: %s" % exc)
                return EXIT_BAD_PARAMETER
            if updates:
                log('INFO', 'children on UDPv4 only (no shared memory): %s%s' % (
                    updates[PROFILE_ENV[0]], ', discovery SUBNET with the static peer '
                    '127.0.0.1 (LOCALHOST reach)' if 'ROS_STATIC_PEERS' in updates else ''))
            else:
                log('INFO', 'children on the transports of the environment: RMW_IMPLEMENTATION '
                    '%s is not Fast DDS' % os.environ.get('RMW_IMPLEMENTATION'))
        sup = Supervisor(node_args, opts.name, opts.pid_file, opts.stop_timeout,
                         opts.respawn_delay, updates)
        return sup.run()


if __name__ == '__main__':
    sys.exit(main())
