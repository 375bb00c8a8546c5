"""
Offline analysis of recorded runs: metrics records and the paper's figures from bags.

Usage::

    analyze BAG [BAG ...] [--figures-dir DIR] [--no-plots] [--passive-joint NAME]
            [--max-ticks N] [--state-topic T] [--joint-topic T] [--theta]
    python -m freejoint_tools.analyze ...        (what ``make analyze BAGS=...`` runs)

For each bag the per-tick arrays are computed from the recorded ``ControllerState`` and
``JointState`` messages only - decoded with the message definitions stored in the bag -
by ``freejoint_common.records.arrays_from_messages``, the same conversion the demo applies
to the messages it receives live, and turned into a record by
``freejoint_core.metrics.compute_record`` with ``source: 'bag'``. The record is written
beside the bag's files as ``<bag>/metrics.json`` and all records are printed as the
offline runner's table.

Run information comes from the bag's ``custom_data`` (the recorder's ``custom_data``
parameter: ``case``, ``variant``, ``seed``, and optionally ``passive_joint``,
``max_ticks``, ``diverged_at_s``, ``nominal_scale``); without it the case is taken from the
bag's directory name if that is a case name, the variant is ``'unknown'`` and the seed
None (a warning says so). Command-line options override the bag.

The arm is read from the bag too (:func:`bag_arm`), so a bag of any arm is analysed without
options: its passive joints are the joints of ``joint_states`` that the controller does not
command (``ControllerState.joint_names`` are the active ones), the first of them the one
plotted unless ``passive_joint`` is given; its model is the recorded
``/robot_description`` (the simulator publishes the URDF it runs, latched), parsed with
those passive joints, else the paper's Table I arm (joints ``joint1..3``).

Time: a lockstep run's stamps are sim time (from 0 at its start) and stay as they are; a
real-time run's are system time (Unix time), and its figures count from its first tick
(``time_origin``; the trace keeps the origin as ``t0``).

Figures (PNG): per bag ``fig3_<bag>.png`` (Case 1, horizontal) or ``fig4_<bag>.png``
(Case 2, vertical) - the paper's Figs. 3/4: desired and actual path in the x-y plane,
tracking errors, active torques, passive joint angle, theta-hat over time; once
``fig2_singularity.png`` - the paper's Fig. 2, recomputed with ``freejoint_core.singularity``
from the nominal parameters, with the recorded planner map (OccupancyGrid) and planned path
(Marker) of the first bag overlaid when they are recorded; with several bags
``compare.png`` side by side. Per-bag figures go into the bag directory, the others into
the bags' common parent directory, unless ``--figures-dir`` names one directory for all.

Joint failures: a joint the simulator made fail (its ``/diagnostics`` key
``failed joints``, e.g. ``joint3 at 2.500 s``) and the controller's detection (the first
``ControllerState.message`` ``joint3 failed at t = 2.507 s (detected by effort) ...``) are
read from the bag (:func:`failures_of`); per failure one line says when it failed, when and
how it was detected, the delay and the largest tracking error after it, and Figs. 3/4 mark
both times.

Against the plan: the table's figures are the error against the controller's own
reference (``ControllerState.position_desired``: held, blended or carried forward). Per bag
one line ``plan: <bag>: ...`` gives the arm against the plan
(``freejoint_core.plan_figures.plan_figures`` of ``freejoint_tools.plan_bag``: the recorded
``ee_position`` against the ``setpoints`` interpolated at each state stamp): rms / max, the
share of the plan's moving ticks within the bound (``--bound-mm``, default the paper's
case's ``tracking_bound_mm``; none for another arm), the time held or braked while the plan
moved, the plans completed and how late. A bag without ``ee_position`` or ``setpoints``
gives a warning instead.

Plans: every outcome the planner published on ``plan_outcome`` (recorded by the recorder
with the graph's topics) is printed, one line each: ``outcome: <bag>: plan N SUCCEEDED
(elapsed .. s, late .. s, n pause(s) .. s, max path error .. mm)``, or the code and why
(docs/feed_hold.md); a bag recorded before the topic existed has none. Then the verdict,
``verdict: <bag>: met (...)``, ``met by the outcomes (...)`` (each plan off the bound
paused or was aborted for a controller not ready, the arm within the bound of its path:
``plan_figures.outcome_excuses``) or ``NOT met (...)`` and why; none without a bound.

Bad input (a missing, truncated or foreign bag, a bag without the run's topics) gives one
line ``analyze: error: <file>: <problem>`` on stderr and exit code 1. A bag whose recorder
was killed (not finalised) is analysed up to its last complete chunk, with a warning.
"""

