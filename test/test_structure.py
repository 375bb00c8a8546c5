"""
Structure of the packages' Python: no import cycle, no private name taken across packages.

The import graph is built from the source text (``ast``) of every module under
``src/<package>/<package>/``: every ``import`` and ``from ... import`` statement counts,
those inside functions too (a lazy import hides a cycle from Python but not from here),
relative ones resolved against the importing module's package.  Only imports of the
project's own modules are edges.
"""
import ast
import functools
import os
import xml.etree.ElementTree as ET

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC = os.path.join(ROOT, 'src')


def package_modules(src):
    """Return ``{dotted module name: file path}`` for every ``src/<pkg>/<pkg>/*.py``."""
    modules = {}
    for pkg in sorted(os.listdir(src)):
        folder = os.path.join(src, pkg, pkg)
        if not os.path.isdir(folder):
            continue
        for name in sorted(os.listdir(folder)):
            if name.endswith('.py'):
                stem = name[:-3]
                dotted = pkg if stem == '__init__' else f'{pkg}.{stem}'
                modules[dotted] = os.path.join(folder, name)
    return modules


def _package_of(module, modules):
    """Return the package a relative import in ``module`` starts from."""
    path = modules[module]
    return module if path.endswith('__init__.py') else module.rpartition('.')[0]


@functools.lru_cache(maxsize=None)
def parse(path):
    """Return the ``ast`` tree of the file at ``path``, parsed once per test process."""
    with open(path, encoding='utf-8') as fh:
        return ast.parse(fh.read(), filename=path)


@functools.lru_cache(maxsize=None)
def import_nodes(path):
    """Return the ``Import`` and ``ImportFrom`` nodes of the file at ``path``, in walk order."""
    return tuple(node for node in ast.walk(parse(path))
                 if isinstance(node, (ast.Import, ast.ImportFrom)))


def imports(module, modules):
    """
    Yield ``(target, names, node)`` for each import of a project module in ``module``.

    ``target`` is the project module imported; ``names`` the names taken from it by a
    ``from target import ...`` (empty for ``import target``); ``node`` the ast node.
    """
    for node in import_nodes(modules[module]):
        if isinstance(node, ast.Import):
            for alias in node.names:
                name = alias.name
                while name and name not in modules:
                    name = name.rpartition('.')[0]
                if name:
                    yield name, (), node
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = _package_of(module, modules)
                for _ in range(node.level - 1):
                    base = base.rpartition('.')[0]
                base = '.'.join(p for p in (base, node.module) if p)
            else:
                base = node.module
            taken = []
            for alias in node.names:
                sub = f'{base}.{alias.name}'
                if sub in modules:
                    yield sub, (), node     # from package import module
                else:
                    taken.append(alias.name)
            if taken and base in modules:
                yield base, tuple(taken), node


def import_graph(modules):
    """Return ``{module: set of project modules it imports}``."""
    return {m: {t for t, _, _ in imports(m, modules) if t != m} for m in modules}


