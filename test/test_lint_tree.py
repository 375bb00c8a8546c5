"""The ament linters over the Python outside the packages: tests, benchmarks, tools."""
import os

from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257_main
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DIRS = [os.path.join(ROOT, d) for d in ('test', 'bench', 'tools') if
        os.path.isdir(os.path.join(ROOT, d))]


def _groups():
    """Return the flake8 runs: each folder of test/ alone, test/'s own files, bench, tools."""
    groups = {}
    for top in DIRS:
        if os.path.basename(top) != 'test':
            groups[os.path.basename(top)] = [top]
            continue
        files = []
        for name in sorted(os.listdir(top)):
            path = os.path.join(top, name)
            if os.path.isdir(path) and name != '__pycache__':
                groups['test/' + name] = [path]
            elif name.endswith('.py'):
                files.append(path)
        groups['test/*.py'] = files
    return groups


GROUPS = _groups()


@pytest.mark.flake8
@pytest.mark.linter
@pytest.mark.parametrize('group', sorted(GROUPS))
def test_flake8_outside_packages(group):
    # one run per group: the slowest linter of the suite spread over the xdist workers
    rc, errors = main_with_errors(argv=GROUPS[group])
    assert rc == 0, 'Found %d code style errors:\n' % len(errors) + '\n'.join(errors)


def test_the_flake8_groups_cover_every_python_file_outside_the_packages():
    grouped = set()
    for paths in GROUPS.values():
        for path in paths:
            if os.path.isdir(path):
                grouped.update(os.path.join(d, f) for d, _, fs in os.walk(path) for f in fs
                               if f.endswith('.py'))
            else:
                grouped.add(path)
    every = {os.path.join(d, f) for top in DIRS for d, _, fs in os.walk(top) for f in fs
             if f.endswith('.py')}
    assert every and every == grouped


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257_outside_packages():
    assert pep257_main(argv=DIRS) == 0, 'Found code style errors / warnings'
