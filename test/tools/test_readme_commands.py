"""
Every command line of the install sections the README points to, run as the user types it.

The sections "On a full ROS 2 Jazzy install" and "Without ROS installed (ROS 2 from PyPI)"
(docs/ros-install.md), "The controller on ros2_control's topics" (docs/real-arm.md, run
after the Jazzy section, as it continues it) and "Bring your own arm" (docs/own-arm.md; its
``my_arm.urdf``: a copy of the shipped paper arm's URDF) are read, their ```bash blocks
split into commands, and each is run in order in a scratch directory (``config/`` linked
in, its ``sim.yaml`` with ``max_steps`` added: a lockstep graph started by hand steps on
after its circle as fast as it can, docs/hand_run.md, and would spend the suite's CPU for
the rest of the test; the lines are what is tested), under ``. tools/env.sh``:

- a node's start (``ros2 run <pkg> <exe> ...``, ``fj run ...`` or the bare executable) is
  started in the background and must come up (its parameter services answer); a block
  that starts nodes first stops those of the blocks before (the real-arm block replaces
  the simulated graph);
- ``ros2 param|service|node|topic ...`` runs as ``fj ...`` with the same arguments (there
  is no ros2cli here: the test is that the syntax is the same); ``fj ...`` as written;
  each must exit 0, a line marked ``refused`` exit 1 with the node's reason, a line
  marked ``until success: true`` is repeated until its answer says so;
- what cannot run without a full ROS install (``source /opt/ros/...``, ``rosdep``,
  ``colcon``, ``ros2 bag``) must be in ``COVERED``: the test that checks what it relies
  on. A line the test does not know fails it.
"""
import os
import re
import shlex
import shutil
import signal
import subprocess
import time

from freejoint_tools.harness import ParameterCalls
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
README = os.path.join(ROOT, 'README.md')
ROS_INSTALL = os.path.join(ROOT, 'docs', 'ros-install.md')
REAL_ARM = os.path.join(ROOT, 'docs', 'real-arm.md')
OWN_ARM_DOC = os.path.join(ROOT, 'docs', 'own-arm.md')
NODE_NAMES = {'sim_node': '/sim_node', 'planner_node': '/freejoint_planner',
              'controller_node': '/controller_node', 'recorder': '/recorder'}
"""Executable -> the node it starts."""
COVERED = {
    'source /opt/ros/jazzy/setup.bash': 'test/workspace/test_install_layout.py',
    'source install/setup.bash': 'test/workspace/test_install_layout.py',
    'rosdep install': 'test/workspace/test_rosdep_keys.py',
    'colcon build': 'test/workspace/test_install_layout.py',
    'ros2 bag info': 'test/tools/test_bagfile.py',
    'ros2 bag play': 'test/tools/test_player.py',
    'ros2 run freejoint_tools reindex': 'test/tools/test_reindex.py',
}
"""Line prefix -> the test of what it needs (a rosdep key, the install layout, the bag)."""
NODE_NICE = 10
"""Niceness of the nodes the lines start (what the test measures are the lines)."""
MAX_STEPS = 1000
"""The scratch ``config/sim.yaml``'s ``max_steps``: 1 s of ticks, then the graph holds (a plan
asked for later starts at the held clock; what is tested is that each line works as typed)."""
JAZZY = '## On a full ROS 2 Jazzy install'
PYPI = '## Without ROS installed (ROS 2 from PyPI)'
OWN_ARM = '## Bring your own arm'
ROS2_CONTROL = "## The controller on ros2_control's topics"
MY_ARM = os.path.join(ROOT, 'src', 'freejoint_description', 'urdf', 'paper_arm.urdf')
"""The URDF the test gives the README's ``my_arm.urdf``."""


def readme_blocks(title, path=README):
    """Return the commands of each ```bash block of the section ``title`` of ``path``."""
    with open(path) as f:
        text = f.read()
    assert title in text, '%s has no section %r' % (os.path.relpath(path, ROOT), title)
    section = text.split(title, 1)[1].split('\n## ', 1)[0]
    blocks = []
    for block in re.findall(r'```bash\n(.*?)```', section, re.S):
        joined = re.sub(r'\\\n\s*', ' ', block)
        blocks.append([line.strip() for line in joined.splitlines()
                       if line.strip() and not line.strip().startswith('#')])
    assert blocks, 'no ```bash block in %r' % title
    return blocks


