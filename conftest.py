"""
The ``dds`` and ``slow`` markers (``make test-fast`` runs the tests that have neither).

A test is marked ``dds`` when it uses the ``procs`` or ``ros_node`` fixture (directly or
through another fixture), when it is marked ``ros`` (it needs the built workspace: it starts
node executables, ``fj`` or the README's commands), when its module starts an rclpy context
or node in the test process (``rclpy.init``, ``create_node``, ``Context()``), or when it
lives under a folder of multi-process tests (``test/graph``, ``test/nodes``,
``test/interfaces``). A test is
marked ``slow`` when its module is in ``SLOW_MODULES``: no DDS, but whole closed-loop runs
or other programs run in subprocesses, tens of seconds each on 2 cores. Everything else
(the core math, the schemas, the control loop, the structure and the linters) is the fast
set: ``pytest -m 'not dds and not slow'`` (``make test-fast``, ``tools/test_fast.sh``). A new
in-process test, e.g. of the loop under ``test/control`` or ``src/<pkg>/test``, is in it
without more.
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
SLOW_MODULES = {
    'test/core/test_four_link_example.py': 'closed-loop runs of the 4-link example',
    'test/core/test_mujoco_plant.py': 'MuJoCo open- and closed-loop runs over the circle',
    'test/core/test_urdf_offline.py': 'the offline runner on URDF arms, both engines',
    'test/core/test_pin_plant.py': 'Pinocchio plant runs against the RK4 plant',
    'test/core/test_batch.py': 'batched closed-loop runs against their scalar runs',
    'src/freejoint_planner/test/test_spatial_planning.py':
        "the spatial planner's nominal closed-loop checks over whole circles",
    'test/tools/test_analyze.py': 'the analysis and its plots in subprocesses',
    'test/tools/test_old_layout.py': 'the analysis of old-layout bags in subprocesses',
    'test/tools/test_reindex.py': 'the reindex tool in subprocesses',
    'test/workspace/test_setup_errors.py': 'tools/setup.sh in subprocesses',
}
"""Modules of ``slow`` tests (workspace-relative path: why), run by ``make test`` only."""

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
    """Declare the ``dds`` and ``slow`` markers."""
    config.addinivalue_line(
        'markers', 'dds: needs DDS: node processes or an rclpy participant in the test '
                   '(set by the root conftest; make test-fast leaves it out)')
    config.addinivalue_line(
        'markers', 'slow: no DDS, but whole runs or programs in subprocesses (set by the '
                   'root conftest from SLOW_MODULES; make test-fast leaves it out)')


def pytest_collection_modifyitems(config, items):
    """Mark every test that needs DDS with ``dds``, every one of ``SLOW_MODULES`` ``slow``."""
    for item in items:
        if needs_dds(item):
            item.add_marker(pytest.mark.dds)
        rel = os.path.relpath(str(item.path), ROOT).replace(os.sep, '/')
        if rel in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def _lint_cache(request, monkeypatch):
    """
    With ``FREEJOINT_LINT_CACHE`` set (``make test-fast``): linters skip files found clean.

    Replaces, in a ``linter`` test's module, ament_flake8's ``main_with_errors`` and
    ament_pep257's ``main`` by the caching calls of ``test/lint_cache.py``.
    """
    folder = os.environ.get('FREEJOINT_LINT_CACHE')
    if not folder or request.node.get_closest_marker('linter') is None:
        return
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        'freejoint_lint_cache', os.path.join(ROOT, 'test', 'lint_cache.py'))
    cache = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cache)
    from ament_flake8.main import main_with_errors
    from ament_pep257.main import main as pep257_main
    module = request.module
    for name, value in list(vars(module).items()):
        if value is main_with_errors:
            monkeypatch.setattr(module, name, cache.cached_flake8(value, folder))
        elif value is pep257_main:
            monkeypatch.setattr(module, name, cache.cached_pep257(value, folder))
