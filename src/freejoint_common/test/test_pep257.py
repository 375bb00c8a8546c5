# As `ros2 pkg create` generates it, made independent of the working directory.
import os

from ament_pep257.main import main
import pytest

PKG = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=[PKG])
    assert rc == 0, 'Found code style errors / warnings'
