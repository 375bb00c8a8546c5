"""
Node plumbing shared by the freejoint nodes.

:class:`NodeParameters` is the generic parameter loader of a node's schema
(``freejoint_common.schema``): :func:`declare` declares each entry once with its descriptor;
:func:`unique_names` validates a joint-name list; :class:`Throttle` rate-limits log lines
per kind of problem; ``SCHEDULING_SPECS`` and :func:`request_scheduling` give a node the
``thread_priority`` / ``cpu_affinity`` parameters of ros2_control's controller_manager;
:func:`overridable` and ``QOS_OVERRIDES`` make a publisher's or subscription's QoS
overridable by ros2's ``qos_overrides.<topic>.<publisher|subscription>.<policy>``
parameters.
"""

import copy
import gc
import time

from freejoint_common.scheduling import process_scheduling, rt_budget, rt_budget_note
from freejoint_common.schema import SCHEDULING, Spec, unique_names  # noqa: F401
from freejoint_core.errors import FreejointValueError
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter
from rclpy.qos_overriding_options import QoSOverridingOptions

_monotonic = time.monotonic


class Throttle:
    """
    Rate-limit log lines per kind of problem (at most one per ``period`` wall s each).

    Unlike rclpy's per-call-site throttling, a different problem is logged at once, and
    the next line of a kind says how many were suppressed meanwhile.
    """

    def __init__(self, period=1.0):
        self.period = period
        self._last = {}
        self._suppressed = {}

    def __call__(self, log, kind, text):
        """Log ``text`` with ``log`` unless ``kind`` was logged less than a period ago."""
        now = _monotonic()
        if now - self._last.get(kind, -1e18) < self.period:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        more = self._suppressed.pop(kind, 0)
        self._last[kind] = now
        text += ' (%d more like it suppressed)' % more if more else ''
        # rclpy ties one severity to each logging call site (ValueError on another one):
        # a call line per severity.
        if getattr(log, '__name__', '') == 'error':
            log(text)
        else:
            log(text)


def declare(node, specs):
    """
    Declare each parameter of ``specs`` once with its descriptor; return the values.

    A parameter that ``follows`` others is declared after them, its default the value it
    follows (the schema's default if that cannot be had: the check then says why).
    """
    values = {}
    for spec in sorted(specs, key=lambda spec: spec.follows is not None):
        default = spec.default
        if spec.follows is not None:
            try:
                default = spec.follows(values)
            except FreejointValueError:
                pass
        desc = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
        if spec.default is None:
            param = node.declare_parameter(spec.name, Parameter.Type.INTEGER_ARRAY, desc)
            if param.type_ == Parameter.Type.NOT_SET:
                # A parameter without a value makes rclpy's GetParameters answer an empty
                # list for any request naming it: `ros2 param dump`, rqt and Foxglove then
                # get nothing at all. An empty typed array is a value.
                node.set_parameters([Parameter(spec.name, Parameter.Type.INTEGER_ARRAY, [])])
            values[spec.name] = plain(param.value) or None    # None: not given
            continue
        if spec.bounds is not None and isinstance(spec.default, int):
            step = spec.bounds[2] if len(spec.bounds) > 2 else 1
            desc.integer_range = [IntegerRange(
                from_value=int(spec.bounds[0]), to_value=int(spec.bounds[1]), step=step)]
        elif spec.bounds is not None:
            desc.floating_point_range = [FloatingPointRange(
                from_value=float(spec.bounds[0]), to_value=float(spec.bounds[1]), step=0.0)]
        values[spec.name] = _typed(spec, node.declare_parameter(spec.name, default,
                                                                desc).value)
    return values


def _typed(spec, value):
    """Return a parameter value as plain Python; an array given empty ([]: None) as []."""
    value = plain(value)
    if value is None and isinstance(spec.default, list):
        return []
    return value


class NodeParameters:
    """
    The generic loader: declare a node's schema, build its config, keep it current.

    Construction declares every entry of ``schema`` (``freejoint_common.schema.Schema``)
    with its descriptor and builds ``config`` from the values; a bad start-up value raises
    (rclpy's ``ParameterException`` for a range or type, ``FreejointValueError`` with the
    schema's reason), which :func:`run` turns into one line and exit status 2. A schema
    with the scheduling entries gets its process scheduling requested. :meth:`listen`
    adds the set-parameters callback: the changed values are validated by the schema
    (then by the node's ``check``, then the scheduling is applied), refused with the
    reason, or taken (``values``, ``config``) and handed to the node's ``apply``.
    """

    def __init__(self, node, schema):
        self.node = node
        self.schema = schema
        self.values = declare(node, schema)
        self.config = schema.config(self.values)
        self._scheduling = all(name in schema for name in SCHEDULING_NAMES)
        self._apply = self._check = None
        self._watch = ()
        if self._scheduling:
            request_scheduling(node, self.values, at_start=True)

    def listen(self, apply=None, check=None, watch=()):
        """
        Validate and apply parameter changes from now on.

        Parameters
        ----------
        apply : callable, optional
            ``apply(old_config, new_config, params)`` after a change was taken.
        check : callable, optional
            ``check(params, values, config) -> reason or None``: the node's run-time checks
            of a change (with what it knows only at run time); None accepts.
        watch : tuple of str
            Names not in the schema whose changes go to ``check`` / ``apply`` too
            (``use_sim_time``).

        """
        self._apply = apply
        self._check = check
        self._watch = tuple(watch)
        self.node.add_on_set_parameters_callback(self._on_set_parameters)

    def _on_set_parameters(self, params):
        mine = [p for p in params if p.name in self.values]
        if not mine and not any(p.name in self._watch for p in params):
            # Not ours (the read-only qos_overrides.* rclpy declares): nothing to check.
            return SetParametersResult(successful=True)
        values = dict(self.values)
        for param in mine:
            values[param.name] = _typed(self.schema[param.name], param.value)
        try:
            config = self.schema.config(values)
            reason = None if self._check is None else self._check(params, values, config)
            if reason is None and self._scheduling:
                reason = scheduling_refusal(self.node, params, values)
        except FreejointValueError as exc:
            reason = str(exc)
        if reason:
            self.node.get_logger().warning('parameter change refused: ' + reason,
                                           throttle_duration_sec=1.0)
            return SetParametersResult(successful=False, reason=reason)
        old = self.config
        self.values = values
        self.config = config
        if self._apply is not None:
            self._apply(old, config, params)
        return SetParametersResult(successful=True)


