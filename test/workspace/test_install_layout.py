"""The built install has what `ros2 run` and `ros2 pkg` look up on a full ROS 2 install."""
import os
import xml.etree.ElementTree as ET

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
INSTALL = os.path.join(ROOT, 'install')

# package -> the executables `ros2 run <package> <exe>` must find.
EXECUTABLES = {
    'freejoint_core': ['offline'],
    'freejoint_sim': ['sim_node'],
    'freejoint_planner': ['planner_node'],
    'freejoint_control': ['controller_node'],
    'freejoint_tools': ['recorder', 'player', 'analyze', 'fj'],
    'freejoint_bringup': ['graph'],
}
PACKAGES = sorted(EXECUTABLES) + ['freejoint_common', 'freejoint_msgs']


@pytest.mark.parametrize('pkg', PACKAGES)
def test_package_has_ament_index_marker_and_manifest(pkg):
    marker = os.path.join(INSTALL, pkg, 'share', 'ament_index', 'resource_index', 'packages',
                          pkg)
    assert os.path.isfile(marker), 'no ament index marker for %s: %s' % (pkg, marker)
    manifest = os.path.join(INSTALL, pkg, 'share', pkg, 'package.xml')
    assert ET.parse(manifest).getroot().findtext('name') == pkg


@pytest.mark.parametrize('pkg,exe', [(p, e) for p, exes in EXECUTABLES.items() for e in exes])
def test_ros2_run_finds_the_executable(pkg, exe):
    path = os.path.join(INSTALL, pkg, 'lib', pkg, exe)
    assert os.path.isfile(path) and os.access(path, os.X_OK), 'missing %s' % path


@pytest.mark.parametrize('pkg', PACKAGES)
def test_every_dependency_has_a_rosdep_key_in_package_xml(pkg):
    root = ET.parse(os.path.join(ROOT, 'src', pkg, 'package.xml')).getroot()
    deps = [e.text for e in root if e.tag.endswith('depend')]
    assert deps, '%s declares no dependencies' % pkg
    assert all(d and d.strip() == d and ' ' not in d for d in deps)
    if pkg not in ('freejoint_msgs', 'freejoint_core'):
        assert 'rclpy' in deps, '%s runs a node but does not depend on rclpy' % pkg
