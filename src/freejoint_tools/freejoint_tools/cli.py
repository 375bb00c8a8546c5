"""
``fj``: the ROS user's everyday commands where ros2cli is not installed (the PyPI path).

Same syntax and output as ``ros2`` for what a freejoint user does most, so a README line
works with either tool (``ros2 param set ...`` or ``fj param set ...``)::

    fj run <package> <executable> [args...]
    fj node list
    fj topic list [-t]
    fj service list [-t]
    fj service call <service> <type> ['<yaml>']
    fj action list [-t]
    fj action send_goal <action> <type> ['<yaml>'] [-f]
    fj param list [node] [--param-type]
    fj param get <node> <name> [--hide-type]
    fj param set <node> <name> <value> [<name> <value> ...]
    fj param describe <node> <name> [<name> ...]
    fj param dump <node>
    fj param load <node> <file> [--use-wildcard]

Built on rclpy: the graph API, rclpy's parameter client
(``rclpy.parameter_client.AsyncParameterClient``: the same ``~/list_parameters``,
``~/get_parameters``, ``~/set_parameters``, ``~/describe_parameters`` calls ros2param makes)
and the service client. ``param load`` sets the node's own section of the file (and
``/**`` with ``--use-wildcard``) with the YAML types kept (``1.0e-07`` a double, ``[]`` the
declared array type), where ros2 param load re-parses each value from its ``str()``;
a read-only parameter the node already has is skipped (ros2 param load reports it failed),
so what ``param dump`` wrote loads back.
Values are parsed as ``ros2 param set`` parses them (YAML:
``rclpy.parameter.get_parameter_value``). Unlike ros2cli there is no daemon: each command
waits for discovery itself, at most ``--timeout`` s for the node or service it names
(the lists: ``--spin-time`` s, then until nothing new was discovered for 1.5 s, at most
``--timeout`` s more: under load a node can be discovered seconds after the others),
and every answer at most ``--service-timeout`` s (a parameter request, idempotent, is
sent again once after half of it).

Exit status: 0 on success; 1 when the node or service is not found, an answer does not
come, a parameter is not set, or a set / load is refused (ros2 param prints the same
``Setting parameter failed: <reason>`` but exits 0); 2 for a usage error.
"""

import argparse
import importlib
import os
import sys
import time

from freejoint_tools.resend import first_answer

HIDDEN_PREFIX = '_'
TYPE_NAMES = {
    1: 'boolean', 2: 'integer', 3: 'double', 4: 'string', 5: 'byte array',
    6: 'boolean array', 7: 'integer array', 8: 'double array', 9: 'string array',
    0: 'not set',
}
"""rcl_interfaces/msg/ParameterType -> the name ros2 param prints."""
GET_LABELS = {
    1: ('Boolean value is:', 'bool_value'), 2: ('Integer value is:', 'integer_value'),
    3: ('Double value is:', 'double_value'), 4: ('String value is:', 'string_value'),
    5: ('Byte values are:', 'byte_array_value'),
    6: ('Boolean values are:', 'bool_array_value'),
    7: ('Integer values are:', 'integer_array_value'),
    8: ('Double values are:', 'double_array_value'),
    9: ('String values are:', 'string_array_value'),
}
"""ParameterType -> (label of ``ros2 param get``, field of ParameterValue)."""


class CommandError(Exception):
    """A failure to report as one line on stderr, exit status 1."""


def absolute_name(name):
    """Return ``name`` with a leading '/' (``controller_node`` -> ``/controller_node``)."""
    return name if name.startswith('/') else '/' + name


def _full_name(name, namespace):
    return namespace.rstrip('/') + '/' + name


