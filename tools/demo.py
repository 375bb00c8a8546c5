"""
Run the paper's two cases through the ROS 2 node graph (`make demo`), beside the offline runner.

For Case 1 (horizontal) and Case 2 (vertical), in lockstep with the robust controller and
disturbance seed 0, this starts the three nodes as separate processes - exactly the
executables ``ros2 run`` starts (``install/<pkg>/lib/<pkg>/<exe>``) with the parameter files
of ``config/`` and per-case overrides (``-p case:=vertical``) - and the recorder when it is
installed, follows the run, stops everything with SIGINT and computes the graph's record from
the messages the run published (``freejoint_common.records.arrays_from_messages``, then
``freejoint_core.metrics.compute_record``).  It prints the offline runner's records of the
same runs beside the graph's, checks that the end-effector trajectories agree, writes the
graph's records to ``bags/demo/metrics.json`` and runs ``analyze`` on the bags if installed.

Usage: ``python tools/demo.py [--cases horizontal vertical] [--seed 0] [--out bags/demo]``

``--stabilise`` runs the vertical case with config/stabilised/ on top (the free
link starts hanging, the controller's ``free_link_damping`` on) beside the offline circles
runner with the same options (``freejoint_core.circles.run_circles``, one circle), into
``<out>/stabilised``.

``--arm four_link`` (``make demo ARM=four_link``) runs the shipped 4-link example instead
(``config/four_link/*.yaml`` on top of ``config/*.yaml``: four_link_arm.urdf, joint1 passive,
the horizontal case), recorded and analysed, beside its offline runner
(``freejoint_core.urdf_offline.run_arm``), and checks its tracking bound (``ARMS``).
With ``--stabilise`` too (``make demo ARM=four_link STABILISE=1``) it runs the example in
the vertical plane with ``config/four_link/stabilised/`` on top (its hanging equilibrium,
null-space damping, twice the paper's task gains) beside the offline circles runner.
``--arm ur5`` / ``--arm panda`` (``make demo ARM=ur5``) run a spatial arm from
example-robot-data's URDF (``config/<arm>/``: UR5 with wrist_2 free, Panda with joint 7
free, task_dim 3): the tip's 0.1-m circle in the vertical plane facing the robot, then a
10-s hold, beside the offline twin (``freejoint_core.spatial_offline.run_twin`` with the
graph's parameter files); the tip compared tick by tick (1e-9 m), the 3-mm bound, the
efforts and joint speeds against the URDF's limits. ``--arm DIR`` does the same for the
files ``fj arm init`` wrote into DIR (``make demo ARM=DIR``; the run named by DIR's
arm.yaml), ``--arm FILE.urdf --passive JOINT [--tip T] [--base B]`` runs ``fj arm init``
into ``OUT/<name>/`` first (docs/own-arm.md).
``--fail joint3@2.5`` (``make demo FAIL=joint3@2.5``) runs the paper's arm with
all three joints driven (``config/fully_actuated/``) whose joint 3 loses its actuator and
brake at 2.5 s (the simulator's ``fail_joint``): the controller detects it (momentum
residual and the effort of joint_states) and switches to the law with that joint free,
announcing it on ``joint_failures``, where the planner learns the new passive set.  Beside
it the offline failure runner (``freejoint_core.failure_offline.run_failure_case``, same
case, seed and failure): joint angles and commands compared tick by tick (1e-9), the
detection and the tracking bound (horizontal 1.7 mm, vertical 5.5 mm) reported, into
``<out>/failure``.
(``make demo`` runs it after ``tools/setup.sh``).  The graph runs in ROS domain
``$ROS_DOMAIN_ID`` (if unset, a free one is picked and printed) and sees only this machine
unless ``ROS_AUTOMATIC_DISCOVERY_RANGE`` says otherwise.
"""
import argparse
import os
import subprocess
import sys
import time

from freejoint_common.contract import LOCKSTEP_WRITER_DEPTH
from freejoint_tools.arm_twin import SPATIAL_ARMS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INSTALL = os.path.join(ROOT, 'install')
CONFIG = os.path.join(ROOT, 'config')
CASES = ('horizontal', 'vertical')
PASSIVE_JOINT = 'joint3'
STALL_TIMEOUT = 30.0
"""Wall seconds without a new tick after which a run is given up."""
SETTLE = 1.0
"""Wall seconds between the recorder's readiness and the start of the circle."""
DRAIN_QUIET = None
"""Wall seconds the recorder's count must stay unchanged before the nodes are stopped
(None: ``freejoint_tools.recorder.REPAIR_QUIET``, past a reliable writer's heartbeat)."""
COLLECT_DEPTH = LOCKSTEP_WRITER_DEPTH
"""Keep-last depth of the collected streams, in this process's readers and in the nodes'
writers of them (:func:`collected_writer_args`; ``freejoint_common.contract``'s
``LOCKSTEP_WRITER_DEPTH`` says why)."""
FIGURES = os.path.join(ROOT, 'docs', 'figures')
ARMS = dict({'four_link': {'passive_joint': 'joint1', 'bound_mm': 2.0}}, **SPATIAL_ARMS)
STABILISED = 'stabilised'
STABILISED_HORIZONTAL = 'stabilised_horizontal'
"""The horizontal case's overlay of ``--stabilise`` (the free link settled in the rests)."""
FULLY_ACTUATED = 'fully_actuated'
"""The overlay of ``--fail``: config/fully_actuated/, all three joints driven."""
FAILURE_BOUND_MM = {'horizontal': 1.7, 'vertical': 5.5}
"""The paper's single-circle bounds, which a run with a joint failing keeps."""
"""The overlay of ``--stabilise``: config/stabilised/, the vertical case."""
"""The shipped examples of ``--arm``: parameter overlay ``config/<name>/``, the passive joint
recorded, the stated tracking bound (horizontal; test/core/test_four_link_example.py); a
spatial arm also its case of ``freejoint_core.spatial_offline`` and the hold
after the circle [s]."""
"""Where the figures of the two paper cases go (shown in the README)."""


