"""
The process harness of the demo, the bench and the multi-process tests.

``make demo`` (tools/demo.py), the bench (bench/graph.py) and the tests (test/conftest.py's
``procs`` fixture) run their node processes and call their services with this module.
:class:`Processes` starts node processes (``ros2 run`` paths, each with its log file and
environment: the run's ``ROS_DOMAIN_ID``), tells which exited, stops them (SIGINT, bounded
wait, SIGKILL of the process group) and collects their exit codes and output.
:class:`ServiceCalls` holds the one copy of the service helpers of a harness node: spin
until a condition (bounded), call a service (waiting for it, bounded), the recorder's
``~/status`` (ready, drained) and the planner's ``~/plan_circle``. :class:`ParameterCalls`
calls one node's parameter services (set, get, list, describe), sending a request again
when its answer is lost. :func:`clean_stale_fast_dds_shm` removes the shared-memory files a
killed node left (the test session calls it). :func:`claim_ros_domain` gives a process a ROS
domain no other run of this machine's tests or demo has claimed. :func:`thread_report` says
what the threads of a process that stopped progressing do. :func:`load_source` imports a
script that is not a package module (tools/demo.py, a test's helpers) by its path.
"""

import fcntl
import importlib.util
import os
import signal
import subprocess
import sys
import tempfile
import time

from freejoint_tools.resend import first_answer


def load_source(path, name):
    """
    Return the Python file at ``path`` executed as a module named ``name``.

    For scripts outside the packages (tools/demo.py, tools/gen_parameters.py) and test
    modules whose helpers another test uses; each call executes the file anew.
    """
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def executable(pkg, exe):
    """Return what ``ros2 run <pkg> <exe>`` starts: <prefix of pkg>/lib/<pkg>/<exe>."""
    from ament_index_python.packages import get_package_prefix
    return os.path.join(get_package_prefix(pkg), 'lib', pkg, exe)


def node_cmd(pkg, exe, params_file=None, overrides=()):
    """Return a node's command line, as ``ros2 run`` with a params file and ``-p`` items."""
    cmd = [executable(pkg, exe), '--ros-args']
    if params_file:
        cmd += ['--params-file', params_file]
    for item in overrides:
        cmd += ['-p', item]
    return cmd


class Processes:
    """
    The node processes of one run: start each with a log and an environment, stop them.

    Parameters
    ----------
    log_dir : str
        Directory of the logs, ``<log_dir>/<tag>_<name>.log`` (``<name>.log`` without tag).
    tag : str, optional
        Prefix of the log names.
    env : dict, optional
        Environment of every process (default: this process's), ``PYTHONUNBUFFERED=1``.
    cwd : str, optional
        Working directory of the processes.
    stop_timeout : float, optional
        Default wait [s] of :meth:`stop` after SIGINT before SIGKILL.

    Attributes
    ----------
    procs : dict
        {name: the latest process started under that name} (``subprocess.Popen`` with
        ``name``, ``log_path``, ``log_file`` and ``logs``: its and its predecessors' logs).

    """

    def __init__(self, log_dir, tag=None, env=None, cwd=None, stop_timeout=20.0):
        self.log_dir = log_dir
        self.stop_timeout = stop_timeout
        self.tag = tag
        self.env = dict(os.environ if env is None else env, PYTHONUNBUFFERED='1')
        self.cwd = cwd
        self.procs = {}
        self.started = []       # every process, in start order

    def start(self, name, cmd, env=None, log_name=None):
        """
        Start ``cmd`` (list) with its output in its log; return the process.

        ``env`` adds to the harness environment. A name already used is replaced in
        ``procs`` (a restart: stop or kill the old process first); ``log_name`` keeps the
        old one's log (a log per name otherwise).
        """
        os.makedirs(self.log_dir, exist_ok=True)
        base = log_name or name
        path = os.path.join(self.log_dir, '%s_%s.log' % (self.tag, base) if self.tag
                            else base + '.log')
        log = open(path, 'w')
        # The processes hold this process's domain claim too (claim_ros_domain): a node
        # that outlives its test keeps its domain from the next run that would take it.
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                env=dict(self.env, **(env or {})), cwd=self.cwd,
                                start_new_session=True, pass_fds=tuple(_DOMAIN_CLAIMS))
        proc.name = name
        proc.log_path = path
        proc.log_file = log
        old = self.procs.get(name)
        proc.logs = [path] + [p for p in getattr(old, 'logs', []) if p != path]
        self.procs[name] = proc
        self.started.append(proc)
        return proc

    def start_node(self, pkg, exe, name, args=()):
        """Start an installed node exactly as ``ros2 run pkg exe args...`` would."""
        return self.start(name, [executable(pkg, exe), *args])

    def start_script(self, path, name, args=()):
        """Start a Python script with this interpreter."""
        return self.start(name, [sys.executable, path, *args])

    def _proc(self, which):
        return self.procs[which] if isinstance(which, str) else which

    def exited(self):
        """Return the names of the processes that have exited; empty while all run."""
        return [n for n, p in self.procs.items() if p.poll() is not None]

    def log(self, which):
        """Return what a process (or name) printed so far."""
        proc = self._proc(which)
        if not proc.log_file.closed:
            proc.log_file.flush()
        with open(proc.log_path) as f:
            return f.read()

    def tail(self, which, lines=8):
        """Return the last ``lines`` lines of a process's (or name's) log."""
        return ''.join(self.log(which).splitlines(True)[-lines:])

    def stop(self, which, timeout=None):
        """SIGINT a process (or name), wait ``timeout`` s, then SIGKILL; return its code."""
        proc = self._proc(which)
        timeout = self.stop_timeout if timeout is None else timeout
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5.0)
        if not proc.log_file.closed:
            proc.log_file.close()
        return proc.returncode

    def stop_all(self, order=(), timeouts=None):
        """
        Stop every process not stopped yet; return {name: exit code}.

        The names of ``order`` first, in that order, then the others, last started first;
        ``timeouts`` maps a name to its SIGINT wait (``stop_timeout`` otherwise).
        """
        rest = [p for p in reversed(self.started) if p.name not in order]
        named = [p for n in order for p in self.started if p.name == n]
        codes = {}
        for proc in named + rest:
            if not proc.log_file.closed:
                codes[proc.name] = self.stop(proc, (timeouts or {}).get(proc.name))
        return codes