def cycles(graph):
    """Return the strongly connected components of ``graph`` with more than one module."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def private_imports_across_packages(modules):
    """
    Return the private names a module takes from another package, one string each.

    Counts ``from other import _name`` and ``other._name`` on a module of another package
    imported as a name; each entry reads ``'module:line takes other.module._name'``.
    """
    found = []
    for module, path in modules.items():
        pkg = module.split('.')[0]
        tree = parse(path)
        bound = {}      # local name -> project module of another package
        for target, names, node in imports(module, modules):
            if target.split('.')[0] == pkg:
                continue
            for name in names:
                if name.startswith('_'):
                    found.append(f'{module}:{node.lineno} takes {target}.{name}')
            for alias in node.names if not names else ():
                if isinstance(node, ast.ImportFrom) and target.endswith('.' + alias.name):
                    bound[alias.asname or alias.name] = target
                elif isinstance(node, ast.Import) and alias.asname and alias.name == target:
                    bound[alias.asname] = target
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in bound and node.attr.startswith('_')
                    and not node.attr.startswith('__')):
                found.append(f'{module}:{node.lineno} takes {bound[node.value.id]}.{node.attr}')
    return found


def package_dependencies(modules, src):
    """
    Return ``{package: (project packages imported, project packages declared)}``.

    Imported: the packages of the modules its modules import (function-level imports
    included). Declared: the ``*depend`` entries of its ``package.xml`` naming a Python
    package of ``src``.
    """
    packages = {m.split('.')[0] for m in modules}
    out = {}
    for pkg in sorted(packages):
        imported = set()
        for module in (m for m in modules if m.split('.')[0] == pkg):
            imported |= {t.split('.')[0] for t, _, _ in imports(module, modules)}
        root = ET.parse(os.path.join(src, pkg, 'package.xml')).getroot()
        declared = {e.text.strip() for e in root if e.tag.endswith('depend') and e.text}
        out[pkg] = (imported & packages - {pkg}, declared & packages)
    return out


def _write(root, files):
    for rel, text in files.items():
        path = os.path.join(root, rel)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, 'w', encoding='utf-8') as fh:
            fh.write(text)


def test_the_package_modules_are_found():
    modules = package_modules(SRC)
    assert 'freejoint_core.arm' in modules and 'freejoint_tools.recorder' in modules
    assert len(modules) > 30


def test_no_package_module_imports_itself_back_through_a_cycle():
    modules = package_modules(SRC)
    found = cycles(import_graph(modules))
    assert not found, 'import cycles (each line one set of modules importing each other):\n' \
        + '\n'.join(' <-> '.join(c) for c in found)


def test_no_package_module_takes_a_private_name_of_another_package():
    found = private_imports_across_packages(package_modules(SRC))
    assert not found, 'private names taken across packages:\n' + '\n'.join(found)


def test_the_demo_and_bench_scripts_take_no_private_name_of_a_package():
    modules = package_modules(SRC)
    for folder in ('tools', 'bench'):
        for name in sorted(os.listdir(os.path.join(ROOT, folder))):
            if name.endswith('.py'):
                modules[f'{folder}.{name[:-3]}'] = os.path.join(ROOT, folder, name)
    found = [f for f in private_imports_across_packages(modules)
             if f.startswith(('tools.', 'bench.'))]
    assert not found, 'private names of packages taken by scripts:\n' + '\n'.join(found)


def test_each_package_declares_exactly_the_project_packages_it_imports():
    wrong = []
    for pkg, (imported, declared) in package_dependencies(package_modules(SRC), SRC).items():
        if imported - declared:
            wrong.append(f'{pkg} imports {sorted(imported - declared)} without declaring them')
        if declared - imported:
            wrong.append(f'{pkg} declares {sorted(declared - imported)} but imports none of it')
    assert not wrong, 'package.xml out of step with the imports:\n' + '\n'.join(wrong)


def test_a_cycle_hidden_in_a_function_level_import_is_found(tmp_path):
    _write(tmp_path, {
        'pa/pa/__init__.py': '',
        'pa/pa/a.py': 'from pa.b import B\n',
        'pa/pa/b.py': 'B = 1\n\n\ndef make():\n    from . import a\n    return a\n',
        'pa/pa/c.py': 'import pa.a\n',
    })
    modules = package_modules(str(tmp_path))
    assert import_graph(modules)['pa.b'] == {'pa.a'}
    assert cycles(import_graph(modules)) == [['pa.a', 'pa.b']]


def test_a_private_name_taken_across_packages_is_found_but_not_inside_a_package(tmp_path):
    _write(tmp_path, {
        'pa/pa/__init__.py': '',
        'pa/pa/a.py': '_x = 1\n_y = 2\n',
        'pa/pa/b.py': 'from pa.a import _x\n',
        'pb/pb/__init__.py': '',
        'pb/pb/c.py': 'from pa.a import _x\n',
        'pb/pb/d.py': 'def f():\n    from pa import a\n    return a._y + a.__name__\n',
    })
    found = private_imports_across_packages(package_modules(str(tmp_path)))
    assert found == ['pb.c:1 takes pa.a._x', 'pb.d:3 takes pa.a._y']


def test_an_undeclared_and_an_unused_project_dependency_are_found(tmp_path):
    manifest = '<package format="3"><name>{0}</name>{1}</package>'
    _write(tmp_path, {
        'pa/package.xml': manifest.format('pa', ''),
        'pa/pa/__init__.py': '',
        'pb/package.xml': manifest.format('pb', '<exec_depend>pc</exec_depend>'),
        'pb/pb/__init__.py': '',
        'pb/pb/b.py': 'def f():\n    import pa\n',
        'pc/package.xml': manifest.format('pc', ''),
        'pc/pc/__init__.py': '',
    })
    deps = package_dependencies(package_modules(str(tmp_path)), str(tmp_path))
    assert deps['pb'] == ({'pa'}, {'pc'})


@pytest.mark.parametrize('source, level', [('from .errors import E\n', 1),
                                           ('from freejoint_core.errors import E\n', 0)])
def test_relative_and_absolute_imports_resolve_to_the_same_module(tmp_path, source, level):
    _write(tmp_path, {
        'freejoint_core/freejoint_core/__init__.py': '',
        'freejoint_core/freejoint_core/errors.py': 'E = 1\n',
        'freejoint_core/freejoint_core/user.py': source,
    })
    modules = package_modules(str(tmp_path))
    [(target, names, node)] = imports('freejoint_core.user', modules)
    assert (target, names, node.level) == ('freejoint_core.errors', ('E',), level)