def arm_info(arm):
    """
    Return the ``ARMS`` entry of a shipped arm, or of an arm directory of ``fj arm init``.

    A directory (``make demo ARM=DIR``) holds sim.yaml, controller.yaml, planner.yaml and
    arm.yaml (``name``, ``passive_joint``, ``hold_s``, ``bound_mm``); its entry's
    ``spatial`` (the run's case label) is ``name``.
    """
    from freejoint_tools.arm_twin import arm_info as dir_info
    if arm in ARMS:
        return ARMS[arm]
    meta = os.path.join(arm, 'arm.yaml')
    if not os.path.isfile(meta):
        raise SystemExit('demo: --arm %s: neither a shipped arm (%s) nor a directory of fj '
                         'arm init (no %s)' % (arm, ', '.join(sorted(ARMS)), meta))
    return dir_info(arm)


def spatial_titles(passive_joint):
    """Return the table titles of a spatial arm: its free joint's range, its kappa."""
    name = passive_joint[:-len('_joint')] if passive_joint.endswith('_joint') else passive_joint
    return {'q3_deg': name + '_deg', 'min_det': 'min_kappa'}


def executable(pkg, exe):
    """Return what ``ros2 run <pkg> <exe>`` starts: install/<pkg>/lib/<pkg>/<exe>."""
    return os.path.join(INSTALL, pkg, 'lib', pkg, exe)


def say(text):
    """Print a progress line at once."""
    print('[demo] ' + text, flush=True)


def shown(path):
    """Return ``path`` relative to the repository if it lies inside it, else absolute."""
    path = os.path.abspath(path)
    return os.path.relpath(path, ROOT) if path.startswith(ROOT + os.sep) else path


# -- settings -------------------------------------------------------------------------
def offline_settings(config_dir=CONFIG):
    """
    Return the ``run_case`` keyword arguments matching the parameter files of the graph.

    Parameters
    ----------
    config_dir : str
        Directory holding sim.yaml, controller.yaml and planner.yaml.

    Returns
    -------
    dict
        ``dt``, ``dt_sub``, ``duration``, ``nominal_scale``, ``dist_bound``, ``q3_0_deg``,
        ``gains``, ``trajectory`` for ``freejoint_core.offline.run_case``.

    """
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_planner.planning import make_circle
    from freejoint_sim.params import SCHEMA as SIM
    sim = SIM.from_yaml(os.path.join(config_dir, 'sim.yaml'))
    ctl = CONTROLLER.from_yaml(os.path.join(config_dir, 'controller.yaml'))
    plan = PLANNER.from_yaml(os.path.join(config_dir, 'planner.yaml'))
    for name, other in (('controller', ctl.dt), ('planner', plan['control_period'])):
        if other != sim.dt:
            raise SystemExit('demo: control_period differs between sim.yaml (%g) and %s.yaml '
                             '(%g)' % (sim.dt, name, other))
    if plan['nominal_scale'] != ctl.nominal_scale:
        raise SystemExit('demo: nominal_scale differs between controller.yaml (%g) and '
                         'planner.yaml (%g)' % (ctl.nominal_scale, plan['nominal_scale']))
    trajectory = make_circle(plan)
    start = trajectory.sample(0.0)[0].tolist()
    if max(abs(a - b) for a, b in zip(start, sim.initial_position)) > 1e-12:
        raise SystemExit('demo: sim.yaml initial_position %s is not the start of the planned '
                         'circle %s, but the offline runner starts there'
                         % (list(sim.initial_position), start))
    return {'dt': sim.dt, 'dt_sub': sim.dt_sub, 'duration': float(plan['duration']),
            'nominal_scale': ctl.nominal_scale, 'dist_bound': sim.dist_bound,
            'q3_0_deg': sim.initial_passive_deg, 'gains': ctl.gains,
            'trajectory': trajectory}


# -- collecting the run's messages -----------------------------------------------------
class Collector:
    """
    Take the run's ControllerState, JointState and ee_position messages, serialized.

    Serialized (``raw=True``) subscriptions keep the callbacks cheap enough for 1 kHz; the
    stamps are read straight from the CDR header, the messages are deserialized after the
    run.  Deep reader queues keep every message while this process catches up.
    """

    def __init__(self, node, depth=COLLECT_DEPTH):
        from freejoint_common.contract import CONTROLLER_STATE, EE_POSITION, JOINT_STATES
        from freejoint_common.contract import profile
        qos = profile(depth)
        self.node = node
        self.types = {}
        self.raw = {}
        self.last = {}
        self.subs = {}
        for topic, msg_type in ((t.name, t.msg_type)
                                for t in (CONTROLLER_STATE, JOINT_STATES, EE_POSITION)):
            self.types[topic] = msg_type
            self.raw[topic] = []
            self.last[topic] = -1
            self.subs[topic] = node.create_subscription(
                self.types[topic], topic, self._callback(topic), qos, raw=True)

    def _callback(self, topic):
        from freejoint_common.contract import clock_ns   # the Header's stamp, as /clock's
        store = self.raw[topic].append
        last = self.last

        def take(raw):
            store(raw)
            ns = clock_ns(raw)
            if ns > last[topic]:
                last[topic] = ns
        return take

    def close(self):
        """Destroy the subscriptions (what arrives later is not taken)."""
        for sub in self.subs.values():
            self.node.destroy_subscription(sub)
        self.subs = {}

    def progress_ns(self):
        """Return the newest stamp every topic has reached (ns), -1 before the first."""
        return min(self.last.values())

    def publishers_ready(self, topics=('controller_state', 'joint_states', 'ee_position')):
        """Return True when each subscription has matched a publisher."""
        return all(self.subs[t].get_publisher_count() > 0 for t in topics)

    def messages(self, topic):
        """Deserialize what was taken on ``topic``, in arrival order."""
        from rclpy.serialization import deserialize_message
        kind = self.types[topic]
        return [deserialize_message(raw, kind) for raw in self.raw[topic]]