import argparse
import os
import re
import sys

from freejoint_common.contract import CONTROLLER_STATE, DIAGNOSTICS, JOINT_STATES
from freejoint_common.contract import PLAN_OUTCOME, ROBOT_DESCRIPTION
from freejoint_common.contract import seconds_to_ns, to_ns
from freejoint_common.outcome import outcome_line

from .bagfile import BagError, open_bag, SYSTEM_TIME_NS

STATE_TYPE = CONTROLLER_STATE.type_name
JOINT_TYPE = JOINT_STATES.type_name
GRID_TYPE = 'nav_msgs/msg/OccupancyGrid'
MARKER_TYPE = 'visualization_msgs/msg/Marker'
DEFAULT_PASSIVE = 'joint3'
DESCRIPTION_TYPE = ROBOT_DESCRIPTION.type_name
FAILED_KEY = 'failed joints'
"""The simulator's ``/diagnostics`` key naming the joints it made fail and when."""
_INJECTED = re.compile(r'(\S+) at ([0-9.]+) s')
DETECTED = re.compile(r'(\S+) failed at t = ([0-9.]+) s \(detected by (\w+)\)')
"""The controller's detection in its status message and log (``freejoint_control.failures``):
groups joint, time [s], how."""


class AnalysisError(Exception):
    """Bad input for the analysis; ``str()`` is one line naming the file."""


def _pick_topic(bag, msgtype, preferred, given):
    if given:
        if given not in bag.topics:
            raise AnalysisError('%s: no topic %s in the bag' % (bag.path, given))
        return given
    names = bag.topics_of_type(msgtype)
    names = [n for n in names if bag.topics[n].count] or names
    if preferred in names:
        return preferred
    if len(names) == 1:
        return names[0]
    if not names:
        raise AnalysisError('%s: no %s topic in the bag (topics: %s)' % (
            bag.path, msgtype, ', '.join(sorted(bag.topics)) or 'none'))
    raise AnalysisError('%s: several %s topics (%s); choose one with an option'
                        % (bag.path, msgtype, ', '.join(names)))


def run_info(bag, overrides=None):
    """
    Return ``(info dict, warnings)`` of a bag: case, variant, seed, passive_joint, ...

    From the bag's custom_data, then the command-line ``overrides`` (non-None values).
    """
    from freejoint_core.arm import CASES
    data = dict(bag.custom_data)
    warnings = []
    info = {'case': data.get('case'), 'variant': data.get('variant'),
            'seed': data.get('seed'), 'passive_joint': data.get('passive_joint'),
            'max_ticks': data.get('max_ticks'), 'diverged_at_s': data.get('diverged_at_s'),
            'nominal_scale': data.get('nominal_scale')}
    for key, value in (overrides or {}).items():
        if value is not None:
            info[key] = value
    name = os.path.basename(os.path.normpath(bag.path))
    if not info['case']:
        if name in CASES:
            info['case'] = name
            warnings.append('%s: no run information in the bag; case %r taken from its '
                            'name' % (bag.path, name))
        else:
            info['case'] = 'unknown'
            warnings.append('%s: no run information in the bag (case unknown)' % bag.path)
    if not info['variant']:
        info['variant'] = 'unknown'
    info['passive_joint'] = info['passive_joint'] or None     # else from the messages

    def number(key, kind):
        value = info[key]
        if value in (None, '', 'None', 'none', 'null'):
            info[key] = None
            return
        try:
            info[key] = kind(value)
        except (TypeError, ValueError):
            raise AnalysisError('%s: run information %s=%r is not a number'
                                % (bag.path, key, value))
    number('seed', int)
    number('max_ticks', int)
    number('diverged_at_s', float)
    number('nominal_scale', float)
    return info, warnings


