"""Set-up stops with a message that names what is missing, not a traceback."""
import glob
import os
import shlex
import shutil
import stat
import subprocess
import sys
import sysconfig

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _copy_tools(tmp_path):
    """Lay out a bare checkout (tools/ and an empty src/) in tmp_path; return setup.sh."""
    shutil.copytree(os.path.join(ROOT, 'tools'), tmp_path / 'tools',
                    ignore=shutil.ignore_patterns('__pycache__', '*.py'))
    (tmp_path / 'src').mkdir()
    return str(tmp_path / 'tools' / 'setup.sh')


def _bin_without(tmp_path, missing):
    """Return a PATH directory with the usual commands but none of `missing`."""
    bindir = tmp_path / 'bin'
    bindir.mkdir()
    for d in ('/usr/local/bin', '/usr/bin', '/bin'):
        if not os.path.isdir(d):
            continue
        for name in os.listdir(d):
            if name not in missing and not (bindir / name).exists():
                os.symlink(os.path.join(d, name), bindir / name)
    for name in ('python3',):
        if (bindir / name).exists() or (bindir / name).is_symlink():
            (bindir / name).unlink()
        os.symlink(sys.executable, bindir / name)
    return str(bindir)


def _run(setup, env):
    clean = {k: v for k, v in os.environ.items()
             if not k.startswith(('ROS_', 'AMENT_', 'COLCON', 'VIRTUAL_ENV'))}
    clean.update(env)
    return subprocess.run(['bash', setup], env=clean, capture_output=True, text=True,
                          timeout=120)


def test_wrong_python_version_is_named_with_the_fix(tmp_path):
    setup = _copy_tools(tmp_path)
    fake = tmp_path / 'python3.9'
    fake.write_text('#!/bin/sh\necho 3.9\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    out = _run(setup, {'PYTHON': str(fake)})
    assert out.returncode != 0
    assert 'Python 3.9 found' in out.stderr
    assert 'CPython 3.10-3.13' in out.stderr
    assert 'Traceback' not in out.stderr + out.stdout


def test_missing_compiler_is_named_with_the_package_to_install(tmp_path):
    setup = _copy_tools(tmp_path)
    path = _bin_without(tmp_path, {'cc', 'gcc', 'c++', 'g++'})
    out = _run(setup, {'PATH': path})
    assert out.returncode != 0
    assert "'cc' not found" in out.stderr
    assert 'build-essential' in out.stderr
    assert not (tmp_path / '.venv').exists()


def test_missing_cmake_is_named(tmp_path):
    setup = _copy_tools(tmp_path)
    path = _bin_without(tmp_path, {'cmake'})
    out = _run(setup, {'PATH': path})
    assert out.returncode != 0
    assert "'cmake' not found" in out.stderr


def _venv_without_packages(tmp_path):
    """
    Make the .venv a set-up that failed to download leaves: a venv, no package in it.

    Its pip is ensurepip's wheel, the pip ``python -m venv`` installs, run from the wheel
    as ensurepip runs it: ``python -m venv`` spends most of its seconds installing that pip
    (6-11 s on 2 cores), which is not what the test is about.
    """
    import ensurepip
    wheels = []
    for folder in (os.path.join(os.path.dirname(ensurepip.__file__), '_bundled'),
                   sysconfig.get_config_var('WHEEL_PKG_DIR')):    # Debian's python3-venv
        if folder and os.path.isdir(folder):
            wheels += glob.glob(os.path.join(folder, 'pip-*.whl'))
    assert wheels, 'no pip wheel of ensurepip found for %s' % sys.executable
    venv = tmp_path / '.venv'
    subprocess.run([sys.executable, '-m', 'venv', '--without-pip', str(venv)], check=True,
                   timeout=60)
    pip = venv / 'bin' / 'pip'
    pip.write_text('#!/bin/sh\nPYTHONPATH=%s exec %s -m pip "$@"\n'
                   % (shlex.quote(wheels[0]), shlex.quote(str(venv / 'bin' / 'python'))))
    pip.chmod(pip.stat().st_mode | stat.S_IEXEC)


def test_failed_download_says_what_failed_and_how_to_retry(tmp_path):
    setup = _copy_tools(tmp_path)
    _venv_without_packages(tmp_path)
    # Port 9 (discard) on loopback: nothing listens, the download fails at once.
    out = _run(setup, {'PIP_INDEX_URL': 'http://127.0.0.1:9/simple', 'PIP_NO_CACHE_DIR': '1',
                       'PIP_RETRIES': '0', 'PIP_TIMEOUT': '2', 'PIP_FIND_LINKS': ''})
    assert out.returncode != 0, out.stdout
    assert 'installing' in out.stdout and 'pinned packages into .venv' in out.stdout, out.stdout
    assert 'downloading/installing the Python packages failed' in out.stderr
    assert '\n  ERROR: ' in out.stderr, out.stderr       # pip's own reason, relayed
    assert 'PyPI is reachable' in out.stderr
    assert "run 'make setup' again" in out.stderr
    assert 'Traceback' not in out.stderr
    assert not (tmp_path / '.stamps' / 'venv').exists()     # the next run installs again