class Session:
    """An rclpy context and a hidden node for one command; closed with ``with``."""

    def __init__(self, args):
        import rclpy
        self.rclpy = rclpy
        self.args = args
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context)
        from rclpy.parameter import Parameter
        # A hidden node that only asks: no parameter services, no /rosout and no
        # ~/get_type_description service (nobody asks fj for its types).
        self.node = rclpy.create_node('%sfj_%d' % (HIDDEN_PREFIX, os.getpid()),
                                      context=self.context,
                                      start_parameter_services=False,
                                      enable_rosout=False,
                                      parameter_overrides=[Parameter(
                                          'start_type_description_service', value=False)])
        from rclpy.executors import SingleThreadedExecutor
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)
        return False

    def spin_for(self, seconds):
        """Let discovery run for ``seconds``."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))

    def settled(self, look, quiet=1.5):
        """
        Return ``look()`` once discovery settled.

        That is after ``--spin-time`` s and once another node was seen, then once it gave
        the same answer for ``quiet`` s (endpoints are discovered after their node), at
        most ``--timeout`` s more in all.
        """
        self.spin_for(self.args.spin_time)
        deadline = time.monotonic() + self.args.timeout
        me = self.node.get_fully_qualified_name()
        while set(self.node_names(include_hidden=True)) <= {me} \
                and time.monotonic() < deadline:
            self.spin_for(0.1)
        seen, since = look(), time.monotonic()
        while time.monotonic() - since < quiet and time.monotonic() < deadline:
            self.spin_for(0.1)
            now = look()
            if now != seen:
                seen, since = now, time.monotonic()
        return seen

    def node_names(self, include_hidden=False):
        """Full names of the nodes seen now (hidden ones only if asked), sorted."""
        names = {_full_name(n, ns) for n, ns in self.node.get_node_names_and_namespaces()}
        if not include_hidden:
            names = {n for n in names if not n.rsplit('/', 1)[-1].startswith(HIDDEN_PREFIX)}
        return sorted(names)

    def wait_for_node(self, name):
        """Wait up to ``--timeout`` s until node ``name`` is seen; raise 'Node not found'."""
        deadline = time.monotonic() + self.args.timeout
        while True:
            if name in self.node_names(include_hidden=True):
                return
            if time.monotonic() >= deadline:
                raise CommandError('Node not found: %s (waited %g s; is it running, in this '
                                   'ROS_DOMAIN_ID?)' % (name, self.args.timeout))
            self.spin_for(0.05)

    def wait_future(self, future, what):
        """
        Spin until ``future`` is done, at most ``--service-timeout`` s; return its result.

        ``future`` may be a callable that sends the request and returns its future (an
        idempotent request: the parameter services'): it is sent again once if half of
        the time passed without an answer, and the first answer of either is taken (a
        response can be lost while the server's side of a service just discovered has not
        matched this client yet; ``freejoint_tools.resend``).
        """
        send = future if callable(future) else (lambda: future)
        timeout = self.args.service_timeout
        answer, _ = first_answer(send, self._spin_while, timeout,
                                 resend=0.5 * timeout if callable(future) else None)
        if answer is None:
            raise CommandError('No answer from %s within %g s' % (what, timeout))
        if answer.exception() is not None:
            raise CommandError('Exception while calling %s: %s' % (what, answer.exception()))
        return answer.result()

    def _spin_while(self, predicate, seconds):
        """Spin until ``predicate()`` or ``seconds`` passed (the ``wait`` of first_answer)."""
        deadline = time.monotonic() + seconds
        while not predicate() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))

    def parameter_client(self, node_name):
        """Return rclpy's AsyncParameterClient of ``node_name`` once its services are up."""
        from rclpy.parameter_client import AsyncParameterClient
        self.wait_for_node(node_name)
        client = AsyncParameterClient(self.node, node_name)
        deadline = time.monotonic() + self.args.timeout
        while not client.services_are_ready():
            if time.monotonic() >= deadline:
                raise CommandError('Wait for service timed out waiting for parameter '
                                   'services for node %s' % node_name)
            self.spin_for(0.05)
        return client


# -- param ------------------------------------------------------------------------------
def _param_list(s, args):
    if args.node_name:
        name = absolute_name(args.node_name)
        s.wait_for_node(name)
        nodes = [name]
    else:
        nodes, services = s.settled(lambda: (
            s.node_names(args.include_hidden_nodes),
            sorted(n for n, _ in s.node.get_service_names_and_types())))
        nodes = [n for n in nodes if n + '/list_parameters' in services]
    for name in nodes:
        client = s.parameter_client(name)
        prefixes = args.param_prefixes or None
        result = s.wait_future(lambda: client.list_parameters(prefixes=prefixes),
                               name + '/list_parameters')
        names = sorted(result.result.names)
        if not args.node_name:
            print(name + ':')
        types = {}
        if args.param_type and names:
            described = s.wait_future(lambda: client.describe_parameters(names),
                                      name + '/describe_parameters')
            types = {d.name: TYPE_NAMES.get(d.type, str(d.type))
                     for d in described.descriptors}
        for pname in names:
            print('  %s (type: %s)' % (pname, types[pname]) if args.param_type
                  else '  ' + pname)
    return 0


def _param_get(s, args):
    name = absolute_name(args.node_name)
    client = s.parameter_client(name)
    values = s.wait_future(lambda: client.get_parameters([args.parameter_name]),
                           name + '/get_parameters').values
    if not values:
        raise CommandError('Parameter not set')
    value = values[0]
    if value.type == 0:
        print('Parameter not set.')
        return 1
    label, field = GET_LABELS[value.type]
    shown = getattr(value, field)
    print(shown if args.hide_type else '%s %s' % (label, shown))
    return 0


def _param_set(s, args):
    from rcl_interfaces.msg import Parameter
    from rclpy.parameter import get_parameter_value
    items = args.params_and_values
    if len(items) % 2:
        print('Parameters must be provided as name/value pairs: name value [name value ...]. '
              'Got %d argument(s).' % len(items), file=sys.stderr)
        return 2
    pairs = list(zip(items[::2], items[1::2]))
    name = absolute_name(args.node_name)
    client = s.parameter_client(name)
    params = [Parameter(name=pname, value=get_parameter_value(text)) for pname, text in pairs]
    results = s.wait_future(lambda: client.set_parameters(params),
                            name + '/set_parameters').results
    status = 0
    for (pname, _), result in zip(pairs, results):
        msg = 'Set parameter successful' if result.successful else 'Setting parameter failed'
        if result.reason:
            msg += ': ' + result.reason
        if len(pairs) > 1:
            msg = '%s: %s' % (pname, msg)
        print(msg, file=sys.stdout if result.successful else sys.stderr)
        status = status or (0 if result.successful else 1)
    return status


def _param_describe(s, args):
    name = absolute_name(args.node_name)
    client = s.parameter_client(name)
    descriptors = s.wait_future(lambda: client.describe_parameters(args.parameter_names),
                                name + '/describe_parameters').descriptors
    if not descriptors:
        raise CommandError('Parameter not declared: %s' % ', '.join(args.parameter_names))
    for d in descriptors:
        print('Parameter name:', d.name)
        print('  Type:', TYPE_NAMES.get(d.type, str(d.type)))
        if d.description:
            print('  Description:', d.description)
        print('  Constraints:')
        if d.read_only:
            print('    Read only: true')
        ranges = list(d.floating_point_range) + list(d.integer_range)
        if ranges:
            print('    Min value:', ranges[0].from_value)
            print('    Max value:', ranges[0].to_value)
            if ranges[0].step:
                print('    Step:', ranges[0].step)
        if d.additional_constraints:
            print('    Additional constraints:', d.additional_constraints)
    return 0


def dump_parameters(names, values):
    """Return ``{name: value}`` nested at '.' as ros2 param dump does, from get_parameters."""
    from rclpy.parameter import parameter_value_to_python
    tree = {}
    for pname, value in zip(names, values):
        *path, leaf = pname.split('.')
        branch = tree
        for part in path:
            branch = branch.setdefault(part, {})
        branch[leaf] = parameter_value_to_python(value)
    return tree


def _param_dump(s, args):
    import yaml
    name = absolute_name(args.node_name)
    client = s.parameter_client(name)
    names = sorted(s.wait_future(lambda: client.list_parameters(),
                                 name + '/list_parameters').result.names)
    values = s.wait_future(lambda: client.get_parameters(names), name + '/get_parameters').values
    if len(values) != len(names):
        raise CommandError('%s/get_parameters answered %d values for %d parameters (a '
                           'parameter without a value?)' % (name, len(values), len(names)))
    print(yaml.dump({name: {'ros__parameters': dump_parameters(names, values)}},
                    default_flow_style=False))
    return 0


def file_parameters(path, node_name, use_wildcard=False):
    """
    Return ``{name: value}`` for ``node_name`` from a params file (``--params-file`` YAML).

    The node's own section (``/name`` or ``name``) and, with ``use_wildcard``, the ``/**``
    section first (the node's own values win); nested keys joined with '.'. Values keep
    their YAML type (rclpy's loader passes them through ``str()``, which turns ``1.0e-07``
    into the string '1e-07'). Raises CommandError naming the file.
    """
    import yaml
    try:
        with open(path) as f:
            content = yaml.safe_load(f)
    except (OSError, yaml.YAMLError) as exc:
        raise CommandError('Cannot load %s: %s' % (path, exc))
    if not isinstance(content, dict):
        raise CommandError('Cannot load %s: not a ROS parameter file' % path)
    keys = (['/**'] if use_wildcard else []) + [node_name, node_name.lstrip('/')]
    keys = [k for k in keys if k in content]
    if not keys:
        raise CommandError('Cannot load %s: no parameters for %s in it (sections: %s%s)' % (
            path, node_name, ', '.join(map(str, content)),
            '' if use_wildcard else "; '/**' is loaded with --use-wildcard"))
    values = {}

    def flatten(prefix, tree):
        for key, value in tree.items():
            if isinstance(value, dict):
                flatten(prefix + str(key) + '.', value)
            else:
                values[prefix + str(key)] = value

    for key in keys:
        section = content[key]
        params = section.get('ros__parameters') if isinstance(section, dict) else None
        if not isinstance(params, dict):
            raise CommandError('Cannot load %s: section %s has no ros__parameters'
                               % (path, key))
        flatten('', params)
    return values


def _drop_unchanged_read_only(s, client, name, params):
    """
    Return ``params`` without the read-only ones the node already has (each said).

    So a file ``param dump`` wrote loads back into a node without a refusal for each
    read-only parameter (ros2 param load prints them as failed).
    """
    from rclpy.parameter import parameter_value_to_python
    names = [p.name for p in params]
    descriptors = s.wait_future(lambda: client.describe_parameters(names),
                                name + '/describe_parameters').descriptors
    read_only = [d.name for d in descriptors if d.read_only]  # none if one is undeclared
    if not read_only:
        return params
    values = s.wait_future(lambda: client.get_parameters(read_only),
                           name + '/get_parameters').values
    current = {n: parameter_value_to_python(v) for n, v in zip(read_only, values)}
    kept = []
    for param in params:
        if param.name in current and param.value == current[param.name]:
            print('Set parameter %s skipped: read-only, already %r'
                  % (param.name, param.value))
        else:
            kept.append(param)
    return kept


def _param_load(s, args):
    from rclpy.parameter import Parameter
    name = absolute_name(args.node_name)
    values = file_parameters(args.parameter_file, name, args.use_wildcard)
    client = s.parameter_client(name)
    types = {}
    empty = [k for k, v in values.items() if v == []]
    if empty:  # an empty list has no type of its own: take the declared one
        answer = s.wait_future(lambda: client.get_parameter_types(empty),
                               name + '/get_parameter_types')
        types = dict(zip(empty, answer.types))
    params = []
    for pname, value in values.items():
        if types.get(pname):
            param = Parameter(pname, Parameter.Type(types[pname]), [])
        else:
            try:
                param = Parameter(pname, value=value)
            except TypeError as exc:
                raise CommandError('Cannot load %s: %s: %s' % (args.parameter_file, pname,
                                                               exc))
        params.append(param)
    params = _drop_unchanged_read_only(s, client, name, params)
    results = s.wait_future(lambda: client.set_parameters(params),
                            name + '/set_parameters').results
    status = 0
    for param, result in zip(params, results):
        msg = 'Set parameter %s %s' % (param.name,
                                       'successful' if result.successful else 'failed')
        if result.reason:
            msg += ': ' + result.reason
        print(msg, file=sys.stdout if result.successful else sys.stderr)
        status = status or (0 if result.successful else 1)
    return status


# -- node, topic, service ------------------------------------------------------------------
def _node_list(s, args):
    for name in s.settled(lambda: s.node_names(args.all)):
        print(name)
    return 0


def _names_and_types(pairs, show_types):
    for name, types in sorted(pairs):
        print('%s [%s]' % (name, ', '.join(types)) if show_types else name)
    return 0


def _topic_list(s, args):
    return _names_and_types(s.settled(s.node.get_topic_names_and_types), args.show_types)


def _service_list(s, args):
    return _names_and_types(s.settled(s.node.get_service_names_and_types), args.show_types)


def interface_class(type_name):
    """Return the class of ``pkg/srv/Name`` (or ``pkg/msg/Name``); raise CommandError."""
    parts = type_name.split('/')
    if len(parts) == 2:
        parts.insert(1, 'srv')
    if len(parts) != 3 or not all(parts):
        raise CommandError('The passed type is invalid: %s (expected <package>/srv/<Name>)'
                           % type_name)
    try:
        return getattr(importlib.import_module('%s.%s' % (parts[0], parts[1])), parts[2])
    except (ImportError, AttributeError):
        raise CommandError('The passed type is invalid or not installed: %s' % type_name)


def _slot_class(slot_type):
    """Message class of a rosidl slot type naming a message (or a sequence of them)."""
    inner = getattr(slot_type, 'value_type', slot_type)
    names = getattr(inner, 'namespaces', None)
    if not names:
        return None
    return getattr(importlib.import_module('.'.join(names)), inner.name)


def set_message_fields(msg, values, where=''):
    """
    Fill ``msg`` from a dict (the YAML of ``ros2 service call``), nested messages too.

    Integers are accepted for float fields, lists for arrays and sequences (of messages:
    a list of dicts). Raises CommandError naming the field on an unknown field or a
    value of the wrong type or range (``msg`` built with ``check_fields=True``).
    """
    if not isinstance(values, dict):
        raise CommandError('Failed to populate field%s: expected a mapping, got %r'
                           % (' ' + where if where else '', values))
    fields = msg.get_fields_and_field_types()
    slots = dict(zip(fields, msg.SLOT_TYPES))
    for key, value in values.items():
        path = where + '.' + key if where else key
        if key not in fields:
            raise CommandError('Failed to populate field %s: %s has no such field (fields: '
                               '%s)' % (path, type(msg).__name__, ', '.join(fields)))
        current = getattr(msg, key)
        sub = _slot_class(slots[key])
        try:
            if sub is not None and isinstance(value, dict):
                value_msg = type(current)(check_fields=True)
                set_message_fields(value_msg, value, path)
                value = value_msg
            elif sub is not None and isinstance(value, list):
                items = []
                for i, item in enumerate(value):
                    obj = sub(check_fields=True)
                    set_message_fields(obj, item, '%s[%d]' % (path, i))
                    items.append(obj)
                value = items
            elif isinstance(current, float) and isinstance(value, int) \
                    and not isinstance(value, bool):
                value = float(value)
            elif isinstance(value, list) and (
                    getattr(getattr(current, 'dtype', None), 'kind', '') == 'f'
                    or getattr(current, 'typecode', '') in ('f', 'd')):
                value = [float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                         for v in value]
            setattr(msg, key, value)
        except (AssertionError, TypeError, ValueError) as exc:
            raise CommandError('Failed to populate field %s: %s' % (path, exc))


def fill_from_yaml(msg, text):
    """Fill ``msg`` from the YAML ``text`` of a command line (CommandError naming why)."""
    import yaml
    try:
        values = yaml.safe_load(text) if text else {}
    except yaml.YAMLError as exc:
        raise CommandError('The passed value is not valid YAML: %s' % exc)
    set_message_fields(msg, values or {})


def _wait_server(s, ready, waiting, missing):
    """Wait up to ``--timeout`` s for ``ready()`` (a server discovered), saying so once."""
    if ready():
        return
    print(waiting)
    deadline = time.monotonic() + s.args.timeout
    while not ready():
        if time.monotonic() >= deadline:
            raise CommandError('%s (waited %g s)' % (missing, s.args.timeout))
        s.spin_for(0.05)


def _service_call(s, args):
    service = absolute_name(args.service_name)
    srv = interface_class(args.service_type)
    request = srv.Request(check_fields=True)  # a value of the wrong type raises, named
    fill_from_yaml(request, args.values)
    client = s.node.create_client(srv, service)
    _wait_server(s, client.service_is_ready, 'waiting for service to become available...',
                 'Service not available: %s' % service)
    print('requester: making request: %r\n' % (request,))
    response = s.wait_future(client.call_async(request), service)
    print('response:\n%r\n' % (response,))
    return 0


# -- actions ----------------------------------------------------------------------------
GOAL_STATUS = {1: 'ACCEPTED', 2: 'EXECUTING', 3: 'CANCELING', 4: 'SUCCEEDED', 5: 'CANCELED',
               6: 'ABORTED'}
"""action_msgs/msg/GoalStatus -> the name ``ros2 action send_goal`` prints."""


def _action_list(s, args):
    from rclpy.action import get_action_names_and_types
    return _names_and_types(s.settled(lambda: get_action_names_and_types(s.node)),
                            args.show_types)


def _outcome_line(result):
    """Return a freejoint PlanOutcome result in one line, '' for another action's result."""
    from freejoint_common.outcome import outcome_line
    outcome = getattr(result, 'outcome', None)
    if outcome is None or not hasattr(outcome, 'code_name'):
        return ''
    return 'Outcome: ' + outcome_line(outcome)


def _send_goal(s, args):
    """
    Send a goal as ``ros2 action send_goal`` does; print feedback (``-f``) and the result.

    Ctrl-C cancels the goal and waits for its result. Exit status 0 when the goal
    succeeded, 1 otherwise (ros2 action exits 0 whatever the outcome).
    """
    from rclpy.action import ActionClient
    name = absolute_name(args.action_name)
    action = interface_class(args.action_type)
    goal = action.Goal(check_fields=True)
    fill_from_yaml(goal, args.goal)
    client = ActionClient(s.node, action, name)
    _wait_server(s, client.server_is_ready,
                 'Waiting for an action server to become available...',
                 'Action server not available: %s' % name)
    print('Sending goal:\n     %r\n' % (goal,))

    def feedback(msg):
        print('Feedback:\n    %r\n' % (msg.feedback,))
    handle = s.wait_future(client.send_goal_async(
        goal, feedback_callback=feedback if args.feedback else None), name)
    if not handle.accepted:
        print('Goal was rejected.')
        return 1
    print('Goal accepted with ID: %s\n' % bytes(handle.goal_id.uuid).hex())
    future = handle.get_result_async()
    try:
        while not future.done():
            s.executor.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        print('Canceling goal...')
        s.wait_future(handle.cancel_goal_async(), name + ' (cancel)')
        s.wait_future(future, name + ' (result)')
    answer = future.result()
    print('Result:\n    %r\n' % (answer.result,))
    line = _outcome_line(answer.result)
    if line:
        print(line)
    status = GOAL_STATUS.get(answer.status, str(answer.status))
    print('Goal finished with status: %s' % status)
    return 0 if status == 'SUCCEEDED' else 1


# -- run --------------------------------------------------------------------------------
def executable_path(package, executable):
    """Return ``<prefix>/lib/<package>/<executable>`` as ``ros2 run`` finds it."""
    from ament_index_python.packages import get_package_prefix, PackageNotFoundError
    try:
        prefix = get_package_prefix(package)
    except PackageNotFoundError:
        raise CommandError('Package not found: %s' % package)
    path = os.path.join(prefix, 'lib', package, executable)
    if not os.access(path, os.X_OK):
        found = sorted(os.listdir(os.path.dirname(path))) \
            if os.path.isdir(os.path.dirname(path)) else []
        raise CommandError('No executable found: %s %s (has: %s)'
                           % (package, executable, ', '.join(found) or 'none'))
    return path


def _run(args):
    path = executable_path(args.package_name, args.executable_name)
    os.execv(path, [path, *args.argv])


# -- command line -------------------------------------------------------------------------
def _waits(parser, spin=False):
    parser.add_argument('--timeout', type=float, default=10.0, metavar='N',
                        help='wait N s for the node or service to be discovered '
                             '(default %(default)s)')
    parser.add_argument('--service-timeout', type=float, default=10.0, metavar='N',
                        help='wait N s for each answer (default %(default)s)')
    if spin:
        parser.add_argument('--spin-time', type=float, default=0.5, metavar='N',
                            help='discover for N s before listing, then until nothing new '
                            "came for 1.5 s (default %(default)s, ros2cli's)")


def _campaign(args):
    from freejoint_tools import campaign
    return campaign.main(args.argv)


def _typed_list(cmds, noun, nouns, help_text, func):
    """Add ``fj <noun> list [-t]``; return the noun's verb subparsers (for more verbs)."""
    verbs = cmds.add_parser(noun, help=nouns).add_subparsers(
        dest='verb', required=True, metavar='verb')
    p = verbs.add_parser('list', help=help_text)
    p.add_argument('-t', '--show-types', action='store_true')
    _waits(p, spin=True)
    p.set_defaults(func=func)
    return verbs


def _arm_init(args):
    """``fj arm init``: write the arm's files, or say in one line why not (status 2)."""
    from freejoint_core.errors import FreejointValueError
    from freejoint_tools.arm_init import init_arm
    try:
        paths = init_arm(args.urdf, args.passive, args.out, args.tip, args.base, args.radius,
                         log=lambda line: print('fj arm init: ' + line, file=sys.stderr),
                         passive_damping=args.passive_damping, hold_s=args.hold)
    except FreejointValueError as exc:
        print(f'fj arm init: refused: {exc}', file=sys.stderr)
        return 2
    for path in paths:
        print(path)
    return 0


def build_parser():
    """Return the argparse parser of ``fj``."""
    parser = argparse.ArgumentParser(
        prog='fj', description="ros2cli's everyday commands for the freejoint nodes, "
        'without ros2cli (ROS 2 from PyPI wheels); same syntax as ros2')
    cmds = parser.add_subparsers(dest='command', required=True, metavar='command')

    run = cmds.add_parser('run', help='run an executable of a package (as ros2 run)')
    run.add_argument('package_name')
    run.add_argument('executable_name')
    run.add_argument('argv', nargs=argparse.REMAINDER)
    run.set_defaults(func=_run, session=False)

    camp = cmds.add_parser('campaign', add_help=False,
                           help='robustness campaigns: run FILE, report RESULTS '
                           '(freejoint_tools.campaign)')
    camp.add_argument('argv', nargs=argparse.REMAINDER)
    camp.set_defaults(func=_campaign, session=False)

    arm = cmds.add_parser('arm', help="a spatial arm's parameter files from its URDF "
                          '(freejoint_tools.arm_init)').add_subparsers(
        dest='verb', required=True, metavar='verb')
    p = arm.add_parser('init', help='write DIR/{sim,controller,planner,arm}.yaml for make '
                       'demo ARM=DIR')
    p.add_argument('urdf')
    p.add_argument('--passive', action='append', required=True, metavar='JOINT',
                   help='a free joint (repeat for more)')
    p.add_argument('--tip', help='tip link (default: the deepest link of moving joints)')
    p.add_argument('--base', help="base link (default: the URDF's root link)")
    p.add_argument('--radius', type=float, help='circle radius [m] (default min(0.1, L/10))')
    p.add_argument('--passive-damping', type=float, metavar='B',
                   help="the free joints' drivetrain damping in the simulator [N m s/rad] "
                   '(default: the least that keeps them within their limits under the '
                   "simulator's disturbance, or the URDF's <dynamics damping> where larger)")
    p.add_argument('--hold', type=float, default=10.0, metavar='S',
                   help='the hold after the circle [s] (default 10)')
    p.add_argument('--out', required=True, metavar='DIR')
    p.set_defaults(func=_arm_init, session=False)

    node = cmds.add_parser('node', help='nodes').add_subparsers(
        dest='verb', required=True, metavar='verb')
    p = node.add_parser('list', help='output a list of available nodes')
    p.add_argument('-a', '--all', action='store_true', help='display hidden nodes too')
    _waits(p, spin=True)
    p.set_defaults(func=_node_list)

    _typed_list(cmds, 'topic', 'topics', 'output a list of available topics', _topic_list)
    service = _typed_list(cmds, 'service', 'services', 'output a list of available services',
                          _service_list)
    p = service.add_parser('call', help='call a service')
    p.add_argument('service_name')
    p.add_argument('service_type', help='e.g. freejoint_msgs/srv/PlanCircle')
    p.add_argument('values', nargs='?', default='{}',
                   help='request fields in YAML, e.g. "{radius: 0.2}"')
    _waits(p)
    p.set_defaults(func=_service_call)

    action = _typed_list(cmds, 'action', 'actions', 'output a list of action names',
                         _action_list)
    p = action.add_parser('send_goal', help='send an action goal, print its result')
    p.add_argument('action_name')
    p.add_argument('action_type', help='e.g. freejoint_msgs/action/FollowCircle')
    p.add_argument('goal', nargs='?', default='{}',
                   help='goal fields in YAML, e.g. "{radius: 0.2, duration: 5.0}"')
    p.add_argument('-f', '--feedback', action='store_true', help='echo the feedback messages')
    _waits(p)
    p.set_defaults(func=_send_goal)

    param = cmds.add_parser('param', help='parameters').add_subparsers(
        dest='verb', required=True, metavar='verb')
    p = param.add_parser('list', help='output a list of available parameters')
    p.add_argument('node_name', nargs='?')
    p.add_argument('--include-hidden-nodes', action='store_true')
    p.add_argument('--param-prefixes', nargs='+', default=[])
    p.add_argument('--param-type', action='store_true')
    _waits(p, spin=True)
    p.set_defaults(func=_param_list)
    p = param.add_parser('get', help='get parameter')
    p.add_argument('node_name')
    p.add_argument('parameter_name')
    p.add_argument('--hide-type', action='store_true')
    _waits(p)
    p.set_defaults(func=_param_get)
    p = param.add_parser('set', help='set parameter')
    p.add_argument('node_name')
    p.add_argument('params_and_values', nargs='+', metavar='name value')
    _waits(p)
    p.set_defaults(func=_param_set)
    p = param.add_parser('describe', help='show descriptive information about parameters')
    p.add_argument('node_name')
    p.add_argument('parameter_names', nargs='+')
    _waits(p)
    p.set_defaults(func=_param_describe)
    p = param.add_parser('dump', help="show every parameter of a node in a params file's "
                         'YAML')
    p.add_argument('node_name')
    _waits(p)
    p.set_defaults(func=_param_dump)
    p = param.add_parser('load', help='load a parameter file into a node')
    p.add_argument('node_name')
    p.add_argument('parameter_file')
    p.add_argument('--use-wildcard', action='store_true',
                   help="load the '/**' section of the file too")
    _waits(p)
    p.set_defaults(func=_param_load)
    return parser


def keep_stdout_for_output():
    """
    Keep the process's stdout for fj's own output; what libraries write there goes to stderr.

    Fast DDS logs to the C++ standard output (e.g. its shared-memory transport's 'Failed
    init_port ... open_and_lock_file failed', harmless: it falls back to UDP), which would
    land in ``fj param dump > file.yaml``. File descriptor 1 becomes a copy of 2, and
    ``sys.stdout`` writes to the original stdout.
    """
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = os.fdopen(saved, 'w', buffering=1)


def main(argv=None):
    """Run one ``fj`` command; return its exit status."""
    args = build_parser().parse_args(argv)
    try:
        if not getattr(args, 'session', True):
            return args.func(args)
        keep_stdout_for_output()
        with Session(args) as session:
            return args.func(session, args)
    except CommandError as exc:
        print(exc, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `fj ... | head`
        sys.stderr.close()
        return 0


if __name__ == '__main__':
    sys.exit(main())
