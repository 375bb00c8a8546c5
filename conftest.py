"""
The ``dds`` marker, set on every test that needs DDS (``make test-fast`` runs the others).

A test is marked ``dds`` when it uses the ``procs`` or ``ros_node`` fixture (directly or
through another fixture), when it is marked ``ros`` (it needs the built workspace: it starts
node executables, ``fj`` or the README's commands), when its module starts an rclpy context
or node in the test process (``rclpy.init``, ``create_node``, ``Context()``), or when it
lives under a folder of multi-process tests (``test/graph``, ``test/nodes``,
``test/interfaces``). Everything
else (the core math, the schemas, the control loop, the structure and the linters) runs
without a participant: ``pytest -m 'not dds'`` (``make test-fast``). A new in-process test
of the loop under ``test/control`` or ``src/<pkg>/test`` is in the fast set without more.
"""
import os

import pytest

DDS_FIXTURES = frozenset(('procs', 'ros_node'))
"""Fixtures that start node processes or an rclpy node in the test process."""
DDS_SOURCE = ('rclpy.init(', 'create_node(', 'Context()')
"""Text in a test module that starts a participant in the test process."""
DDS_FOLDERS = (os.path.join('test', 'graph'), os.path.join('test', 'nodes'),
               os.path.join('test', 'interfaces'))
"""Folders (from the workspace root) of multi-process tests."""
ROOT = os.path.dirname(os.path.abspath(__file__))

_module_starts_dds = {}


def _starts_dds(path):
    """Return True if the module at ``path`` starts an rclpy participant itself."""
    if path not in _module_starts_dds:
        try:
            with open(path, encoding='utf-8') as fh:
                text = fh.read()
        except OSError:
            text = ''
        _module_starts_dds[path] = any(s in text for s in DDS_SOURCE)
    return _module_starts_dds[path]


def needs_dds(item):
    """Return True if the test ``item`` needs DDS (a participant or node processes)."""
    if DDS_FIXTURES.intersection(getattr(item, 'fixturenames', ())):
        return True
    if item.get_closest_marker('ros') is not None:
        return True
    path = str(item.path)
    rel = os.path.relpath(path, ROOT)
    if any(rel == f or rel.startswith(f + os.sep) for f in DDS_FOLDERS):
        return True
    return _starts_dds(path)


def pytest_configure(config):
    """Declare the ``dds`` marker."""
    config.addinivalue_line(
        'markers', 'dds: needs DDS: node processes or an rclpy participant in the test '
                   "(set by the root conftest; make test-fast runs -m 'not dds')")


def pytest_collection_modifyitems(config, items):
    """Mark every test that needs DDS with ``dds``."""
    for item in items:
        if needs_dds(item):
            item.add_marker(pytest.mark.dds)
