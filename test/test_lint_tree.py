"""The ament linters over the Python outside the packages: tests, benchmarks, tools."""
import os

from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257_main
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DIRS = [os.path.join(ROOT, d) for d in ('test', 'bench', 'tools') if
        os.path.isdir(os.path.join(ROOT, d))]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8_outside_packages():
    rc, errors = main_with_errors(argv=DIRS)
    assert rc == 0, 'Found %d code style errors:\n' % len(errors) + '\n'.join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257_outside_packages():
    assert pep257_main(argv=DIRS) == 0, 'Found code style errors / warnings'