class ServiceCalls:
    """
    Service calls of a harness node spun by ``executor`` (every wait bounded).

    Parameters
    ----------
    node : rclpy.node.Node
        The harness's node (clients are created on it per call).
    executor : rclpy executor, optional
        The executor that spins ``node``; None: ``rclpy.spin_once(node)`` (the global
        executor, as a test's ``ros_node`` is spun).

    """

    def __init__(self, node, executor=None):
        self.node = node
        self.executor = executor

    def spin_until(self, predicate, timeout, step=0.05):
        """Spin until ``predicate()`` or ``timeout`` wall s; return whether it held."""
        import rclpy
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            if self.executor is None:
                rclpy.spin_once(self.node, timeout_sec=step)
            else:
                self.executor.spin_once(timeout_sec=step)
        return predicate()

    def first_answer(self, send, timeout, resend=None):
        """
        Send a request and spin until it is answered; return ``(result or None, sent)``.

        ``send()`` sends one request and returns its future. With ``resend`` (s; for
        idempotent requests only) a request unanswered that long is sent again, until one
        is answered or ``timeout`` s have passed: rmw_fastrtps drops a response sent before
        the server matched the client's response reader (ros2/rmw_fastrtps#390, #467), and
        waiting longer never brings it. ``sent`` is the number of requests sent; the
        others' futures are cancelled (a late answer goes nowhere). The loop is
        ``freejoint_tools.resend.first_answer``, spinning this executor while it waits.
        """
        future, sent = first_answer(
            send, lambda predicate, seconds: self.spin_until(predicate, seconds, step=0.01),
            timeout, resend)
        return (None if future is None else future.result()), sent

    def call(self, srv_type, name, request, timeout, resend=None):
        """
        Call service ``name`` (waiting for it up to ``timeout`` s); answer or None.

        ``resend``: see :meth:`first_answer` (idempotent services only, e.g. a ``~/reset``).
        """
        client = self.node.create_client(srv_type, name)
        try:
            if not self.spin_until(client.service_is_ready, timeout):
                return None
            return self.first_answer(lambda: client.call_async(request), timeout, resend)[0]
        finally:
            self.node.destroy_client(client)

    def recorder_answer(self, timeout=5.0):
        """Return the recorder's ``~/status`` answer (``std_srvs/Trigger``), None if none."""
        from freejoint_common.contract import RECORDER_STATUS
        trigger = RECORDER_STATUS.srv_type
        return self.call(trigger, RECORDER_STATUS.of('recorder'), trigger.Request(), timeout,
                         resend=2.0)

    def recorder_status(self, timeout=5.0):
        """Return the answer message of the recorder's ``~/status`` ('': no answer)."""
        answer = self.recorder_answer(timeout)
        return answer.message if answer is not None else ''

    def recorder_ready(self, timeout):
        """Wait until the recorder's ``~/status`` says every graph topic is matched."""
        from freejoint_common.contract import RECORDER_STATUS
        trigger = RECORDER_STATUS.srv_type
        deadline = time.monotonic() + timeout
        answer = None
        while time.monotonic() < deadline:
            answer = self.call(trigger, RECORDER_STATUS.of('recorder'), trigger.Request(),
                               max(0.1, deadline - time.monotonic()), resend=2.0)
            if answer is not None and answer.success:
                return True, answer.message
            self.spin_until(lambda: False, 0.2)
        return False, answer.message if answer is not None else 'no answer'

    def recorder_drained(self, quiet=None, timeout=120.0):
        """
        Wait until the recorder's received count is unchanged for ``quiet`` s.

        ``quiet`` None: ``recorder.REPAIR_QUIET`` (a reliable writer's repair of a sample
        the recorder missed comes after its next heartbeat).

        Called once the simulator holds at ``max_steps`` (the graph is silent): a steady
        count means the recorder has taken everything. Return (count or None, wall s).
        """
        from freejoint_tools.recorder import REPAIR_QUIET, wait_drained
        quiet = REPAIR_QUIET if quiet is None else quiet
        deadline = time.monotonic() + timeout
        return wait_drained(
            lambda: self.recorder_status(max(0.1, deadline - time.monotonic())),
            quiet, timeout, lambda: self.spin_until(lambda: False, 0.1))

    def plan_circle(self, plan, timeout=20.0):
        """Ask the planner for the circle of ``plan`` (its parameters), executed at once."""
        from freejoint_common.contract import PLAN_CIRCLE
        request = PLAN_CIRCLE.srv_type.Request(
            centre=[float(v) for v in plan['centre']], radius=float(plan['radius']),
            duration=float(plan['duration']), start_angle=float(plan['start_angle']),
            direction=int(plan['direction']), execute=True)
        return self.call(PLAN_CIRCLE.srv_type, PLAN_CIRCLE.of('freejoint_planner'), request,
                         timeout)