def analyse_bag(path, overrides=None, state_topic=None, joint_topic=None):
    """
    Compute the record of one bag.

    Returns
    -------
    tuple
        ``(record, trace, warnings)``: the metrics record (``source: 'bag'``), a dict of
        per-tick arrays for the plots (the ``compute_record`` arrays plus ``name``,
        ``info``, the recorded ``grid`` and ``path`` if any), and warning lines.

    Raises
    ------
    BagError, AnalysisError
        With a one-line message naming the file.

    """
    from freejoint_common.records import arrays_from_messages
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.metrics import compute_record
    bag = open_bag(path)
    warnings = list(bag.notes)
    info, more = run_info(bag, overrides)
    warnings += more
    states_topic = _pick_topic(bag, STATE_TYPE, CONTROLLER_STATE.absolute, state_topic)
    joints_topic = _pick_topic(bag, JOINT_TYPE, JOINT_STATES.absolute, joint_topic)
    store = bag.typestore()
    diag = [DIAGNOSTICS.absolute] if DIAGNOSTICS.absolute in bag.topics else []
    decoded = bag.decode_topics([states_topic, joints_topic] + diag, store)
    states = [m for _, m in decoded[states_topic]]
    joints = [m for _, m in decoded[joints_topic]]
    arm = bag_arm(bag, store, states, joints, info)
    if not info['passive_joint']:
        info['passive_joint'] = arm['passive'][0] if arm['passive'] else DEFAULT_PASSIVE
    warnings += arm['notes']
    try:
        arrays = arrays_from_messages(states, joints, info['passive_joint'],
                                      max_ticks=info['max_ticks'])
        record = compute_record(info['case'], info['variant'], info['seed'],
                                diverged_at_s=info['diverged_at_s'], source='bag', **arrays)
    except (ValueError, FreejointValueError) as exc:
        raise AnalysisError('%s: %s (topics %s, %s)'
                            % (bag.path, exc, states_topic, joints_topic))
    if info['max_ticks'] is not None and len(arrays['t']) < info['max_ticks']:
        warnings.append('%s: holds %d ticks, fewer than max_ticks = %d (run cut short?)'
                        % (bag.path, len(arrays['t']), info['max_ticks']))
    trace = dict(arrays)
    trace['name'] = os.path.basename(os.path.normpath(bag.path))
    trace['info'] = info
    trace['finalised'] = bag.finalised
    trace['joints'] = joint_positions(joints, arrays['t'])
    trace['arm'] = arm
    trace['t0'] = time_origin(arrays['t'])
    trace['t'] = arrays['t'] - trace['t0']
    trace['failures'] = failures_of(states, [m for topic in diag for _, m in decoded[topic]])
    trace['plan'] = plan_of(bag, store, info, arm, warnings)
    trace['grid'] = trace['path'] = None
    grids = bag.topics_of_type(GRID_TYPE)
    if grids and bag.topics[grids[0]].count:
        trace['grid'] = bag.decode(grids[0], store)[-1][1]
    markers = bag.topics_of_type(MARKER_TYPE)
    if markers and bag.topics[markers[0]].count:
        trace['path'] = bag.decode(markers[0], store)[-1][1]
    outcome = PLAN_OUTCOME.absolute
    trace['outcomes'] = [m for _, m in bag.decode(outcome, store)] \
        if outcome in bag.topics and bag.topics[outcome].count else []
    return record, trace, warnings


def verdict_line(trace):
    """
    Return the run's verdict against the plan (``plan_met``), '' without a share.

    ``met``: 99 % of the plan's moving ticks within the bound; ``met by the outcomes``:
    each plan off the bound paused or was aborted for a controller not ready, the arm
    within the bound of its path (``outcome_excuses``); else ``NOT met`` and why.
    """
    from freejoint_core.plan_figures import outcome_excuses, plan_met
    figures = trace.get('plan')
    if not figures or figures.get('share') is None:
        return ''
    outcomes = {int(m.plan_id): (m.code_name, int(m.pauses)) for m in trace['outcomes']
                if int(m.plan_id) > 0}
    share = '%.1f %% of the moving ticks within %.3f mm' % (
        100.0 * figures['share'], figures['bound_mm'])
    if plan_met(figures):
        return 'met (%s)' % share
    excused, why = outcome_excuses(figures, outcomes)
    if plan_met(figures, outcome_excuses=excused):
        return 'met by the outcomes (%s): %s' % (share, why)
    return 'NOT met (%s): %s' % (share, why)