def ee_trajectory(points, dt_ns, n_ticks, dims=2):
    """
    Return the end-effector positions of ticks 0..n_ticks-1 from ee_position messages.

    Parameters
    ----------
    points : list of geometry_msgs/PointStamped
        The messages, any order, repeats allowed (the first per stamp counts).
    dt_ns : int
        Control period (ns).
    n_ticks : int
        Number of ticks wanted.
    dims : {2, 3}
        2: (x, y) of a planar arm; 3: (x, y, z) of a spatial arm's tip.

    Returns
    -------
    numpy.ndarray, (n_ticks, dims)

    Raises
    ------
    ValueError
        Naming the first tick without a message.

    """
    from freejoint_common.contract import to_ns
    import numpy as np
    first = {}
    for msg in points:
        first.setdefault(to_ns(msg.header.stamp), msg)
    out = np.empty((n_ticks, dims))
    for k in range(n_ticks):
        msg = first.get(k * dt_ns)
        if msg is None:
            raise ValueError('ee_position: no message for tick %d (t = %.3f s)'
                             % (k, k * dt_ns * 1e-9))
        out[k] = (msg.point.x, msg.point.y, msg.point.z)[:dims]
    return out


def collected_writer_args(node):
    """
    Return ``-p`` items giving ``node``'s writers of the collected streams COLLECT_DEPTH.

    ``node``: 'sim' (joint_states, ee_position) or 'controller' (controller_state); any
    other node writes none of them (``[]``): ``contract.lockstep_writer_overrides``.
    """
    from freejoint_common.contract import lockstep_writer_overrides
    return lockstep_writer_overrides(node, COLLECT_DEPTH)


def _overlay_files(overlays, node):
    """Return the files ``config/<dir>/<node>.yaml`` of ``overlays`` (dirs) that exist."""
    paths = [os.path.join(CONFIG, name, node + '.yaml') for name in overlays]
    return [path for path in paths if os.path.exists(path)]


def _overlay(overlays, node):
    """Return the ``--params-file`` arguments of the overlays for ``node`` (none: ``[]``)."""
    return [arg for path in _overlay_files(overlays, node) for arg in ('--params-file', path)]


def _args(node_args, node):
    """Return the ``-p`` arguments of :func:`collected_writer_args` and ``node_args[node]``."""
    items = collected_writer_args(node) + list((node_args or {}).get(node, ()))
    return [arg for item in items for arg in ('-p', item)]


def run_graph(case, seed, n_ticks, dt_ns, collector, executor, out_dir, log_dir,
              record=True, progress=say, overlays=(), passive_joint=PASSIVE_JOINT,
              node_args=None, recorded_as=None):
    """
    Run one case through the graph in lockstep until tick n_ticks - 1 was published.

    ``overlays``: directories under config/ (a shipped example of ``ARMS``, ``STABILISED``,
    ``FULLY_ACTUATED``, or both of ``--arm four_link --stabilise``) whose ``<node>.yaml``
    follow each node's parameter file, in order, where there is one; () for the paper's arm.
    ``passive_joint``: the one the recorder's metadata names.  ``node_args``: ``{'sim' |
    'controller' | 'planner': ['name:=value', ...]}``, parameters set last.
    ``recorded_as``: ``(case, variant)`` the bag's run information names (default
    ``(case, 'robust')``; a spatial arm: its ``spatial_offline`` case, 'spatial').

    All nodes are started (recorder if installed, simulator, controller, planner with
    ``autostart: false``); once the recorder (``~/status``) and this process have matched
    every publisher, the planner's ``~/plan_circle`` starts the configured circle at t = 0.

    Returns
    -------
    dict
        ``wall_s`` (first to last tick), ``sim_s``, ``codes`` (exit codes), ``logs``,
        ``bag`` (path or None), ``sim_log``.

    Raises
    ------
    RuntimeError
        A node exited early, or the run did not start or stalled (the message names the
        logs).

    """
    from freejoint_tools.harness import node_cmd, Processes, ServiceCalls
    graph = Processes(log_dir, case, cwd=ROOT)
    calls = ServiceCalls(collector.node, executor)
    rec_exe = executable('freejoint_tools', 'recorder')
    bag = None
    try:
        if record and os.path.exists(rec_exe):
            bag = os.path.join(out_dir, recorded_as[0] if recorded_as else case)
            info = 'case=%s, variant=%s, seed=%d, passive_joint=%s, max_ticks=%d' % (
                *(recorded_as or (case, 'robust')), seed, passive_joint, n_ticks)
            graph.start('recorder', [rec_exe, '--ros-args', '-p', 'output:=' + bag,
                                     '-p', 'topics:=[]', '-p', 'overwrite:=true',
                                     '-p', 'use_sim_time:=true',
                                     '-p', 'custom_data:=[%s]' % info])
        graph.start('sim_node', node_cmd('freejoint_sim', 'sim_node',
                                         os.path.join(CONFIG, 'sim.yaml'),
                                         ['case:=' + case, 'seed:=%d' % seed,
                                          'max_steps:=%d' % n_ticks])
                    + _overlay(overlays, 'sim') + _args(node_args, 'sim'))
        graph.start('controller_node', node_cmd('freejoint_control', 'controller_node',
                                                os.path.join(CONFIG, 'controller.yaml'),
                                                ['case:=' + case])
                    + _overlay(overlays, 'controller') + _args(node_args, 'controller'))
        graph.start('planner_node', node_cmd('freejoint_planner', 'planner_node',
                                             os.path.join(CONFIG, 'planner.yaml'),
                                             ['case:=' + case, 'autostart:=false'])
                    + _overlay(overlays, 'planner') + _args(node_args, 'planner'))
        if not calls.spin_until(lambda: collector.publishers_ready() or graph.exited(),
                                60.0) or graph.exited():
            raise RuntimeError('the nodes did not come up within 60 s%s (logs in %s)' % (
                '' if not graph.exited() else ': %s exited' % graph.exited(), log_dir))
        if bag is not None:
            ok, status = calls.recorder_ready(60.0)
            if not ok:
                raise RuntimeError('the recorder is not ready after 60 s: %s (logs in %s)'
                                   % (status, log_dir))
            # The readers have matched every publisher; the writers' side of the match
            # (what makes a volatile writer send to the recorder) can lag by tens of ms.
            calls.spin_until(lambda: False, SETTLE)
        from freejoint_planner.params import SCHEMA as PLANNER
        plan = PLANNER.yaml_values(os.path.join(CONFIG, 'planner.yaml'),
                                   *_overlay_files(overlays, 'planner'))
        answer = calls.plan_circle(plan, 30.0)
        if answer is None or not answer.accepted:
            raise RuntimeError('the planner did not start the circle: %s (logs in %s)' % (
                'no answer from ~/plan_circle' if answer is None else answer.reason, log_dir))
        last_ns = (n_ticks - 1) * dt_ns
        first_wall = time.monotonic()
        started = False
        last_change = time.monotonic()
        seen = -1
        next_report = time.monotonic() + 1.0
        while collector.progress_ns() < last_ns:
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            ns = collector.progress_ns()
            if ns != seen:
                seen = ns
                last_change = now
                if not started and ns >= 0:
                    started = True
                    first_wall = now
            if now >= next_report and started:
                next_report = now + 1.0
                rtf = ns * 1e-9 / max(now - first_wall, 1e-9)
                progress('  %-10s t = %.3f of %.3f s sim   (%.2fx real time)'
                         % (recorded_as[0] if recorded_as else case, ns * 1e-9,
                            last_ns * 1e-9, rtf))
            if graph.exited():
                raise RuntimeError('%s exited during the run (logs in %s)'
                                   % (graph.exited(), log_dir))
            if now - last_change > STALL_TIMEOUT:
                raise RuntimeError('no new tick for %g s at t = %.3f s (logs in %s)'
                                   % (STALL_TIMEOUT, max(ns, 0) * 1e-9, log_dir))
        wall = time.monotonic() - first_wall
        # The simulator now holds (max_steps): take what is still in flight, and let the
        # recorder take everything before any publisher exits (a sample not yet taken from
        # shared memory dies with its publisher).
        calls.spin_until(lambda: False, 0.2)
        if bag is not None:
            calls.recorder_drained(DRAIN_QUIET, 30.0)
    finally:
        # The recorder last, so that it finalises the bag after every publisher is gone.
        codes = graph.stop_all(order=('controller_node', 'planner_node', 'sim_node',
                                      'recorder'), timeouts={'recorder': 60.0})
    return {'wall_s': wall, 'sim_s': last_ns * 1e-9, 'codes': codes,
            'logs': [p.log_path for p in graph.started], 'bag': bag,
            'sim_log': graph.procs['sim_node'].log_path}


