"""Set-up stops with a message that names what is missing, not a traceback."""
import glob
import os
import shlex
import shutil
import stat
import subprocess
import sys
import sysconfig

import pytest

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
             if not k.startswith(('ROS_', 'AMENT_', 'COLCON', 'VIRTUAL_ENV', 'UV_',
                                  'FREEJOINT_', 'SSL_CERT_'))}
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


# Port 9 (discard) on loopback: nothing listens, a download fails at once.
DEAD_INDEX = {'PIP_INDEX_URL': 'http://127.0.0.1:9/simple', 'PIP_NO_CACHE_DIR': '1',
              'PIP_RETRIES': '0', 'PIP_TIMEOUT': '2', 'PIP_FIND_LINKS': ''}


def _uv_pin():
    with open(os.path.join(ROOT, 'tools', 'requirements-uv.txt'), encoding='utf-8') as fh:
        pins = [line.strip() for line in fh if line.startswith('uv==')]
    assert len(pins) == 1, pins
    return pins[0][len('uv=='):]


def _fake_uv(folder, log):
    """
    Write a uv at ``folder/uv`` that logs its arguments and uv settings, then fails.

    It answers ``--version``; ``pip install`` prints uv's progress lines and fails as uv
    does when the index is unreachable (``error:`` and ``Caused by:``, exit 2).
    """
    folder.mkdir(parents=True, exist_ok=True)
    uv = folder / 'uv'
    uv.write_text(
        '#!/bin/sh\n'
        'if [ "$1" = --version ]; then echo "uv 0.0.0 (fake)"; exit 0; fi\n'
        'echo "$* | $UV_DEFAULT_INDEX | $UV_HTTP_TIMEOUT | $SSL_CERT_FILE" >> %s\n'
        'echo "Resolved 3 packages in 10ms" >&2\n'
        'echo "error: Failed to fetch: http://127.0.0.1:9/simple/apsw/" >&2\n'
        'echo "  Caused by: Connection refused (os error 111)" >&2\n'
        'exit 2\n' % shlex.quote(str(log)))
    uv.chmod(uv.stat().st_mode | stat.S_IEXEC)
    return uv


def _assert_failed_cleanly(out, tmp_path):
    assert out.returncode != 0, out.stdout
    assert 'downloading/installing the Python packages failed' in out.stderr
    assert 'PyPI is reachable' in out.stderr
    assert "run 'make setup' again" in out.stderr
    assert 'Traceback' not in out.stderr
    assert not (tmp_path / '.stamps' / 'venv').exists()     # the next run installs again


@pytest.mark.parametrize('where', ['on PATH', 'in the bootstrap folder'])
def test_uv_installs_the_pins_and_its_failure_is_relayed_with_the_pip_way_out(tmp_path, where):
    setup = _copy_tools(tmp_path)
    _venv_without_packages(tmp_path)
    log = tmp_path / 'uv-calls'
    path = _bin_without(tmp_path, {'uv'})
    cache = tmp_path / 'cache'
    if where == 'on PATH':
        path = '%s:%s' % (_fake_uv(tmp_path / 'uvbin', log).parent, path)
    else:           # installed by an earlier set-up of any checkout: reused, not installed
        _fake_uv(cache / ('uv-' + _uv_pin()) / 'bin', log)
    out = _run(setup, dict(DEAD_INDEX, PATH=path, FREEJOINT_CACHE=str(cache),
                           PIP_CERT='/etc/some-proxy-ca.pem'))
    _assert_failed_cleanly(out, tmp_path)
    assert 'pinned packages into .venv with uv' in out.stdout, out.stdout
    assert '[setup] uv: Resolved 3 packages in 10ms' in out.stdout
    assert 'installing uv' not in out.stdout
    assert '(uv exit 2)' in out.stderr
    assert '\n  error: Failed to fetch: http://127.0.0.1:9/simple/apsw/' in out.stderr
    assert 'FREEJOINT_INSTALLER=pip' in out.stderr
    # the pins, into .venv, with this machine's pip settings handed to uv
    calls = log.read_text().splitlines()
    venv_python = tmp_path / '.venv' / 'bin' / 'python'
    req = tmp_path / 'tools' / 'requirements.txt'
    assert calls == ['pip install --python %s -r %s | http://127.0.0.1:9/simple | 2 | '
                     '/etc/some-proxy-ca.pem' % (venv_python, req)]


def _stand_in_pip(tmp_path):
    """Make .venv's pip one that logs its arguments and fails at once as pip does."""
    pip = tmp_path / '.venv' / 'bin' / 'pip'
    pip.write_text('#!/bin/sh\necho "$*" >> %s\nfor a; do last=$a; done\n'
                   'echo "ERROR: No matching distribution found for $(tail -1 "$last")"\n'
                   'exit 1\n' % shlex.quote(str(tmp_path / 'pip-calls')))
    return tmp_path / 'pip-calls'


def test_without_uv_pip_installs_after_the_bootstrap_failed_and_says_why(tmp_path):
    setup = _copy_tools(tmp_path)
    _venv_without_packages(tmp_path)
    calls = _stand_in_pip(tmp_path)
    cache = tmp_path / 'cache'
    out = _run(setup, {'PATH': _bin_without(tmp_path, {'uv'}), 'FREEJOINT_CACHE': str(cache)})
    _assert_failed_cleanly(out, tmp_path)
    pin = _uv_pin()
    assert 'installing uv %s with pip into %s' % (pin, cache) in out.stdout, out.stdout
    assert ('installer: pip (installing uv %s failed: ERROR: No matching distribution found '
            'for uv==%s)' % (pin, pin)) in out.stdout
    assert not os.listdir(cache)                # no half-installed uv left to reuse
    assert 'pinned packages into .venv with pip' in out.stdout
    assert '(pip exit 1)' in out.stderr
    bootstrap, install = calls.read_text().splitlines()
    assert bootstrap.startswith('install --disable-pip-version-check --progress-bar off '
                                '--no-deps --target %s/uv-%s.tmp.' % (cache, pin))
    assert bootstrap.endswith(' -r %s' % (tmp_path / 'tools' / 'requirements-uv.txt'))
    assert install == ('install --disable-pip-version-check --progress-bar off -r %s'
                       % (tmp_path / 'tools' / 'requirements.txt'))


def test_failed_download_with_pip_says_what_failed_and_how_to_retry(tmp_path):
    # FREEJOINT_INSTALLER=pip: pip though a uv is on PATH; the real pip, its own reason
    setup = _copy_tools(tmp_path)
    _venv_without_packages(tmp_path)
    log = tmp_path / 'uv-calls'
    path = '%s:%s' % (_fake_uv(tmp_path / 'uvbin', log).parent, os.environ['PATH'])
    out = _run(setup, dict(DEAD_INDEX, PATH=path, FREEJOINT_INSTALLER='pip'))
    _assert_failed_cleanly(out, tmp_path)
    assert 'installer: pip (FREEJOINT_INSTALLER=pip)' in out.stdout, out.stdout
    assert not log.exists()
    assert 'pinned packages into .venv with pip' in out.stdout
    assert '(pip exit ' in out.stderr
    assert '\n  ERROR: ' in out.stderr, out.stderr       # pip's own reason, relayed


def test_an_unknown_installer_is_named(tmp_path):
    setup = _copy_tools(tmp_path)
    out = _run(setup, {'FREEJOINT_INSTALLER': 'conda'})
    assert out.returncode != 0
    assert 'FREEJOINT_INSTALLER=conda: expected auto, uv or pip.' in out.stderr
    assert not (tmp_path / '.venv').exists()