def plan_of(bag, store, info, arm, warnings):
    """
    Return the bag's figures against the plan (``plan_figures``), or None with a warning.

    The bound: ``info['bound_mm']`` if given, else the paper's case's ``tracking_bound_mm``
    for the Table I arm, else none (no share).
    """
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.plan_figures import plan_figures, tracking_bound_mm
    from .plan_bag import plan_arrays
    bound = info.get('bound_mm')
    if bound is None and arm['name'] == 'Table I' and info['case'] in ('horizontal',
                                                                       'vertical'):
        bound = tracking_bound_mm(info['case'])[0]
    try:
        arrays, origin = plan_arrays(bag, store)
        figures = plan_figures(bound_mm=bound, **arrays)
    except (ValueError, FreejointValueError) as exc:
        warnings.append('%s: no figures against the plan: %s' % (bag.path, exc))
        return None
    figures['origin_ns'] = origin
    return figures


def failures_of(states, diagnostics=()):
    """
    Return the joint failures of a run: when each failed and when it was detected.

    Parameters
    ----------
    states : sequence of ControllerState
        Its ``message`` names a detection (``joint3 failed at t = 2.507 s (detected by
        effort) ...``, the first one per joint taken).
    diagnostics : sequence of DiagnosticArray
        The simulator's key ``failed joints`` (``joint3 at 2.500 s[, ...]``).

    Returns
    -------
    list of dict
        ``joint``, ``failed_s`` (None: not recorded), ``detected_s`` (None: not detected),
        ``by`` (``residual`` | ``effort`` | ``notice`` | None), ordered by time.

    """
    found = {}
    for array in diagnostics:
        for status in array.status:
            for kv in status.values:
                if kv.key == FAILED_KEY:
                    for joint, at in _INJECTED.findall(kv.value):
                        found.setdefault(joint, {'joint': joint, 'failed_s': float(at),
                                                 'detected_s': None, 'by': None})
    seen = set()
    last = None
    for msg in states:
        text = msg.message
        if text == last or 'failed at t = ' not in text:
            continue
        last = text
        for joint, at, by in DETECTED.findall(text):
            if joint not in seen:
                seen.add(joint)
                entry = found.setdefault(joint, {'joint': joint, 'failed_s': None})
                entry.update(detected_s=float(at), by=by)
    return sorted(found.values(), key=lambda f: min(
        t for t in (f['failed_s'], f['detected_s'], float('inf')) if t is not None))


def failure_lines(name, failures, t, error_m):
    """
    Return one line per failure: when, detected when and how, the error after it.

    Parameters
    ----------
    name : str
        The bag's name.
    failures : list of dict
        :func:`failures_of`.
    t : ndarray, (N,)
        Tick times [s] on the stamps' time base.
    error_m : ndarray, (N,)
        Tracking error norm [m] per tick.

    """
    out = []
    for f in failures:
        failed, detected = f['failed_s'], f['detected_s']
        text = '%s: %s failed at %s' % (name, f['joint'], '(not recorded)' if failed is None
                                        else '%.3f s' % failed)
        if detected is None:
            text += ', not detected'
        else:
            text += ', detected at %.3f s by %s' % (detected, f['by'])
            if failed is not None:
                text += ' (delay %.0f ms)' % ((detected - failed) * 1e3)
        start = failed if failed is not None else detected
        after = error_m[t >= start - 1e-9] if len(t) else error_m[:0]
        if len(after):
            text += '; max tracking error after it %.4f mm' % (float(after.max()) * 1e3)
        out.append(text)
    return out


def passive_from_messages(states, joint_states):
    """
    Return the passive joints of a run: joint states' joints the controller does not command.

    Parameters
    ----------
    states : iterable of ControllerState
        Their ``joint_names`` are the active joints (the first non-empty list counts).
    joint_states : iterable of JointState
        Their ``name`` lists every joint, base to tip (the first non-empty one counts).

    Returns
    -------
    tuple of (list of str, list of str)
        ``(all joints, passive joints)`` in the joint states' order; empty if either
        list is missing.

    """
    active = next((list(m.joint_names) for m in states if len(m.joint_names)), None)
    names = next((list(m.name) for m in joint_states if len(m.name)), None)
    if not active or not names:
        return names or [], []
    return names, [n for n in names if n not in active]


