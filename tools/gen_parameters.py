"""
Write the parameter tables of the docs from the schemas: docs/parameters.md and docs/GRAPH.md.

The schemas (``src/<pkg>/<pkg>/params.py``, entries shared by nodes in
``freejoint_common/schema.py``) are the one place of a parameter's default, range,
read-only flag and description; this renders them as one table per node in
docs/parameters.md, and fills every table of docs/GRAPH.md between a
``<!-- schema-table <node>: <name> ... -->`` line and ``<!-- end schema-table -->`` with
the rows of those parameters. Run it after changing a schema
(test/tools/test_parameter_schemas.py fails while a file is stale):

    python tools/gen_parameters.py            # rewrite docs/parameters.md, docs/GRAPH.md
    python tools/gen_parameters.py --check    # exit 1 if either is stale
"""
import argparse
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUTPUT = os.path.join(ROOT, 'docs', 'parameters.md')
GRAPH = os.path.join(ROOT, 'docs', 'GRAPH.md')
TABLE = re.compile(r'(<!-- schema-table (\S+): ([^>]*?) -->\n)(.*?)(<!-- end schema-table -->)',
                   re.S)
"""A generated table of docs/GRAPH.md: its opening line (node, names), body, closing line."""
COMMAND = 'python tools/gen_parameters.py'


def nodes():
    """Return (node, executable, schema file, params file or None, Schema) of every node."""
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    from freejoint_tools.params import PLAYER, RECORDER, VIEWER
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
        ('viewer', 'freejoint_tools viewer', 'src/freejoint_tools/freejoint_tools/params.py',
         None, VIEWER),
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
        lines += [row(p) for p in schema]
    return '\n'.join(lines) + '\n'


def row(p):
    """Return the table row of the entry ``p``."""
    default = 'not set' if p.default is None else '`%s`' % cell(shown(p.default))
    return '| `%s` | %s | %s | %s | %s | %s |' % (
        p.name, type_name(p.default), default, bounds(p), 'yes' if p.read_only else '',
        cell(p.description))


def render_graph(text):
    """Return docs/GRAPH.md's ``text`` with each schema table filled from its schema."""
    schemas = {node: schema for node, _, _, _, schema in nodes()}

    def table(match):
        node, names = match.group(2), match.group(3).split()
        unknown = [n for n in names if node not in schemas or n not in schemas[node]]
        if unknown:
            raise SystemExit('docs/GRAPH.md: %s has no parameter %s' % (node, unknown[0]))
        body = ['| name | type | default | range | read-only | description |',
                '|---|---|---|---|---|---|'] + [row(schemas[node][n]) for n in names]
        return match.group(1) + '\n'.join(body) + '\n' + match.group(5)
    return TABLE.sub(table, text)


def outputs():
    """Return ``{path: generated text}`` of every file the generator writes."""
    with open(GRAPH) as fh:
        graph = fh.read()
    return {OUTPUT: render(), GRAPH: render_graph(graph)}


def main(argv=None):
    """Write docs/parameters.md and docs/GRAPH.md, or with ``--check`` say if one is stale."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--check', action='store_true',
                        help='exit 1 if docs/parameters.md or docs/GRAPH.md differs from '
                        'the schemas')
    args = parser.parse_args(argv)
    stale = False
    for path, text in outputs().items():
        with open(path) as fh:
            same = fh.read() == text
        if args.check and not same:
            stale = True
            print('%s is stale: run %s' % (os.path.relpath(path, ROOT), COMMAND),
                  file=sys.stderr)
        elif not args.check and not same:
            with open(path, 'w') as fh:
                fh.write(text)
    return 1 if stale else 0


if __name__ == '__main__':
    sys.exit(main())