def graph_record(collector, case, seed, n_ticks, passive_joint=PASSIVE_JOINT,
                 variant='robust'):
    """Return the graph's record of the collected run (source 'graph') and its arrays."""
    from freejoint_common.records import arrays_from_messages
    from freejoint_core.metrics import compute_record
    arrays = arrays_from_messages(collector.messages('controller_state'),
                                  collector.messages('joint_states'), passive_joint,
                                  max_ticks=n_ticks)
    got = len(arrays['t'])
    if got != n_ticks:
        raise RuntimeError('only %d of %d ticks have both a ControllerState and a JointState'
                           % (got, n_ticks))
    record = compute_record(case, variant, seed, source='graph', **arrays)
    return record, arrays


def arm_offline(arm, case, seed, n_ticks, normal=None):
    """Return the offline runner's record and trace of a shipped example arm (``ARMS``)."""
    if 'spatial' in arm_info(arm):
        return spatial_offline(arm, seed, n_ticks, normal)
    from freejoint_core.trajectory import CircleQuintic
    from freejoint_core.urdf import four_link_arm, FOUR_LINK_CIRCLE, FOUR_LINK_Q0
    from freejoint_core.urdf_offline import run_arm
    assert arm == 'four_link', arm
    return run_arm(four_link_arm(case), CircleQuintic(**FOUR_LINK_CIRCLE), FOUR_LINK_Q0,
                   label=case, seed=seed, n_ticks=n_ticks)


def spatial_configs(arm):
    """
    Return the simulator's and the controller's configs and the planner's values of ``arm``.

    ``config/<node>.yaml`` with the arm's overlay (``config/<arm>/`` or the directory of
    ``fj arm init``) on top, as the graph's nodes read them (``freejoint_tools.arm_twin``).
    """
    from freejoint_tools.arm_twin import arm_configs
    return arm_configs(os.path.join(CONFIG, arm), CONFIG)


def spatial_ticks(arm):
    """Return the ticks of a spatial arm's run: the planner's circle and the arm's hold."""
    from freejoint_tools.arm_twin import run_ticks
    return run_ticks(os.path.join(CONFIG, arm), CONFIG)


def spatial_offline(arm, seed, n_ticks, normal=None):
    """
    Return the offline twin's record and trace of a spatial arm (``freejoint_tools.arm_twin``).

    Everything is taken from the graph's parameter files (``config/*.yaml`` and
    ``config/<arm>/*.yaml`` or the arm's directory): the real arm and its start posture,
    dt_sub, the disturbance and the free joint's damping (the simulator's), the law built
    as the controller builds it, the circle's radius and duration (the planner's);
    ``normal``: the circle plane's normal given to the planner on the command line
    (``--plane-normal``), else the planner's file's ``plane_normal``.
    """
    from freejoint_tools.arm_twin import twin
    return twin(os.path.join(CONFIG, arm), seed, n_ticks, CONFIG, normal)