def test_the_readme_points_to_each_page_whose_commands_are_run_here():
    with open(README) as f:
        text = f.read()
    for path in (ROS_INSTALL, REAL_ARM, OWN_ARM_DOC):
        assert os.path.relpath(path, ROOT) in text, path


def sourced_env(cwd):
    """Return the environment a shell in ``cwd`` has after ``. tools/env.sh``."""
    done = subprocess.run(['bash', '-c', '. %s/tools/env.sh && env -0' % ROOT], cwd=cwd,
                          capture_output=True, check=True, timeout=60)
    return dict(item.split('=', 1) for item in done.stdout.decode().split('\0') if '=' in item)


class Runner:
    """
    Run README lines in a scratch directory under tools/env.sh; keep started nodes.

    Each line runs in a shell of its own with the environment ``. tools/env.sh`` gives
    (sourced once: each line's shell is what the user's is after it).
    """

    def __init__(self, cwd, ros_node):
        import yaml
        self.cwd = cwd
        self.ros_node = ros_node
        config = os.path.join(cwd, 'config')
        os.mkdir(config)
        for name in os.listdir(os.path.join(ROOT, 'config')):
            if name != 'sim.yaml':
                os.symlink(os.path.join(ROOT, 'config', name), os.path.join(config, name))
        with open(os.path.join(ROOT, 'config', 'sim.yaml')) as f:
            sim = yaml.safe_load(f)
        sim['/**']['ros__parameters']['max_steps'] = MAX_STEPS
        with open(os.path.join(config, 'sim.yaml'), 'w') as f:
            yaml.safe_dump(sim, f)
        self.nodes = []
        self.ran = []
        self.env = sourced_env(cwd)

    def shell(self, line, timeout=120):
        return subprocess.run(['bash', '-c', line], cwd=self.cwd, env=self.env,
                              capture_output=True, text=True, timeout=timeout)

    def start(self, line, exe):
        log = open(os.path.join(self.cwd, '%s_%d.log' % (exe, len(self.nodes))), 'w')
        # Niced: a lockstep graph started by hand steps on after its circle as fast as it
        # can (docs/hand_run.md), and would take the CPU from the lines under test.
        proc = subprocess.Popen(['nice', '-n', str(NODE_NICE), 'bash', '-c', 'exec ' + line],
                                cwd=self.cwd, env=self.env, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)
        proc.log = log
        self.nodes.append(proc)
        # its parameter services answer (a get returns at the first answer; a list would
        # wait for discovery to settle: 3.5 s or more a node), asked from this process (the
        # lines' own fj calls are the ones under test). The answer may come late too: a
        # planner computes its map before it answers (beside a numpy hog and the other
        # workers, the niced four-link planner took over 10 s)
        try:
            ParameterCalls(self.ros_node, NODE_NAMES[exe], timeout=60.0).get_parameters(
                ['use_sim_time'])
            why = ''
        except TimeoutError as e:
            why = str(e)
        assert not why and proc.poll() is None, (
            '%r did not come up: %s\n%s' % (line, why, self.log(proc)))

    def log(self, proc):
        proc.log.flush()
        with open(proc.log.name) as f:
            return f.read()

    def stop_all(self):
        for proc in reversed(self.nodes):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(15.0)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait(5.0)
            proc.log.close()
        self.nodes = []

    def run_block(self, lines):
        if any(self.starts(line) for line in lines):
            self.stop_all()
        for line in lines:
            self.run_line(line)

    def starts(self, line):
        """Return the executable ``line`` starts as a node, or None."""
        words = shlex.split(line, comments=True)
        if words[:2] in (['ros2', 'run'], ['fj', 'run']):
            words = words[3:4]
        return words[0] if words and words[0] in NODE_NAMES else None

    def run_line(self, line):
        words = shlex.split(line, comments=True)
        comment = line.split('#', 1)[1] if '#' in line else ''
        covered = [p for p in COVERED if line.startswith(p)]
        if covered:
            assert os.path.isfile(os.path.join(ROOT, COVERED[covered[0]])), covered
            self.ran.append(('covered', line))
            return
        if words[:2] == ['.', 'tools/env.sh']:
            self.ran.append(('env', line))  # every line here runs under it
            return
        exe = self.starts(line)
        if exe is not None:
            command = line.split('#', 1)[0]
            if command.startswith('ros2 run'):
                command = 'fj' + command[len('ros2'):]
            self.start(command, exe)
            self.ran.append(('started', line))
            return
        assert words[0] in ('ros2', 'fj') and words[1] in ('param', 'service', 'node',
                                                           'topic', 'run'), \
            'README line the test does not know: %r (add it to the test)' % line
        command = line.split('#', 1)[0].strip()
        if words[0] == 'ros2':
            command = 'fj' + command[len('ros2'):]
        deadline = time.monotonic() + 60.0
        while True:
            done = self.shell(command)
            if 'until success: true' not in comment or 'success=True' in done.stdout \
                    or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert 'Traceback' not in done.stderr, done.stderr
        if 'refused' in comment:
            assert done.returncode == 1, (line, done.stdout, done.stderr)
            assert 'Setting parameter failed: ' in done.stderr, done.stderr
        else:
            assert done.returncode == 0, (line, done.stdout, done.stderr)
        if 'until success: true' in comment:
            assert 'success=True' in done.stdout, (line, done.stdout)
        self.ran.append(('ran', line))