def bag_arm(bag, store, states, joint_states, info):
    """
    Return the arm of a bag: its joints, passive joints and model (see the module notes).

    Returns
    -------
    dict
        ``joints`` (all, base to tip), ``passive`` (names), ``params`` (ArmParams of the
        real arm: the recorded ``/robot_description``, else Table I of the case; None for
        a spatial arm, whose ControllerState positions have 3 values),
        ``name`` (the URDF's robot name, or 'Table I'), ``source`` (where it came from),
        ``notes`` (warnings).

    """
    from freejoint_core.arm import table1
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.urdf import parse_urdf
    names, passive = passive_from_messages(states, joint_states)
    if info.get('passive_joint'):
        passive = [info['passive_joint']] + [p for p in passive if p != info['passive_joint']]
    case = info['case'] if info['case'] in ('horizontal', 'vertical') else 'horizontal'
    notes = []
    texts = [t for t in bag.topics_of_type(DESCRIPTION_TYPE)
             if t == ROBOT_DESCRIPTION.absolute and bag.topics[t].count]
    if texts:
        text = bag.decode(texts[0], store)[-1][1].data
        try:
            urdf = parse_urdf(text, passive)
            # the shipped paper_arm.urdf is the Table I arm (gravity aside: not in the map)
            paper = urdf.params == table1('horizontal')
            return {'joints': list(urdf.joint_names), 'passive': list(urdf.passive_joints),
                    'params': table1(case) if paper else urdf.params,
                    'name': 'Table I' if paper else urdf.name or 'URDF arm',
                    'source': 'the recorded %s' % ROBOT_DESCRIPTION.absolute, 'notes': notes}
        except FreejointValueError as exc:
            spatial = _spatial_arm(text, names, passive, states)
            if spatial is not None:
                return spatial
            notes.append('%s: the recorded %s is not an arm the analysis models (%s); '
                         'Fig. 2 shows the Table I arm' % (bag.path, texts[0], exc))
    params = table1(case)
    joints = names or ['joint1', 'joint2', 'joint3']
    return {'joints': joints, 'passive': passive or [DEFAULT_PASSIVE], 'params': params,
            'name': 'Table I', 'source': 'Table I (no %s in the bag)'
            % ROBOT_DESCRIPTION.absolute if not texts else 'Table I', 'notes': notes}


def _spatial_arm(text, names, passive, states):
    """
    Return the arm of a spatial run (``task_dim`` 3: 3-value positions), else None.

    Its figures draw the tip in the plane of its path and no joint-space map (``params``
    None); the URDF's robot name names it.
    """
    import xml.etree.ElementTree as ET
    if not states or len(states[0].position) != 3:
        return None
    try:
        name = ET.fromstring(text).get('name') or 'URDF arm'
    except ET.ParseError:
        return None
    return {'joints': list(names), 'passive': list(passive), 'params': None,
            'name': name, 'source': 'the recorded %s (spatial)' % ROBOT_DESCRIPTION.absolute,
            'notes': []}


def time_origin(t):
    """
    Return the time (s) the figures count from: 0 in sim time, else the first tick's.

    Parameters
    ----------
    t : numpy.ndarray, shape (N,)
        The ticks' stamps (s), increasing.

    Returns
    -------
    float
        0.0 for sim-time stamps (a lockstep run: its time already counts from its start),
        ``t[0]`` for system-time ones (a real-time run: Unix time, ``SYSTEM_TIME_NS``).

    """
    first = float(t[0])
    return first if seconds_to_ns(first) >= SYSTEM_TIME_NS else 0.0


def joint_positions(joint_states, t):
    """
    Return ``{joint name: positions (N,)}`` at the tick times ``t`` (first per stamp).

    A stamp is matched by its time in s computed as ``arrays_from_messages`` computes
    ``t`` (``ns * 1e-9``, the same float): system-time seconds (1.8e9 s) hold no whole
    nanoseconds to round back to.
    """
    import numpy as np
    wanted = {float(v) for v in t}
    first = {}
    for msg in joint_states:
        ns = to_ns(msg.header.stamp) * 1e-9
        if ns in wanted and ns not in first:
            first[ns] = msg
    stamps = [float(v) for v in t]
    if not stamps or any(ns not in first for ns in stamps):
        return {}
    names = list(first[stamps[0]].name)
    out = {}
    for i, name in enumerate(names):
        try:
            out[name] = np.array([float(first[ns].position[list(first[ns].name).index(name)])
                                  for ns in stamps])
        except (ValueError, IndexError):
            continue
    return out