def circles_offline(case, seed, settings, overlays=(STABILISED,), arm=None, circles=1,
                    rest=0.0, stabilise=True):
    """
    Return the offline circles runner's records and trace (the stabilised options, or none).

    ``circles`` revolutions with ``rest`` s between them (one by default), the graph's
    settings (``offline_settings``), the options of
    ``freejoint_core.circles.stabilised_options`` (the paper arm, vertical: hanging start,
    the free link's damping with the bound of ``MODULATION``; the 4-link example
    (``arm``): its hanging equilibrium, null-space damping; none with ``stabilise`` false:
    the paper's law and start), the gains those of the graph's controller
    (config/controller.yaml and the ``overlays``' files); the trace gains ``p`` (ticks, 2),
    the end effector [m] as the law measured it. Returns ``(records, trace)``, a record
    per revolution.
    """
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_core.circles import arm_circle, run_circles, stabilised_options
    from freejoint_core.trajectory import RepeatedCircle
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_planner.planning import make_circle
    import numpy as np
    traj = make_circle(PLANNER.yaml_values(os.path.join(CONFIG, 'planner.yaml'),
                                           *_overlay_files(overlays, 'planner')))
    options = stabilised_options(case, arm or 'paper') if stabilise else {}
    expected = options.pop('gains', None)
    gains = CONTROLLER.from_yaml(os.path.join(CONFIG, 'controller.yaml'),
                                 *_overlay_files(overlays, 'controller')).gains
    if expected is not None and (gains.K, gains.Lambda) != (expected.K, expected.Lambda):
        raise SystemExit('demo: K, Lambda %s, %s of the controller overlay are not those of '
                         'the stabilised options, %s, %s' % (gains.K, gains.Lambda, expected.K,
                                                             expected.Lambda))
    runner = run_circles(case, 'robust', seed, circles=circles, rest=rest, arm=arm or 'paper',
                         dt=settings['dt'], dt_sub=settings['dt_sub'],
                         nominal_scale=settings['nominal_scale'],
                         dist_bound=settings['dist_bound'], gains=gains, record_trace=True,
                         **options)
    records, trace = runner
    for t in (0.0, 1.3, 4.9):
        if traj.sample_tuple(t) != arm_circle(arm or 'paper').sample_tuple(t):
            raise SystemExit('demo: --stabilise compares with the circles runner, which runs '
                             "the arm's own circle: the planner's files plan another")
    series = RepeatedCircle(traj, circles, rest, settings['dt'])
    des = np.array([series.sample(t)[0] for t in trace['t']])
    trace['p'] = trace['e'] + des
    return records, trace


def per_circle(arrays, n_circle, n_rest, circles):
    """
    Return the graph's tracking error per revolution: ``[(rms_mm, max_mm), ...]``.

    As the offline circles runner counts it: over each revolution's ``n_circle`` ticks, not
    its rest (``arrays``: ``graph_record``'s, ``p`` and ``p_d`` per tick).
    """
    import numpy as np
    err = 1e3 * np.hypot(*(arrays['p'] - arrays['p_d']).T)
    out = []
    for c in range(circles):
        e = err[c * (n_circle + n_rest):c * (n_circle + n_rest) + n_circle]
        out.append((float(np.sqrt(np.mean(e * e))), float(e.max())))
    return out


def failure_comparison(collector, case, seed, fail, n_ticks, dt_ns, logs, effort=True,
                       free_link_damping=None):
    """
    Compare a lockstep run whose joint failed with the offline failure runner's.

    Parameters
    ----------
    collector : Collector
        The run's messages (``controller_state``, ``joint_states``).
    case, seed, fail : str, int, str
        As the run (``fail``: ``joint3@2.5``, ``failure_offline.parse_fail``).
    n_ticks, dt_ns : int
        The run's ticks and control period [ns].
    logs : list of str
        The run's node logs (the controller's and the planner's lines are read).
    effort : bool
        The controller compared its commands with joint_states' effort.
    free_link_damping : dict, optional
        The offline runner's option of the same name (the controller's
        config/fully_actuated/free_link_damping.yaml).

    Returns
    -------
    dict
        ``ticks`` (collected), ``d_cmd`` [N m], ``d_q`` [rad] (largest differences),
        ``max_mm`` (the graph's tracking error), ``found`` (the controller's detection
        lines), ``planner`` (the planner's lines on a failure), ``offline`` (the runner's
        record).

    """
    import re
    from freejoint_common.records import arrays_from_messages
    from freejoint_core.failure_offline import parse_fail, run_failure_case
    from freejoint_tools.analyze import DETECTED, joint_positions
    import numpy as np
    failing = parse_fail(fail)
    joint_states = collector.messages('joint_states')
    try:
        arrays = arrays_from_messages(collector.messages('controller_state'), joint_states,
                                      'joint%d' % (failing[0][0] + 1), max_ticks=n_ticks)
    except ValueError as exc:
        raise RuntimeError('no tick collected (another graph in ROS domain %s?): %s'
                           % (os.environ.get('ROS_DOMAIN_ID'), exc)) from None
    ticks = np.rint(arrays['t'] * 1e9 / dt_ns).astype(int)
    q = np.column_stack(list(joint_positions(joint_states, arrays['t']).values()))
    rec, trace = run_failure_case(case, seed, failing, duration=n_ticks * dt_ns * 1e-9,
                                  record_trace=True, effort=effort,
                                  free_link_damping=free_link_damping)

    def log_text(who):
        with open([p for p in logs if who in os.path.basename(p)][0]) as fh:
            return fh.read()
    return {'ticks': len(ticks),
            'd_cmd': float(np.max(np.abs(arrays['tau'] - trace['tau'][ticks]))),
            'd_q': float(np.max(np.abs(q - trace['q'][ticks]))),
            'max_mm': float(np.max(np.hypot(*(arrays['p'] - arrays['p_d']).T))) * 1e3,
            'found': [DETECTED.search(line).group(0)
                      for line in log_text('controller').splitlines()
                      if 'joint failure: ' in line and DETECTED.search(line)],
            'planner': re.findall(r'(joint\d (?:reported )?failed[:( ][^\n]*)',
                                  log_text('planner')),
            'offline': rec}


