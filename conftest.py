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
import functools
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
SLOW_TESTS = {
    'test/core/test_failure.py::'
    'test_damping_the_freed_link_in_the_rests_slows_its_revolutions_and_leaves_the_circle':
        'two 12-s offline runs of the freed link, damped and not',
    'test/control/test_failures.py::'
    'test_the_freed_link_is_damped_in_the_rest_after_the_failure_as_offline_bit_for_bit':
        'the loop over 6 s against two 6-s offline runs of the freed link',
    'test/control/test_failures.py::'
    'test_joint3_failure_is_found_by_the_residual_the_law_switches_as_offline_bit_for_bit'
    '[vertical]': 'the vertical case (the horizontal one stays in test-fast)',
    'test/control/test_internal_motion_loop.py::'
    'test_the_loop_with_damping_commands_what_the_offline_circles_run_does_bit_for_bit[2.0]':
        'the second damping (0.5 stays in test-fast)',
    'test/core/test_internal_motion.py::'
    'test_the_horizontal_stabilised_options_settle_the_free_rotor_in_the_rests':
        'offline circles with rests (the loop against the offline settle stays in test-fast)',
    'test/core/test_arm_init.py::'
    'test_init_then_the_twin_runs_the_jaco_within_its_bound_for_half_a_second':
        "fj arm init's search, then the Jaco's twin over half a second",
    'src/freejoint_planner/test/test_plan_goal.py::'
    'test_a_plan_paused_for_an_arm_braked_at_once_resumes_from_where_the_arm_stopped':
        'a paused and resumed plan run through the circle',
    'src/freejoint_planner/test/test_after_failure.py::'
    'test_joint2_free_runs_away_in_both_cases_and_joint3_free_is_held':
        'closed-loop runs of both failures in both cases',
    'src/freejoint_planner/test/test_from_rest.py::'
    'test_a_transition_into_the_semi_singular_region_is_refused_naming_the_arms_position':
        "the transition's path check from many rest positions",
    'test/core/test_delay.py::'
    'test_delay_study_rows_summarise_the_runs_and_zero_delay_is_the_paper_run':
        "the delay study's closed-loop runs",
    'test/core/test_singularity_nlink.py::'
    'test_path_check_on_the_four_link_example_circle_conservative_refuses_sampled_accepts':
        "the four-link circle's path check, both ways, over the whole circle",
    'test/core/test_trajectory.py::'
    'test_repeated_circle_is_the_offline_circles_runners_setpoint_tick_by_tick':
        'every tick of the repeated circles',
    'test/core/test_guards.py::'
    'test_kept_by_a_driver_through_bursts_of_missed_states_the_damped_hold_keeps_the_arm'
    '[horizontal]': 'the horizontal case (the vertical one stays in test-fast)',
    'test/control/test_failures.py::'
    'test_the_fully_actuated_config_drives_all_three_joints_with_nullspace_damping':
        'a closed-loop run of the fully actuated arm',
    'test/tools/test_campaign.py::'
    'test_the_report_prints_the_summary_and_draws_a_heatmap_per_pair_of_axes':
        "the campaign report's plots (matplotlib)",
    'test/tools/test_campaign.py::'
    'test_the_paper_arms_urdf_as_a_campaign_arm_gives_the_table_i_campaigns_results':
        "a campaign on the paper arm's URDF (the spatial arm's campaign stays in test-fast)",
    'test/tools/test_spatial_map_cli.py::test_two_worker_processes_write_the_same_map_as_one':
        'worker processes (one and two workers in one process stay in test-fast)',
    'test/control/test_takeover.py::'
    'test_a_spare_activated_after_a_kill_mid_circle_tracks_within_2_s[0.25-vertical]':
        'the braked takeover the watchdog test also runs in test-fast',
    'test/control/test_takeover.py::'
    'test_a_spare_activated_after_a_kill_mid_circle_tracks_within_2_s[0.25-horizontal]':
        'a middle gap (0.03 s and 1 s stay in test-fast)',
    'test/control/test_takeover.py::'
    'test_a_spare_activated_after_a_kill_mid_circle_tracks_within_2_s[1.0-horizontal]':
        'the horizontal case of the longest gap (the vertical stays in test-fast)',
    'test/core/test_law_path.py::'
    'test_the_laws_from_the_literature_track_the_paper_circle_offline[vertical-vsc]':
        'the vertical case (the horizontal stays in test-fast)',
    'test/core/test_law_path.py::'
    'test_the_laws_from_the_literature_track_the_paper_circle_offline[vertical-tdc]':
        'the vertical case (the horizontal stays in test-fast)',
    'test/core/test_control.py::'
    'test_sigma_modification_keeps_theta_nonnegative_with_a_large_step[False]':
        '2000 ticks of the general path (the fast path stays in test-fast)',
}
"""Single ``slow`` tests (``path::name``, with ``[parameters]`` for one case: why): whole
closed-loop runs (0.4-4.5 CPU-s each), run by ``make test`` only; where a check
of the same path stays in ``make test-fast``, the entry says which."""

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
    """Mark tests needing DDS ``dds``, those of ``SLOW_MODULES`` and ``SLOW_TESTS`` ``slow``."""
    for item in items:
        if needs_dds(item):
            item.add_marker(pytest.mark.dds)
        rel = os.path.relpath(str(item.path), ROOT).replace(os.sep, '/')
        if rel in SLOW_MODULES or f'{rel}::{item.name}' in SLOW_TESTS or \
                f'{rel}::{getattr(item, "originalname", item.name)}' in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def _flake8_serial(request, monkeypatch):
    """
    A ``linter`` test runs flake8 in its own process, not in a forked pool.

    flake8 forks a ``multiprocessing`` pool of the test worker, which has rclpy's DDS
    threads, numba and Pinocchio loaded: a forked child segfaulted while collecting
    garbage and the pool waited for its result until pytest's timeout (a clean-clone CI
    run). The workers already keep the cores busy; serial costs nothing here.
    """
    if request.node.get_closest_marker('linter') is None:
        return
    import flake8.checker
    monkeypatch.setattr(flake8.checker, '_try_initialize_processpool', lambda *a, **k: None)


@functools.lru_cache(maxsize=None)
def _lint_cache_module():
    """Load ``test/lint_cache.py`` once per process (its linter keys are cached in it)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        'freejoint_lint_cache', os.path.join(ROOT, 'test', 'lint_cache.py'))
    cache = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cache)
    return cache


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
    cache = _lint_cache_module()
    from ament_flake8.main import main_with_errors
    from ament_pep257.main import main as pep257_main
    module = request.module
    for name, value in list(vars(module).items()):
        if value is main_with_errors:
            monkeypatch.setattr(module, name, cache.cached_flake8(value, folder))
        elif value is pep257_main:
            monkeypatch.setattr(module, name, cache.cached_pep257(value, folder))