@pytest.fixture
def runner(tmp_path, ros_node):
    r = Runner(str(tmp_path), ros_node)
    yield r
    r.stop_all()


def test_every_line_of_the_full_jazzy_section_works_with_fj_in_place_of_ros2(runner):
    blocks = readme_blocks(JAZZY, ROS_INSTALL) + readme_blocks(ROS2_CONTROL, REAL_ARM)
    for lines in blocks:
        runner.run_block(lines)
    kinds = [kind for kind, _ in runner.ran]
    assert len(runner.ran) == sum(len(b) for b in blocks)
    assert kinds.count('started') >= 6 and kinds.count('ran') >= 10, runner.ran
    assert os.path.isfile(os.path.join(runner.cwd, 'my_controller.yaml'))


@pytest.mark.skipif(not os.path.isfile(os.path.join(ROOT, '.stamps', 'venv'))
                    or 'system' in open(os.path.join(ROOT, '.stamps', 'venv')).read(),
                    reason='set up on a sourced ROS 2 (the PyPI section is for a set-up '
                    'without ROS: tools/env.sh leaves PATH to ros2 there)')
def test_every_line_of_the_pypi_section_works_as_typed_after_env_sh(runner):
    blocks = readme_blocks(PYPI, ROS_INSTALL)
    for lines in blocks:
        runner.run_block(lines)
    kinds = [kind for kind, _ in runner.ran]
    assert len(runner.ran) == sum(len(b) for b in blocks)
    assert kinds.count('started') == 4 and kinds.count('ran') >= 10, runner.ran
    with open(os.path.join(runner.cwd, 'my_controller.yaml')) as f:
        assert f.read().startswith('/controller_node:\n  ros__parameters:\n')


def test_every_line_of_the_own_arm_section_brings_up_the_nodes_on_the_urdf_it_names(runner):
    shutil.copy(MY_ARM, os.path.join(runner.cwd, 'my_arm.urdf'))
    blocks = readme_blocks(OWN_ARM, OWN_ARM_DOC)
    own = [lines for lines in blocks if any('my_arm.urdf' in line for line in lines)]
    assert own, 'no block of %r starts a node on my_arm.urdf' % OWN_ARM
    for lines in blocks:
        runner.run_block(lines)
        if lines is own[0]:
            passive = runner.shell('fj param get /sim_node passive_joints')
            assert passive.returncode == 0 and "['joint2']" in passive.stdout, passive
    kinds = [kind for kind, _ in runner.ran]
    assert len(runner.ran) == sum(len(b) for b in blocks)
    assert kinds.count('started') >= 7, runner.ran