# -- main -------------------------------------------------------------------------------
def _parse(argv):
    ap = argparse.ArgumentParser(prog='demo', description=__doc__.split('\n')[1])
    ap.add_argument('--cases', nargs='+', choices=CASES, default=list(CASES))
    ap.add_argument('--seed', type=int, default=0, help='disturbance seed (default 0)')
    ap.add_argument('--out', default=os.path.join(ROOT, 'bags', 'demo'),
                    help='output directory (default bags/demo)')
    ap.add_argument('--no-record', action='store_true', help='do not start the recorder')
    ap.add_argument('--arm', metavar='ARM',
                    help='run a shipped example arm instead of the paper cases (%s; make '
                    'demo ARM=four_link), the directory fj arm init wrote (make demo '
                    'ARM=DIR), or a URDF with --passive (fj arm init into OUT/<name>/arm '
                    'first)' % ', '.join(sorted(ARMS)))
    ap.add_argument('--passive', action='append', metavar='JOINT',
                    help='with --arm FILE.urdf: its free joint (fj arm init --passive)')
    ap.add_argument('--tip', help='with --arm FILE.urdf: the tip link (fj arm init --tip)')
    ap.add_argument('--base', help='with --arm FILE.urdf: the base link (fj arm init --base)')
    ap.add_argument('--stabilise', action='store_true',
                    help='the internal-motion stabilisation (vertical: config/stabilised/, the '
                    'free link starts hanging, its damping on; horizontal: '
                    'config/stabilised_horizontal/, the free link slowed in the rests; with '
                    '--arm four_link config/four_link/stabilised/, vertical), beside the '
                    'offline circles runner with the same options')
    ap.add_argument('--fail', metavar='JOINT@T',
                    help='the fully actuated arm whose joint fails at T s, e.g. joint3@2.5 '
                    "(config/fully_actuated/, the simulator's fail_joint; make demo "
                    'FAIL=joint3@2.5), beside the offline failure runner')
    ap.add_argument('--circles', type=int, default=1, metavar='N',
                    help="N revolutions back to back (the planner's circles; make demo "
                    'CIRCLES=N), beside the offline circles runner, reported per revolution')
    ap.add_argument('--rest', type=float, default=0.0, metavar='S',
                    help="rest (s) between the revolutions (the planner's rest; make demo "
                    'REST=S)')
    ap.add_argument('--plane-normal', type=float, nargs=3, metavar=('X', 'Y', 'Z'),
                    help="a spatial arm's circle in the plane of this normal (base frame; "
                    "the planner's plane_normal; make demo ARM=ur5 PLANE='0 0 1')")
    ap.add_argument('--view', action='store_true',
                    help='also start the viewer (Foxglove WebSocket on ws://127.0.0.1:8765, '
                    'layout config/foxglove_layout.json, with --arm ur5 / panda '
                    'config/foxglove_layout_<arm>.json; make demo VIEW=1)')
    return ap.parse_args(argv)


