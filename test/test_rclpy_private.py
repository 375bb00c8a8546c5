"""
No rclpy private member is used by the project's code (src/, tools/, bench/).

rclpy's private names are read from the installed rclpy itself: every ``_name`` (not
``__dunder__``) its sources define or access as an attribute (``self._time_source``,
``clock._set_ros_time_is_active``, ``node._parameters``, ...). The project's code may not
access an attribute of such a name unless the project defines that name itself (an
attribute it assigns or a method it defines: ``self._clock`` of its own class); and a
class deriving from rclpy's ``Node`` may not assign a private attribute of rclpy's Node
(that would overwrite rclpy's own: ``self._clock = ...`` in a node replaces its clock); nor
import rclpy's private modules (``rclpy._rclpy_pybind11``, ``rclpy.impl``).
"""

import ast
import os

import pytest
import rclpy

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCANNED = ('src', 'tools', 'bench')


def private(name):
    return name.startswith('_') and not name.startswith('__')


def python_files(top):
    for base, dirs, files in os.walk(top):
        dirs[:] = [d for d in dirs if d not in ('build', 'install', 'log', '__pycache__')
                   and not d.startswith('.')]
        for name in files:
            if name.endswith('.py'):
                yield os.path.join(base, name)


def parse(path):
    with open(path, encoding='utf-8') as f:
        return ast.parse(f.read(), path)


def rclpy_private_names():
    """Return (every private name of rclpy, Node's private instance attributes)."""
    names, node_attrs = set(), set()
    for path in python_files(os.path.dirname(rclpy.__file__)):
        tree = parse(path)
        is_node = path.endswith(os.path.join('rclpy', 'node.py'))
        for n in ast.walk(tree):
            if isinstance(n, ast.Attribute) and private(n.attr):
                names.add(n.attr)
                if is_node and isinstance(n.value, ast.Name) and n.value.id == 'self':
                    node_attrs.add(n.attr)
            elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and private(n.name):
                names.add(n.name)
    return names, node_attrs


def assigned_self_attrs(cls):
    """Yield (name, line) of every ``self._x = ...`` inside class ``cls``."""
    for n in ast.walk(cls):
        targets = []
        if isinstance(n, ast.Assign):
            targets = n.targets
        elif isinstance(n, (ast.AugAssign, ast.AnnAssign)):
            targets = [n.target]
        for t in targets:
            for e in ast.walk(t):
                if (isinstance(e, ast.Attribute) and isinstance(e.value, ast.Name)
                        and e.value.id == 'self' and private(e.attr)):
                    yield e.attr, e.lineno


def project_trees(roots=SCANNED):
    trees = {}
    for top in roots:
        for path in python_files(os.path.join(ROOT, top)):
            trees[os.path.relpath(path, ROOT)] = parse(path)
    return trees


def project_definitions(trees):
    """Private names the project defines: methods, assigned attributes, class names."""
    defined = set()
    for tree in trees.values():
        for n in ast.walk(tree):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                defined.add(n.name)
            elif isinstance(n, ast.ClassDef):
                defined.update(name for name, _ in assigned_self_attrs(n))
            elif isinstance(n, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
                targets = n.targets if isinstance(n, ast.Assign) else [n.target]
                for t in targets:
                    for e in ast.walk(t):
                        if isinstance(e, ast.Attribute):
                            defined.add(e.attr)
                        elif isinstance(e, ast.Name):
                            defined.add(e.id)
    return {name for name in defined if private(name)}


def node_subclasses(tree):
    for n in ast.walk(tree):
        if isinstance(n, ast.ClassDef) and any(
                (isinstance(b, ast.Name) and b.id == 'Node')
                or (isinstance(b, ast.Attribute) and b.attr == 'Node') for b in n.bases):
            yield n


def violations(trees, rclpy_names, node_attrs):
    """Return 'path:line: text' of each rclpy private member used by ``trees``."""
    forbidden = rclpy_names - project_definitions(trees)
    found = []
    for path, tree in sorted(trees.items()):
        for n in ast.walk(tree):
            if isinstance(n, ast.Attribute) and n.attr in forbidden:
                found.append('%s:%d: .%s (rclpy private)' % (path, n.lineno, n.attr))
            elif (isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
                    and n.func.id in ('getattr', 'hasattr', 'setattr') and len(n.args) > 1
                    and isinstance(n.args[1], ast.Constant) and n.args[1].value in forbidden):
                found.append('%s:%d: %s(..., %r) (rclpy private)'
                             % (path, n.lineno, n.func.id, n.args[1].value))
            if isinstance(n, (ast.Import, ast.ImportFrom)):
                modules = ([a.name for a in n.names] if isinstance(n, ast.Import)
                           else [n.module or ''])
                for module in modules:
                    parts = module.split('.')
                    if parts[0] == 'rclpy' and any(private(x) or x == 'impl'
                                                   for x in parts[1:]):
                        found.append('%s:%d: import of %s (rclpy private module)'
                                     % (path, n.lineno, module))
        for cls in node_subclasses(tree):
            for name, line in assigned_self_attrs(cls):
                if name in node_attrs:
                    found.append('%s:%d: %s assigns self.%s, a private attribute of rclpy '
                                 'Node' % (path, line, cls.name, name))
    return sorted(set(found))


@pytest.fixture(scope='module')
def rclpy_names():
    return rclpy_private_names()


def test_rclpy_private_names_are_found_in_the_installed_rclpy(rclpy_names):
    names, node_attrs = rclpy_names
    assert {'_time_source', '_set_ros_time_is_active', '_parameters'} <= names
    assert {'_time_source', '_clock', '_parameters'} <= node_attrs


def test_no_rclpy_private_member_is_used_in_src_tools_or_bench(rclpy_names):
    found = violations(project_trees(), *rclpy_names)
    assert not found, 'rclpy private members used:\n' + '\n'.join(found)


def test_the_rule_catches_private_access_getattr_clobbered_node_attribute_private_module(
        rclpy_names):
    source = (
        'from rclpy.node import Node\n'
        'class Planner(Node):\n'
        '    def __init__(self):\n'
        '        self._clock = None\n'
        '        self._own = 1\n'
        '        self._time_source.detach_node()\n'
        '        getattr(self, "_set_ros_time_is_active")\n'
        '        self._own += 1\n'
        'from rclpy.impl.implementation_singleton import rclpy_implementation\n')
    found = violations({'example.py': ast.parse(source)}, *rclpy_names)
    assert found == [
        'example.py:4: Planner assigns self._clock, a private attribute of rclpy Node',
        'example.py:6: ._time_source (rclpy private)',
        "example.py:7: getattr(..., '_set_ros_time_is_active') (rclpy private)",
        'example.py:9: import of rclpy.impl.implementation_singleton (rclpy private module)',
    ]