def _parse(argv):
    parser = argparse.ArgumentParser(
        prog='analyze', description="Metrics and the paper's figures from recorded bags.")
    parser.add_argument('bags', nargs='+', metavar='BAG', help='bag directories')
    parser.add_argument('--figures-dir', default=None,
                        help='write every figure here (default: per-bag figures into the '
                        "bag, the others into the bags' common parent)")
    parser.add_argument('--no-plots', action='store_true', help='only the metrics')
    parser.add_argument('--passive-joint', default=None,
                        help="passive joint name (default: the bag's run information, else "
                        'the joint the controller does not command)')
    parser.add_argument('--max-ticks', type=int, default=None,
                        help='use only the first N ticks (default: from the bag, else all)')
    parser.add_argument('--case', default=None, help='override the case of every bag')
    parser.add_argument('--variant', default=None, help='override the variant of every bag')
    parser.add_argument('--seed', type=int, default=None, help='override the seed')
    parser.add_argument('--state-topic', default=None, help='ControllerState topic')
    parser.add_argument('--joint-topic', default=None, help='JointState topic')
    parser.add_argument('--theta', action='store_true', help='table with theta_final')
    parser.add_argument('--bound-mm', type=float, default=None,
                        help="tracking bound against the plan [mm] (default: the paper's "
                        "case's, 1.5 x the offline worst max; none for another arm)")
    return parser.parse_args(argv)


def print_plan_lines(traces):
    """Print per bag the figures against the plan (the table is vs the controller's reference)."""
    from freejoint_core.plan_figures import format_figures
    print('(the table: error against the controller reference, position_desired)')
    for trace in traces:
        if trace['plan'] is not None:
            print('plan: %s: %s' % (trace['name'], format_figures(trace['plan'])))


def main(argv=None):
    """Analyse the bags named on the command line; return the exit code."""
    opts = _parse(sys.argv[1:] if argv is None else argv)
    from freejoint_core.metrics import format_table, write_records
    overrides = {'case': opts.case, 'variant': opts.variant, 'seed': opts.seed,
                 'passive_joint': opts.passive_joint, 'max_ticks': opts.max_ticks,
                 'bound_mm': opts.bound_mm}
    records, traces = [], []
    for path in opts.bags:
        try:
            record, trace, warnings = analyse_bag(path, overrides, opts.state_topic,
                                                  opts.joint_topic)
        except (BagError, AnalysisError) as exc:
            print('analyze: error: %s' % exc, file=sys.stderr)
            return 1
        for line in warnings:
            print('analyze: warning: %s' % line, file=sys.stderr)
        try:
            write_records(os.path.join(path, 'metrics.json'), [record])
        except OSError as exc:
            print('analyze: error: %s: cannot write metrics.json: %s'
                  % (path, exc.strerror), file=sys.stderr)
            return 1
        records.append(record)
        traces.append(trace)
    print(format_table(records, theta=opts.theta))
    print_plan_lines(traces)
    import numpy as np
    for trace in traces:
        error = np.linalg.norm(trace['p'] - trace['p_d'], axis=1)
        for line in failure_lines(trace['name'], trace['failures'], trace['t'] + trace['t0'],
                                  error):
            print('failure: %s' % line)
        for outcome in trace['outcomes']:
            print('outcome: %s: %s' % (trace['name'], outcome_line(outcome)))
        line = verdict_line(trace)
        if line:
            print('verdict: %s: %s' % (trace['name'], line))
    if not opts.no_plots:
        from .plots import write_figures
        try:
            written = write_figures(traces, [os.path.normpath(p) for p in opts.bags],
                                    opts.figures_dir)
        except OSError as exc:
            print('analyze: error: %s: cannot write a figure: %s'
                  % (exc.filename or opts.figures_dir, exc.strerror), file=sys.stderr)
            return 1
        for path in written:
            print('figure: %s' % path)
    return 0


if __name__ == '__main__':
    sys.exit(main())