def main(argv=None):
    """Run the demo; return the exit code."""
    args = _parse(sys.argv[1:] if argv is None else argv)
    t_start = time.monotonic()
    overlays = ()
    if args.arm and args.arm.endswith('.urdf'):
        if not args.passive:
            say('error: --arm %s: a URDF needs --passive JOINT (make demo ARM=... PASSIVE=...)'
                % args.arm)
            return 2
        from freejoint_core.errors import FreejointValueError
        from freejoint_tools.arm_twin import from_urdf
        try:    # its files, then its bag, in args.out/<name>
            arm_dir = from_urdf(args.arm, args.passive, args.out, args.tip, args.base,
                                log=lambda line: say('fj arm init: ' + line))
        except FreejointValueError as exc:
            say('error: fj arm init %s: %s' % (args.arm, exc))
            return 2
        say('fj arm init: wrote %s' % shown(arm_dir))
        args.arm = arm_dir
    elif args.passive or args.tip or args.base:
        say('error: --passive, --tip and --base go with --arm FILE.urdf')
        return 2
    if args.arm:
        # The 4-link example alone is the horizontal case: with the free base pivot under
        # gravity the paper's law does not stabilise it (offline: diverges within 0.2 s). A
        # spatial arm has its own gravity (-z of its base); its case is not read.
        if 'spatial' in arm_info(args.arm) and (args.stabilise or args.fail):
            say('error: --arm %s runs the spatial example alone (not with --stabilise or '
                '--fail)' % args.arm)
            return 2
        if args.arm not in ARMS:
            args.arm = os.path.abspath(args.arm)
        args.cases = ['horizontal']
        args.out = os.path.join(args.out, os.path.basename(args.arm.rstrip(os.sep)))
        overlays = (args.arm,)
    per_case = {}
    if args.stabilise:
        # The paper's arm: each case its overlay (circles.stabilised_options: vertical the
        # hanging start and the damping, horizontal the settle in the rests); the 4-link
        # example its own overlay, vertical.
        if args.arm:
            args.cases = ['vertical']
        args.out = os.path.join(args.out, STABILISED)
        if not args.arm:
            per_case = {'horizontal': overlays + (STABILISED_HORIZONTAL,)}
        overlays += (os.path.join(args.arm, STABILISED) if args.arm else STABILISED,)
    node_args = None
    if args.plane_normal is not None:
        if not (args.arm and 'spatial' in arm_info(args.arm)):
            say('error: --plane-normal turns the circle of a spatial arm (--arm ur5, panda)')
            return 2
        node_args = {'planner': ['plane_normal:=[%s]' % ', '.join(
            repr(v) for v in args.plane_normal)]}
    series = args.circles != 1 or args.rest != 0.0
    if series:
        if args.arm or args.fail or args.circles < 1 or args.rest < 0.0:
            say("error: --circles N (>= 1) and --rest S (>= 0) run the paper's arm (with or "
                'without --stabilise), not with --arm or --fail')
            return 2
        args.out = os.path.join(args.out, 'circles')
        node_args = {'planner': ['circles:=%d' % args.circles, 'rest:=%r' % args.rest]}
    if args.fail:
        if args.arm or args.stabilise:
            say("error: --fail runs the paper's arm fully actuated: not with --arm or "
                '--stabilise')
            return 2
        from freejoint_core.errors import FreejointValueError
        from freejoint_core.failure_offline import parse_fail
        try:
            failing = parse_fail(args.fail)
        except FreejointValueError as exc:
            say('error: --fail %s' % exc)
            return 2
        args.out = os.path.join(args.out, 'failure')
        overlays = (FULLY_ACTUATED,)
        node_args = {'sim': ['fail_joint:=' + args.fail]}
    if not os.environ.get('ROS_DOMAIN_ID'):
        from freejoint_tools.harness import claim_ros_domain
        os.environ['ROS_DOMAIN_ID'] = str(claim_ros_domain(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')
    missing = [exe for exe in (executable('freejoint_sim', 'sim_node'),
                               executable('freejoint_control', 'controller_node'),
                               executable('freejoint_planner', 'planner_node'))
               if not os.path.exists(exe)]
    if missing:
        say('error: not built: %s (run tools/setup.sh)' % ', '.join(missing))
        return 1
    from freejoint_core.metrics import format_table, write_records
    from freejoint_core.offline import run_case
    import numpy as np
    import rclpy
    from freejoint_tools.harness import Processes
    from rclpy.experimental import EventsExecutor

    settings = offline_settings()
    passive_joint = arm_info(args.arm)['passive_joint'] if args.arm else (
        'joint%d' % (failing[0][0] + 1) if args.fail else PASSIVE_JOINT)
    dt_ns = round(settings['dt'] * 1e9)
    n_circle = int(round(settings['duration'] / settings['dt']))
    n_rest = int(round(args.rest / settings['dt']))
    if series and abs(n_rest * settings['dt'] - args.rest) > 1e-9:
        say('error: --rest %g s is not a whole number of control periods (%g s)'
            % (args.rest, settings['dt']))
        return 2
    n_ticks = args.circles * n_circle + (args.circles - 1) * n_rest
    spatial = args.arm and 'spatial' in arm_info(args.arm)
    if spatial:         # the circle, then the hold (the planner's duration is 5 s as the paper's)
        n_ticks += int(round(arm_info(args.arm)['hold_s'] / settings['dt']))
    out = os.path.abspath(args.out)
    log_dir = os.path.join(out, 'logs')
    os.makedirs(out, exist_ok=True)
    recorder = executable('freejoint_tools', 'recorder')
    analyze = executable('freejoint_tools', 'analyze')
    say('ROS_DOMAIN_ID=%s, discovery %s; %d ticks of %g s per case, seed %d' % (
        os.environ['ROS_DOMAIN_ID'], os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'], n_ticks,
        settings['dt'], args.seed))
    record_bags = not args.no_record and os.path.exists(recorder)
    if not args.no_record and not record_bags:
        say('recorder not installed yet (%s): running without bags' % recorder)

    rclpy.init()
    node = rclpy.create_node('freejoint_demo')
    collector = None
    executor = EventsExecutor()
    executor.add_node(node)
    graph_records, offline_records, runs = [], [], []
    failed = False
    view = Processes(log_dir, 'view', cwd=ROOT)
    try:
        if args.view:
            proc = view.start('viewer', [executable('freejoint_tools', 'viewer')])
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline and proc.poll() is None and \
                    'viewer ready' not in open(proc.log_path).read():
                time.sleep(0.1)
            say('viewer: %s' % view.tail(proc, 1).split(']: ')[-1].strip())
        for i, case in enumerate(args.cases):
            label = arm_info(args.arm)['spatial'] if spatial else case
            who = 'recorder, ' if record_bags else ''
            say('case %d/%d: %s - starting %ssim_node, controller_node, planner_node '
                '(lockstep, %s, seed %d)' % (i + 1, len(args.cases), label, who,
                                             'spatial' if spatial else 'robust', args.seed))
            if collector is not None:
                collector.close()
            collector = Collector(node)
            try:
                run = run_graph(case, args.seed, n_ticks, dt_ns, collector, executor, out,
                                log_dir, record=record_bags,
                                overlays=per_case.get(case, overlays),
                                passive_joint=passive_joint, node_args=node_args,
                                recorded_as=(arm_info(args.arm)['spatial'], 'spatial')
                                if spatial else None)
            except RuntimeError as exc:
                say('error: %s: %s' % (label, exc))
                failed = True
                break
            bad = {name: code for name, code in run['codes'].items() if code != 0}
            say('  %s: %.3f s simulated in %.2f s wall (%.2fx real time); stopped cleanly%s'
                % (label, run['sim_s'], run['wall_s'], run['sim_s'] / run['wall_s'],
                   '' if not bad else ' EXCEPT %s' % bad))
            with open(run['sim_log']) as f:
                stop_line = [line for line in f if 'simulator stopped' in line]
            if stop_line:
                say('  ' + stop_line[-1].split(']: ')[-1].strip())
            try:
                record, arrays = graph_record(
                    collector, arm_info(args.arm)['spatial'] if spatial else case, args.seed,
                    n_ticks, passive_joint, 'spatial' if spatial else 'robust')
            except (RuntimeError, ValueError) as exc:
                say('error: %s: %s' % (label, exc))
                failed = True
                break
            if args.fail:
                cmp = failure_comparison(collector, case, args.seed, args.fail, n_ticks,
                                         dt_ns, run['logs'])
                off = cmp['offline']
                bound = FAILURE_BOUND_MM[case]
                say('  controller: %s' % ('; '.join(cmp['found']) or 'NO DETECTION'))
                say('  planner: %s' % ('; '.join(cmp['planner']) or 'no line on a failure'))
                say('  offline failure runner: detected at %s s by %s, max %.4f mm'
                    % (off['detected_at_s'], off['detected_by'], off['max_mm']))
                say('  graph: max tracking error %.4f mm (bound %g mm)%s' % (
                    cmp['max_mm'], bound, '' if cmp['max_mm'] <= bound else '  NOT MET'))
                verdict = '' if max(cmp['d_cmd'], cmp['d_q']) <= 1e-9 and \
                    cmp['ticks'] == n_ticks else '  (NOT within 1e-9)'
                say('  graph vs offline runner over %d of %d ticks: max |command difference| '
                    '%.3g N m, max |q difference| %.3g rad%s' % (
                        cmp['ticks'], n_ticks, cmp['d_cmd'], cmp['d_q'], verdict))
                failed = failed or bool(verdict) or not cmp['found'] or \
                    cmp['max_mm'] > bound
                graph_records.append(record)
                runs.append(run)
                continue
            if args.stabilise or series:
                offs, trace = circles_offline(case, args.seed, settings,
                                              per_case.get(case, overlays), args.arm,
                                              args.circles, args.rest, args.stabilise)
                graph_circles = per_circle(arrays, n_circle, n_rest, args.circles)
                for c, off in enumerate(offs):
                    swing = '' if off['swing_deg'] is None else \
                        ', swing at its end %.3f deg' % off['swing_deg']
                    say('  revolution %d: offline circles runner (%s): rms %.4f mm, max '
                        '%.4f mm, peak effort %s N m%s; graph: rms %.4f mm, max %.4f mm'
                        % (c + 1, off['variant'], off['rms_mm'], off['max_mm'],
                           ' / '.join('%.1f' % v for v in off['effort_peak']), swing,
                           *graph_circles[c]))
                off = offs[-1]
                if len(offs) < args.circles:
                    say('  offline circles runner: diverged at %s s' % off['diverged_at_s'])
                say('  graph: rms %.4f mm, max %.4f mm' % (record['rms_mm'], record['max_mm']))
            elif args.arm:
                off, trace = arm_offline(args.arm, case, args.seed, n_ticks,
                                         args.plane_normal)
                bound = arm_info(args.arm)['bound_mm']
                if spatial:
                    outside = off['active_outside_limits'] + off['free_outside_limits']
                    say('  offline twin: max %.3f mm (last second of the hold %.3f mm), '
                        "peak |effort| %.2f of the URDF's limits, active joint speeds %.2f "
                        'of them, the free joint %.2f; joints %s%s' % (
                            off['max_mm'], off['hold_last_s_max_mm'], off['tau_ratio'],
                            off['vel_ratio'], off['vel_ratio_free'],
                            'within their position limits' if not outside
                            else 'OUTSIDE their limits: %s' % outside,
                            '' if off['diverged_at_s'] is None else
                            ', DIVERGED at %.3f s' % off['diverged_at_s']))
                    failed = failed or off['diverged_at_s'] is not None or \
                        off['tau_ratio'] > 1.0 or off['vel_ratio'] > 1.0 or \
                        off['vel_ratio_free'] > 1.0 or bool(outside)
                say('  %s example, %s: max tracking error %.3f mm (stated bound %g mm)%s'
                    % (args.arm, arm_info(args.arm).get('spatial', case), record['max_mm'], bound,
                       '' if record['max_mm'] <= bound else '  NOT MET'))
                failed = failed or record['max_mm'] > bound
            else:
                off, trace = run_case(case, 'robust', args.seed, record_trace=True,
                                      **settings)
            ee = ee_trajectory(collector.messages('ee_position'), dt_ns, n_ticks,
                               3 if spatial else 2)
            dev = float(np.max(np.abs(ee - trace['p'])))
            verdict = '' if dev <= 1e-9 else '  (NOT within 1e-9 m)'
            say('  end-effector trajectory, graph vs offline runner: max |difference| = '
                '%.3g m over %d ticks%s' % (dev, n_ticks, verdict))
            failed = failed or dev > 1e-9
            graph_records.append(record)
            if not (args.stabilise or series):     # circles records: another table
                offline_records.append(off)
            runs.append(run)
    finally:
        view.stop_all()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    if graph_records:
        metrics = os.path.join(out, 'metrics.json')
        write_records(metrics, graph_records)
        rows = [r for pair in zip(offline_records, graph_records) for r in pair] \
            if offline_records else graph_records
        print()
        print(format_table(rows, titles=spatial_titles(passive_joint) if spatial else None))
        print()
    if not failed and os.path.exists(analyze) and record_bags:
        bags = [run['bag'] for run in runs]
        say('analyze %s' % ' '.join(shown(b) for b in bags))
        figures = FIGURES if not overlays else os.path.join(out, 'figures')
        code = subprocess.call([analyze, *bags, '--figures-dir', figures], cwd=ROOT)
        if code != 0:
            say('analyze exited with %d' % code)
            failed = True
    elif record_bags and not os.path.exists(analyze):
        say('analyze not installed yet (%s): no bag analysis' % analyze)
    say('outputs:')
    if graph_records:
        say('  %s  graph records (source "graph")' % shown(metrics))
    for run in runs:
        if run['bag']:
            say('  %s/  bag of the %s run' % (shown(run['bag']),
                                              os.path.basename(run['bag'])))
    say('  %s/  node logs' % shown(log_dir))
    say('wall time %.1f s%s' % (time.monotonic() - t_start, ' - FAILED' if failed else ''))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
