"""Set-up says what colcon is doing: a line per package started and built, k of total."""
import os
import subprocess

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..')
AWK = os.path.join(ROOT, 'tools', 'colcon_progress.awk')

# What `colcon build --event-handlers console_direct- status- console_start_end+` prints
COLCON = """Starting >>> freejoint_core
Starting >>> freejoint_msgs
Finished <<< freejoint_core [2.41s]
--- stderr: freejoint_msgs
CMake Warning: something
---
Finished <<< freejoint_msgs [1min 52s]
Starting >>> freejoint_common
Failed   <<< freejoint_common [0.52s, exited with code 1]

Summary: 2 packages finished [1min 55s]
"""


def test_each_package_started_and_built_is_a_line_as_it_happens():
    out = subprocess.run(['awk', '-v', 'n=9', '-f', AWK], input=COLCON, text=True,
                         capture_output=True, check=True).stdout
    assert out.splitlines() == [
        '[setup] colcon: building freejoint_core',
        '[setup] colcon: building freejoint_msgs',
        '[setup] colcon: 1/9 built: freejoint_core [2.41s]',
        '[setup] colcon: 2/9 built: freejoint_msgs [1min 52s]',
        '[setup] colcon: building freejoint_common',
        '[setup] colcon: failed freejoint_common',
    ]


def test_setup_feeds_colcon_s_start_and_end_events_to_the_progress_lines():
    with open(os.path.join(ROOT, 'tools', 'setup.sh'), encoding='utf-8') as fh:
        text = fh.read()
    assert 'console_start_end+' in text
    assert '"${AWK[@]}" -v n="$total" -f "$ROOT/tools/colcon_progress.awk"' in text
    assert 'AWK=(awk -W interactive)' in text      # mawk: each line as it comes
