"""
The project's Fast DDS profile (config/fastdds.xml): accepted by Fast DDS, used by the shell.

Fast DDS reports a bad XML profile only in its log output (``XMLPARSER Error``, on stdout
with these wheels; other errors there, e.g. a stale shared-memory port a killed process
left in /dev/shm, are not the profile's) and then runs on its defaults, so a typo in the
file would silently undo it: the first test loads the shipped file in a node process and
fails on any XML error; the second shows that the check sees one. What the profile buys
(a restarted controller's first command, a killed node forgotten) is measured by
``bench/scenarios.py controller_restart`` (docs/performance.md). The profile
``controller_supervisor`` derives for its children (UDPv4 only: a killed child leaves no
shared-memory port locked) is checked the same way, and that its process maps no Fast DDS
shared memory.
"""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROFILE = os.path.join(ROOT, 'config', 'fastdds.xml')
NODE = ('import rclpy\n'
        'rclpy.init()\n'
        'node = rclpy.create_node("profile_probe")\n'
        'print("names", node.get_node_names())\n'
        'print("shm", sorted({ln.split()[-1] for ln in open("/proc/self/maps")\n'
        '                     if "/dev/shm/fastrtps" in ln}))\n'
        'node.destroy_node()\n'
        'rclpy.shutdown()\n')


def run_node(profile, **env_updates):
    """Run a node process with ``profile`` as the default profiles file: (code, output)."""
    env = dict(os.environ)
    env.pop('FASTDDS_DEFAULT_PROFILES_FILE', None)
    env['FASTRTPS_DEFAULT_PROFILES_FILE'] = profile
    env.update(env_updates)
    done = subprocess.run([sys.executable, '-c', NODE], env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=60)
    return done.returncode, done.stdout


def test_the_shipped_fastdds_profile_is_accepted_without_an_xml_error():
    code, output = run_node(PROFILE)
    assert code == 0, output
    assert 'profile_probe' in output
    assert 'XMLPARSER' not in output, output


def test_a_profile_with_an_unknown_element_is_reported_in_the_log(tmp_path):
    with open(PROFILE) as f:
        text = f.read()
    assert '<leaseDuration>' in text
    bad = tmp_path / 'bad.xml'
    bad.write_text(text.replace('<leaseDuration>', '<leaseDurationX>').replace(
        '</leaseDuration>', '</leaseDurationX>'))
    code, output = run_node(str(bad))
    assert 'XMLPARSER' in output and 'leaseDurationX' in output, output


def test_env_sh_points_fast_dds_at_the_profile_unless_one_is_chosen():
    env = {k: v for k, v in os.environ.items()
           if k not in ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')}
    show = ('. tools/env.sh --no-install && echo "$FASTRTPS_DEFAULT_PROFILES_FILE" '
            '"$FASTDDS_DEFAULT_PROFILES_FILE"')
    out = subprocess.run(['bash', '-c', show], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=30).stdout.split()
    assert out == [PROFILE, PROFILE]
    env['FASTRTPS_DEFAULT_PROFILES_FILE'] = '/somewhere/mine.xml'
    out = subprocess.run(['bash', '-c', show], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=30).stdout.split()
    assert out == ['/somewhere/mine.xml']


def _shm_mapped(output):
    line = next(ln for ln in output.splitlines() if ln.startswith('shm '))
    return line != 'shm []'


def test_the_supervisors_children_profile_is_accepted_and_maps_no_shared_memory(tmp_path):
    from freejoint_control.supervisor import udp_environment
    environ = {'FASTRTPS_DEFAULT_PROFILES_FILE': PROFILE,
               'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    updates = udp_environment(environ, str(tmp_path))
    # LOCALHOST makes rmw_fastrtps add a shared-memory transport of its own: the children
    # get SUBNET with the static peer 127.0.0.1, their UDPv4 bound to 127.0.0.1.
    assert updates['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'
    assert updates['ROS_STATIC_PEERS'] == '127.0.0.1'
    assert updates['FASTDDS_DEFAULT_PROFILES_FILE'] == updates['FASTRTPS_DEFAULT_PROFILES_FILE']
    child = updates.pop('FASTRTPS_DEFAULT_PROFILES_FILE')
    code, output = run_node(child, **updates)
    assert code == 0, output
    assert 'XMLPARSER' not in output, output
    assert not _shm_mapped(output), output
    # The control: the shipped profile under LOCALHOST maps Fast DDS shared memory.
    code, output = run_node(PROFILE, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    assert code == 0 and _shm_mapped(output), output


def test_the_childrens_profile_keeps_discovery_and_drops_only_shared_memory():
    from xml.etree import ElementTree
    from freejoint_control.supervisor import udp_profile
    with open(PROFILE) as f:
        text = f.read()
    ns = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'
    for loopback in (False, True):
        out = udp_profile(text, loopback)
        assert out.startswith('<profiles xmlns="http://www.eprosima.com/XMLSchemas/'), out
        root, shipped = ElementTree.fromstring(out), ElementTree.fromstring(text)
        kinds = [d.find(ns + 'type').text for d in root.iter(ns + 'transport_descriptor')]
        assert kinds == ['UDPv4']
        refs = [t.text for t in next(root.iter(ns + 'userTransports'))]
        assert refs == ['freejoint_udp'], out
        assert next(root.iter(ns + 'useBuiltinTransports')).text == 'false'
        allowed = [a.text for a in root.iter(ns + 'address')]
        assert allowed == (['127.0.0.1'] if loopback else [])
        assert (ElementTree.tostring(next(root.iter(ns + 'discovery_config')))
                == ElementTree.tostring(next(shipped.iter(ns + 'discovery_config'))))
    # Without a profile: one UDPv4 transport of its own, the default participant's.
    root = ElementTree.fromstring(udp_profile(None, False))
    assert [d.find(ns + 'type').text for d in root.iter(ns + 'transport_descriptor')] == [
        'UDPv4']
    assert next(root.iter(ns + 'participant')).get('is_default_profile') == 'true'


def test_a_broken_profile_stops_the_supervisor_with_its_name(tmp_path):
    from freejoint_control.supervisor import udp_environment
    bad = tmp_path / 'broken.xml'
    bad.write_text('<profiles><participant>')
    with pytest.raises(ValueError, match='Fast DDS profile .*broken.xml: not a Fast DDS '
                       'profiles file'):
        udp_environment({'FASTRTPS_DEFAULT_PROFILES_FILE': str(bad)}, str(tmp_path))
    with pytest.raises(OSError, match='Fast DDS profile /nonexistent.xml: No such file'):
        udp_environment({'FASTDDS_DEFAULT_PROFILES_FILE': '/nonexistent.xml'},
                        str(tmp_path))


def test_under_another_rmw_the_children_keep_their_environment(tmp_path):
    from freejoint_control.supervisor import udp_environment
    environ = {'FASTRTPS_DEFAULT_PROFILES_FILE': PROFILE,
               'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    assert udp_environment(dict(environ, RMW_IMPLEMENTATION='rmw_cyclonedds_cpp'),
                           str(tmp_path)) == {}
    assert os.listdir(tmp_path) == []
    # Fast DDS named or by default (Jazzy's): the children's profile.
    for rmw in ('rmw_fastrtps_cpp', ''):
        assert udp_environment(dict(environ, RMW_IMPLEMENTATION=rmw), str(tmp_path))[
            'ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'
