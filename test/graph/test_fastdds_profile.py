"""
The project's Fast DDS profile (config/fastdds.xml): accepted by Fast DDS, used by the shell.

Fast DDS reports a bad XML profile only in its log output (``XMLPARSER Error``, on stdout
with these wheels) and then runs on its defaults, so a typo in the file would silently undo
it: the first test loads the shipped file in a node process and fails on any XML error; the
second shows that the check sees one. What the profile buys (a restarted controller's
first command, a killed node forgotten) is measured by ``bench/scenarios.py
controller_restart`` (docs/performance.md).
"""

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROFILE = os.path.join(ROOT, 'config', 'fastdds.xml')
NODE = ('import rclpy\n'
        'rclpy.init()\n'
        'node = rclpy.create_node("profile_probe")\n'
        'print("names", node.get_node_names())\n'
        'node.destroy_node()\n'
        'rclpy.shutdown()\n')


def run_node(profile):
    """Run a node process with ``profile`` as the default profiles file: (code, output)."""
    env = dict(os.environ)
    env.pop('FASTDDS_DEFAULT_PROFILES_FILE', None)
    env['FASTRTPS_DEFAULT_PROFILES_FILE'] = profile
    done = subprocess.run([sys.executable, '-c', NODE], env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=60)
    return done.returncode, done.stdout


def test_the_shipped_fastdds_profile_is_accepted_without_an_xml_error():
    code, output = run_node(PROFILE)
    assert code == 0, output
    assert 'profile_probe' in output
    assert 'XMLPARSER' not in output and 'Error' not in output, output


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