class ParameterCalls:
    """
    Call the parameter services of the node ``target``, sending a lost request again.

    A request left unanswered for ``resend`` s is sent again, and again, until one is
    answered or ``timeout`` s have passed; the first answer is returned. rmw_fastrtps
    drops a service response when the server has not matched the client's response reader
    yet ("failed to send response ... client will not receive response",
    ros2/rmw_fastrtps#390, #467): waiting longer never brings that answer, a new request
    does. Only idempotent requests are made, so that a request taken twice leaves the node
    as once: set parameters to values (the nodes' set callbacks act on the values, not on
    the number of requests; a refused value is refused again), get, list, describe. The
    requests go through one rclpy ``AsyncParameterClient``, so they arrive in order: a
    resent set is taken before the next call's request. Every wait is bounded.

    Parameters
    ----------
    node : rclpy.node.Node
        The calling node (the harness's or the test's).
    target : str
        The node whose services are called, as ``ros2 param`` names it
        (``/controller_node``, or relative to ``node``'s namespace).
    executor : rclpy executor, optional
        The executor that spins ``node``; None: ``rclpy.spin_once(node)``.
    timeout : float, optional
        Wall s to wait for the services (once per instance), then for each call's answer.
    resend : float, optional
        Wall s without an answer after which the request is sent again.

    Attributes
    ----------
    sent : int
        The number of requests the latest call sent (1 when its first was answered).

    Raises
    ------
    TimeoutError
        From any call: no parameter services of ``target`` within ``timeout`` s, or no
        answer within ``timeout`` s; the message names the target and the service.

    """

    def __init__(self, node, target, executor=None, timeout=15.0, resend=3.0):
        from rclpy.parameter_client import AsyncParameterClient
        self.target = target
        self.timeout = timeout
        self.resend = resend
        self.calls = ServiceCalls(node, executor)
        self.client = AsyncParameterClient(node, target)
        self.sent = 0           # requests sent by the latest call
        self._ready = False

    def _call(self, service, send):
        """Send ``send()`` until answered (every ``resend`` s, ``timeout`` s); the answer."""
        if not self._ready:
            self._ready = self.calls.spin_until(self.client.services_are_ready, self.timeout)
            if not self._ready:
                raise TimeoutError('no parameter services of %s within %g s'
                                   % (self.target, self.timeout))
        result, self.sent = self.calls.first_answer(send, self.timeout, self.resend)
        if result is None:
            raise TimeoutError('no answer from %s/%s within %g s (requests sent: %d, one '
                               'every %g s)' % (self.target, service, self.timeout,
                                                self.sent, self.resend))
        return result

    def set_parameters(self, params):
        """
        Set ``params`` (``rclpy.parameter.Parameter`` list) as ``ros2 param set`` does.

        Returns the node's ``SetParametersResult`` of each, in order (``successful``,
        ``reason``).
        """
        params = list(params)
        return list(self._call('set_parameters',
                               lambda: self.client.set_parameters(params)).results)

    def get_parameters(self, names):
        """Return the ``ParameterValue`` messages of ``names``, in order."""
        names = list(names)
        return list(self._call('get_parameters',
                               lambda: self.client.get_parameters(names)).values)

    def get_values(self, names):
        """Return {name: value as plain Python} of ``names`` (one get_parameters call)."""
        from rclpy.parameter import parameter_value_to_python
        names = list(names)
        return {n: parameter_value_to_python(v)
                for n, v in zip(names, self.get_parameters(names))}

    def list_parameters(self):
        """Return the names of every parameter of the node (``ros2 param list``)."""
        return list(self._call('list_parameters',
                               lambda: self.client.list_parameters()).result.names)

    def describe_parameters(self, names):
        """Return the ``ParameterDescriptor`` messages of ``names``, in order."""
        names = list(names)
        return list(self._call('describe_parameters',
                               lambda: self.client.describe_parameters(names)).descriptors)


