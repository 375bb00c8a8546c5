"""The description package installs its URDFs where ROS tools look them up."""
import os
import xml.etree.ElementTree as ET

from freejoint_core.urdf import parse_urdf, SHIPPED
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARE = os.path.join(ROOT, 'install', 'freejoint_description', 'share', 'freejoint_description')


def test_description_package_has_ament_index_marker_and_manifest():
    marker = os.path.join(ROOT, 'install', 'freejoint_description', 'share', 'ament_index',
                          'resource_index', 'packages', 'freejoint_description')
    assert os.path.isfile(marker), marker
    manifest = os.path.join(SHARE, 'package.xml')
    assert ET.parse(manifest).getroot().findtext('name') == 'freejoint_description'


@pytest.mark.parametrize('name', SHIPPED)
def test_installed_urdf_is_the_source_urdf_and_parses(name):
    installed = os.path.join(SHARE, 'urdf', name + '.urdf')
    source = os.path.join(ROOT, 'src', 'freejoint_description', 'urdf', name + '.urdf')
    with open(installed, encoding='utf-8') as f:
        text = f.read()
    with open(source, encoding='utf-8') as f:
        assert f.read() == text
    assert parse_urdf(text).params.n >= 3
