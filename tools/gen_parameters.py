"""
Write docs/parameters.md, the parameter reference of every node, from the schemas.

The schemas (``src/<pkg>/<pkg>/params.py``, entries shared by nodes in
``freejoint_common/schema.py``) are the one place of a parameter's default, range,
read-only flag and description; this renders them as one table per node. Run it after
changing a schema (test/tools/test_parameter_schemas.py fails while the file is stale):

    python tools/gen_parameters.py            # rewrite docs/parameters.md
    python tools/gen_parameters.py --check    # exit 1 if docs/parameters.md is stale
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUTPUT = os.path.join(ROOT, 'docs', 'parameters.md')
COMMAND = 'python tools/gen_parameters.py'


def nodes():
    """Return (node, executable, schema file, params file or None, Schema) of every node."""
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    from freejoint_tools.params import PLAYER, RECORDER
    return (
        ('sim_node', 'freejoint_sim sim_node', 'src/freejoint_sim/freejoint_sim/params.py',
         'config/sim.yaml', SIM),
        ('controller_node', 'freejoint_control controller_node',
         'src/freejoint_control/freejoint_control/params.py', 'config/controller.yaml',
         CONTROLLER),
        ('freejoint_planner', 'freejoint_planner planner_node',
         'src/freejoint_planner/freejoint_planner/params.py', 'config/planner.yaml', PLANNER),
        ('recorder', 'freejoint_tools recorder',
         'src/freejoint_tools/freejoint_tools/params.py', None, RECORDER),
        ('player', 'freejoint_tools player', 'src/freejoint_tools/freejoint_tools/params.py',
         None, PLAYER),
    )


def type_name(default):
    """Return the ROS parameter type of a schema default."""
    if default is None:
        return 'integer[]'
    if isinstance(default, (list, tuple)):
        return type_name(default[0] if default else '') + '[]'
    return {bool: 'bool', int: 'integer', float: 'double', str: 'string'}[type(default)]


def shown(value):
    """Return a value as a ``--params-file`` YAML writes it."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return repr(value) if value in ('', 'off', 'on', 'true', 'false') else value
    if isinstance(value, (list, tuple)):
        return '[%s]' % ', '.join(shown(v) for v in value)
    return repr(value)


def bounds(param):
    """Return the inclusive (or lower-exclusive) range of an entry, or ''."""
    if param.bounds is None:
        return ''
    lo, hi = param.bounds[:2]
    return '%s%g, %g]' % ('(' if param.exclusive_min else '[', lo, hi)


def cell(text):
    """Return ``text`` fit for a Markdown table cell."""
    return text.replace('|', '\\|').replace('\n', ' ')


def render():
    """Return the text of docs/parameters.md."""
    lines = [
        '# Node parameters',
        '',
        'Generated from the parameter schemas by `%s`: do not edit, change the schema and '
        'regenerate (`test/tools/test_parameter_schemas.py` fails while this file is stale). '
        'A running node answers the same with `fj param describe <node> <name>`. The '
        '`config/*.yaml` files set only what a run changes from these defaults.' % COMMAND,
        '',
        'Ranges are inclusive unless they open with `(`; a read-only parameter is set at '
        'start-up only (`--params-file`, `-p`); every other one can be set at run time, a bad '
        'value refused with its reason.',
    ]
    for node, executable, schema_file, params_file, schema in nodes():
        lines += ['', '## %s' % node, '',
                  '`ros2 run %s`; schema: `%s`%s.' % (
                      executable, schema_file,
                      '' if params_file is None else '; settings of the graph: `%s`'
                      % params_file),
                  '',
                  '| name | type | default | range | read-only | description |',
                  '|---|---|---|---|---|---|']
        for p in schema:
            default = 'not set' if p.default is None else '`%s`' % cell(shown(p.default))
            lines.append('| `%s` | %s | %s | %s | %s | %s |' % (
                p.name, type_name(p.default), default, bounds(p),
                'yes' if p.read_only else '', cell(p.description)))
    return '\n'.join(lines) + '\n'


def main(argv=None):
    """Write docs/parameters.md, or with ``--check`` say whether it is stale."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--check', action='store_true',
                        help='exit 1 if docs/parameters.md differs from the schemas')
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        with open(OUTPUT) as fh:
            stale = fh.read() != text
        if stale:
            print('docs/parameters.md is stale: run %s' % COMMAND, file=sys.stderr)
        return 1 if stale else 0
    with open(OUTPUT, 'w') as fh:
        fh.write(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