_POLICIES = {0: 'OTHER', 1: 'FIFO', 2: 'RR', 3: 'BATCH', 5: 'IDLE', 6: 'DEADLINE'}


def _thread_stats(task_dir):
    """Return {tid: (name, state, cpu ticks, policy, rt priority, last CPU)} of a task dir."""
    out = {}
    try:
        tids = os.listdir(task_dir)
    except OSError:
        return out
    for tid in tids:
        try:
            with open(os.path.join(task_dir, tid, 'stat')) as fh:
                stat = fh.read()
        except OSError:
            continue            # ended meanwhile
        name = stat[stat.index('(') + 1:stat.rindex(')')]
        rest = stat[stat.rindex(')') + 2:].split()
        # fields 3 (state), 14 + 15 (utime, stime), 39 (processor), 40, 41 (rt prio, policy)
        out[int(tid)] = (name, rest[0], int(rest[11]) + int(rest[12]), int(rest[38]),
                         int(rest[37]), int(rest[36]))
    return out


def _wchan(pid, tid):
    try:
        with open('/proc/%d/task/%d/wchan' % (pid, tid)) as fh:
            return fh.read().strip() or '-'
    except OSError:
        return '?'


def thread_scheduling(pid):
    """
    Return the scheduling of every thread of process ``pid``, split as the node sets it.

    Returns
    -------
    (list, list)
        ``(policy, priority, cpus)`` of each thread the node's ``thread_priority`` applies
        to, and of each thread it keeps at the default scheduler
        (``freejoint_common.scheduling.BEST_EFFORT_THREADS``); ``cpus`` sorted lists. A
        thread that ended meanwhile is left out.

    """
    from freejoint_common.scheduling import best_effort_thread
    node, best_effort = [], []
    for tid in map(int, os.listdir('/proc/%d/task' % pid)):
        try:
            with open('/proc/%d/task/%d/comm' % (pid, tid)) as f:
                name = f.read().strip()
            row = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority,
                   sorted(os.sched_getaffinity(tid)))
        except OSError:                       # the thread ended meanwhile
            continue
        (best_effort if best_effort_thread(name) else node).append(row)
    return node, best_effort


