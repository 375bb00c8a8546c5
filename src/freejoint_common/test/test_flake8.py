# As `ros2 pkg create` generates it, made independent of the working directory.
import os

from ament_flake8.main import main_with_errors
import pytest

PKG = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    rc, errors = main_with_errors(argv=[PKG])
    assert rc == 0, \
        'Found %d code style errors / warnings:\n' % len(errors) + \
        '\n'.join(errors)