SCHEDULING_SPECS = SCHEDULING
SCHEDULING_NAMES = tuple(spec.name for spec in SCHEDULING_SPECS)


def request_scheduling(node, values, at_start=False):
    """
    Ask for the node's ``thread_priority`` / ``cpu_affinity`` for the whole process.

    Returns None when applied, else the reason. At start-up (``at_start``, before the
    node's set-parameters callback is added) a refusal is logged as an error and the node
    runs on without it, as ros2_control's controller_manager does: ``thread_priority``
    becomes 0 in ``values`` and in the node's parameters (``ros2 param get`` tells the
    truth) and the affinity alone is applied. A non-default result is logged.
    """
    sched = process_scheduling()
    name = node.get_fully_qualified_name()
    reason = sched.request(name, values['thread_priority'], values['cpu_affinity'])
    if reason is not None and at_start:
        asked = values['thread_priority']
        values['thread_priority'] = 0
        node.set_parameters([Parameter('thread_priority', value=0)])
        again = sched.request(name, 0, values['cpu_affinity'])
        node.get_logger().error(
            'thread_priority %s not applied: %s; running with thread_priority 0 (%s)'
            % (asked, reason, sched.describe() if again is None else again))
    elif reason is None and sched.requests and (sched.priority or sched.affinity):
        node.get_logger().info('process scheduling: ' + sched.describe())
        note = rt_budget_note(rt_budget()) if sched.priority else None
        if note is not None:
            node.get_logger().info(note, once=True)
    return reason


def scheduling_refusal(node, params, values):
    """
    Apply a change of ``thread_priority`` / ``cpu_affinity`` among ``params`` (set-callback).

    ``values`` are the node's validated values with ``params`` in them. Returns None when
    neither is among ``params`` or the change is applied, else the reason to refuse the
    parameters with.
    """
    if not any(p.name in SCHEDULING_NAMES for p in params):
        return None
    return request_scheduling(node, values)


QOS_OVERRIDES = QoSOverridingOptions.with_default_policies()
"""rclpy's standard QoS overriding options (history, depth, reliability): with
``qos_overriding_options=QOS_OVERRIDES`` a publisher or subscription declares the read-only
parameters ``qos_overrides.<resolved topic>.<publisher|subscription>.<policy>`` with the
profile's values, and takes a value given at start-up (``-p``, ``--params-file``) instead."""


def overridable(profile):
    """
    Return a copy of ``profile`` for one publisher or subscription with ``QOS_OVERRIDES``.

    rclpy writes the overridden policies into the profile it is given: a profile shared
    by several entities would carry one topic's override to the others.
    """
    return copy.copy(profile)


def plain(value):
    """Parameter value as plain Python (arrays as lists)."""
    if isinstance(value, (str, bool, int, float)) or value is None:
        return value
    return list(value)


class GcPauses:
    """
    The garbage collector's runs and longest pauses in this process, per generation.

    :meth:`start` collects once and freezes what start-up made (``gc.freeze``: modules,
    rclpy, the node, preallocated arrays are never scanned again, so a full collection
    only walks what the run allocated since) and installs a ``gc.callbacks`` hook; the
    hook costs nothing between collections.  :meth:`report` says how often each
    generation ran and its longest pause: the tail of a Python real-time loop.
    """

    def __init__(self):
        self.count = [0, 0, 0]
        self.longest = [0.0, 0.0, 0.0]
        self._t0 = 0.0

    def __call__(self, phase, info):
        """Time each collection (the ``gc.callbacks`` hook)."""
        if phase == 'start':
            self._t0 = time.perf_counter()
            return
        gen = info.get('generation', 2)
        pause = time.perf_counter() - self._t0
        self.count[gen] += 1
        if pause > self.longest[gen]:
            self.longest[gen] = pause

    def start(self):
        """Collect, freeze the start-up objects and hook the collector."""
        gc.collect()
        gc.freeze()
        if self not in gc.callbacks:
            gc.callbacks.append(self)

    def report(self):
        """Return 'garbage collections: gen0 N (longest x ms), ...'."""
        return 'garbage collections: ' + ', '.join(
            'gen%d %d (longest %.2f ms)' % (g, self.count[g], 1e3 * self.longest[g])
            for g in range(3))


GC_PAUSES = GcPauses()
"""This process's collector statistics (started by ``runner.spin_until``)."""


def parameter_error(exc):
    """
    One line naming the parameter and the reason, from a start-up parameter error.

    ``FreejointValueError`` messages already start with the name; rclpy's
    ``ParameterException`` ends with it ('<reason>: <name>'), so it is moved to the front.
    """
    text = ' '.join(str(exc).split())
    if isinstance(exc, FreejointValueError):
        return text
    reason, sep, names = text.rpartition(': ')
    return '%s: %s' % (names, reason) if sep else text
