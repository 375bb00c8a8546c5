"""
Every dependency a package.xml names is a rosdep key (``rosdep install`` resolves it).

A key is either a package of this workspace or one of ``rosdep_keys.txt``: the keys found
in ros/rosdistro (``rosdep/python.yaml`` for system and pip keys, ``jazzy/distribution.yaml``
for ROS packages), each with the file and line it was found at.
"""
import glob
import os
import re
import xml.etree.ElementTree as ET

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
KEYS_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'rosdep_keys.txt')
MANIFESTS = sorted(glob.glob(os.path.join(ROOT, 'src', '*', 'package.xml')))
NOT_KEYS = {'python3-mcap', 'python3-rosbags'}
"""Names that look like rosdep keys but are not in rosdistro."""


def _known_keys():
    keys = {}
    with open(KEYS_FILE) as f:
        for number, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith('#'):
                continue
            fields = line.split()
            assert len(fields) == 2 and re.fullmatch(
                r'(rosdep/python\.yaml|jazzy/distribution\.yaml):\d+', fields[1]), \
                'rosdep_keys.txt:%d: expected "<key> <rosdistro file>:<line>", got %r' % (
                    number, line)
            keys[fields[0]] = fields[1]
    return keys


def _workspace_packages():
    return {ET.parse(m).getroot().findtext('name') for m in MANIFESTS}


def _dependencies(manifest):
    root = ET.parse(manifest).getroot()
    return [(e.tag, (e.text or '').strip()) for e in root if e.tag.endswith('depend')]


def test_the_key_list_cites_its_rosdistro_source_and_holds_no_invented_key():
    with open(KEYS_FILE) as f:
        header = f.read()
    assert 'github.com/ros/rosdistro' in header and re.search(r'commit [0-9a-f]{40}', header)
    keys = _known_keys()
    assert keys and not NOT_KEYS & set(keys)


@pytest.mark.parametrize('manifest', MANIFESTS,
                         ids=[os.path.basename(os.path.dirname(m)) for m in MANIFESTS])
def test_every_depend_of_the_package_is_a_rosdep_key_or_a_workspace_package(manifest):
    known = set(_known_keys()) | _workspace_packages()
    unknown = ['<%s>%s' % (tag, key) for tag, key in _dependencies(manifest)
               if key not in known]
    assert not unknown, (
        '%s names keys rosdep does not know: %s (look the key up in ros/rosdistro '
        'rosdep/*.yaml or jazzy/distribution.yaml and add it to %s with its line)'
        % (os.path.relpath(manifest, ROOT), ', '.join(unknown),
           os.path.relpath(KEYS_FILE, ROOT)))