def thread_report(pid, interval=1.0):
    """
    Describe what the threads of process ``pid`` do, for a process that stopped progressing.

    Samples ``/proc`` twice, ``interval`` s apart: per thread of ``pid`` its name, state,
    scheduling, last CPU, CPU time used in the interval and kernel wait channel; then every
    SCHED_FIFO / SCHED_RR thread of the machine (other processes) that used CPU in the
    interval - a busy real-time thread starves lower priorities on its CPUs. Returns the
    text (no exception: what cannot be read is left out).
    """
    tick = os.sysconf('SC_CLK_TCK')
    before = _thread_stats('/proc/%d/task' % pid)
    others = {}
    for proc in os.listdir('/proc'):
        if proc.isdigit() and int(proc) != pid:
            for tid, st in _thread_stats('/proc/%s/task' % proc).items():
                if st[3] in (1, 2):
                    others[(int(proc), tid)] = st
    time.sleep(interval)
    after = _thread_stats('/proc/%d/task' % pid)
    lines = ['threads of %d over %g s (name state policy/prio cpu used[s] wchan):'
             % (pid, interval)]
    for tid in sorted(after):
        name, state, ticks, policy, prio, cpu = after[tid]
        used = (ticks - before.get(tid, after[tid])[2]) / tick
        lines.append('  %d %s %s %s/%d cpu%d %.2f %s' % (
            tid, name, state, _POLICIES.get(policy, policy), prio, cpu, used,
            _wchan(pid, tid)))
    busy = []
    for (proc, tid), st in sorted(others.items()):
        now = _thread_stats('/proc/%d/task' % proc).get(tid)
        if now is not None and now[2] > st[2]:
            busy.append('  %d/%d %s %s/%d cpu%d %.2f' % (
                proc, tid, now[0], _POLICIES.get(now[3], now[3]), now[4], now[5],
                (now[2] - st[2]) / tick))
    lines.append('real-time threads of other processes busy meanwhile: %s'
                 % ('\n' + '\n'.join(busy) if busy else 'none'))
    return '\n'.join(lines)


SHM_DIR = '/dev/shm'
SHM_PREFIX = 'fastrtps_'


_DOMAIN_CLAIMS = []
"""Open lock files of the domains this process claimed (held until it exits)."""
DOMAIN_LOCK_DIR = os.path.join(tempfile.gettempdir(), 'freejoint_ros_domains')


def claim_ros_domain(preferred, first=1, count=100, lock_dir=DOMAIN_LOCK_DIR):
    """
    Claim a ROS domain no other process of this machine holds; return its id.

    Runs that share a machine (two ``make test``, a test run and ``make demo``) each pick a
    domain, and with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` two that picked the same
    one see each other's nodes: a recorder records the other run's publisher, a planner
    takes the other run's arm (whatever the load, as soon as their picks coincide). Each
    domain ``d`` of ``first .. first + count - 1`` has a lock file ``<lock_dir>/<d>.lock``;
    this takes the first of ``preferred, preferred + 1, ...`` (wrapping) whose exclusive
    ``flock`` nobody holds and holds it until the process exits (the kernel releases it
    then, also on SIGKILL). The node processes :class:`Processes` starts inherit the lock,
    so a node that outlives its run keeps the domain claimed.

    Raises
    ------
    RuntimeError
        Every domain of the range is claimed.

    """
    os.makedirs(lock_dir, exist_ok=True)
    for i in range(count):
        domain = first + (preferred - first + i) % count
        fd = os.open(os.path.join(lock_dir, '%d.lock' % domain), os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _DOMAIN_CLAIMS.append(fd)
        return domain
    raise RuntimeError('every ROS domain %d..%d is claimed (locks in %s)'
                       % (first, first + count - 1, lock_dir))


def clean_stale_fast_dds_shm(shm_dir=SHM_DIR):
    """
    Remove the Fast DDS shared-memory files whose owner is dead; return their names.

    What ``fastdds shm clean`` does: a participant holds an exclusive ``flock`` on the
    ``<name>_el`` file of its segment and of each port it listens on for its whole life; a
    process killed with SIGKILL leaves them behind (sometimes the ``_el`` file without its
    port), and a later participant given the same port number fails
    ``open_and_lock_file`` and loses messages (the tests kill nodes on purpose). An
    ``_el`` file nobody holds is removed with its ``<name>`` file.
    """
    try:
        names = [n for n in os.listdir(shm_dir)
                 if n.startswith(SHM_PREFIX) and n.endswith('_el')]
    except OSError:
        return []
    removed = []
    for name in names:
        path = os.path.join(shm_dir, name)
        try:
            fd = os.open(path, os.O_RDWR)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue            # held: its owner lives
        try:
            for stale in (path[:-3], path):
                try:
                    os.unlink(stale)
                    removed.append(os.path.basename(stale))
                except FileNotFoundError:
                    pass
        finally:
            os.close(fd)
    return removed
