"""The built interfaces are kept once and copied into other checkouts, their paths rewritten."""
import os
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CACHE = os.path.join(ROOT, 'tools', 'interface_cache.sh')
PKG = 'freejoint_msgs'
LIBRARY = b'\x7fELF\x00\x01 built in %s\x00\xff'


def _cache(*args):
    return subprocess.run(['bash', CACHE] + [str(a) for a in args], capture_output=True,
                          text=True, timeout=60)


def _built_checkout(root):
    """Lay out what colcon --symlink-install leaves of the interfaces in ``root``."""
    build = root / 'build' / PKG
    share = root / 'install' / PKG / 'share' / PKG
    lib = root / 'install' / PKG / 'lib'
    site = lib / 'python3.11' / 'site-packages' / PKG
    for folder in (build, share, site / '__pycache__'):
        folder.mkdir(parents=True)
    (share / 'package.sh').write_text('. "%s/install/%s/share/%s/hook.sh"\n' % (root, PKG, PKG))
    (build / 'hook.dsv').write_text('prepend-non-duplicate;PATH;%s/install/%s/bin\n'
                                    % (root, PKG))
    os.symlink(build / 'hook.dsv', share / 'hook.dsv')
    (lib / 'libfreejoint_msgs.so').write_bytes(LIBRARY % str(root).encode())
    (site / '__init__.py').write_text('')
    (site / '__pycache__' / '__init__.cpython-311.pyc').write_bytes(b'\x00')


def test_a_saved_entry_is_the_install_tree_without_links_into_the_build_tree_nor_bytecode(
        tmp_path):
    a = tmp_path / 'a'
    _built_checkout(a)
    entry = tmp_path / 'cache' / 'key1'
    out = _cache('save', entry, a)
    assert out.returncode == 0, out.stderr
    assert (entry / 'root').read_text() == str(a)
    kept = entry / PKG / 'share' / PKG / 'hook.dsv'
    assert not kept.is_symlink() and str(a) in kept.read_text()
    assert not list(entry.rglob('__pycache__'))
    assert not list(tmp_path.joinpath('cache').glob('*.tmp.*'))


def test_a_restored_tree_names_the_checkout_it_was_copied_into(tmp_path):
    a = tmp_path / 'a'
    _built_checkout(a)
    entry = tmp_path / 'cache' / 'key1'
    assert _cache('save', entry, a).returncode == 0
    b = tmp_path / 'b&c|d.e'            # characters sed would read specially
    _built_checkout(b)                  # an older build, replaced
    (b / 'install' / PKG / 'stale').write_text('')
    out = _cache('restore', entry, b)
    assert out.returncode == 0, out.stderr
    share = b / 'install' / PKG / 'share' / PKG
    assert (share / 'package.sh').read_text() == (
        '. "%s/install/%s/share/%s/hook.sh"\n' % (b, PKG, PKG))
    assert (share / 'hook.dsv').read_text() == (
        'prepend-non-duplicate;PATH;%s/install/%s/bin\n' % (b, PKG))
    assert not (b / 'install' / PKG / 'stale').exists()
    assert not (b / 'build' / PKG).exists()
    assert (b / 'install' / 'COLCON_IGNORE').exists()   # colcon finds no package in it
    # Binaries are copied as they are (they load by name; a path in them is only text).
    assert (b / 'install' / PKG / 'lib' / 'libfreejoint_msgs.so').read_bytes() == (
        LIBRARY % str(a).encode())


def test_a_missing_or_partial_entry_restores_nothing(tmp_path):
    b = tmp_path / 'b'
    _built_checkout(b)
    before = (b / 'install' / PKG / 'share' / PKG / 'package.sh').read_text()
    entry = tmp_path / 'cache' / 'key1'
    assert _cache('restore', entry, b).returncode == 1
    (entry / PKG).mkdir(parents=True)           # no "root": a save that did not finish
    assert _cache('restore', entry, b).returncode == 1
    assert (b / 'install' / PKG / 'share' / PKG / 'package.sh').read_text() == before


def test_saving_keeps_the_three_newest_entries(tmp_path):
    a = tmp_path / 'a'
    _built_checkout(a)
    cache = tmp_path / 'cache'
    for i, key in enumerate(('k1', 'k2', 'k3')):
        assert _cache('save', cache / key, a).returncode == 0
        os.utime(cache / key, (1000 + i, 1000 + i))
    assert _cache('save', cache / 'k4', a).returncode == 0
    assert sorted(os.listdir(cache)) == ['k2', 'k3', 'k4']


def test_setup_restores_the_interfaces_from_the_cache_and_builds_the_rest():
    with open(os.path.join(ROOT, 'tools', 'setup.sh'), encoding='utf-8') as fh:
        text = fh.read()
    assert 'interface_cache.sh" restore "$MSGS_CACHE" "$ROOT"' in text
    assert 'interface_cache.sh" save "$MSGS_CACHE" "$ROOT"' in text
    assert '${skip[@]+"${skip[@]}"}' in text        # --packages-skip freejoint_msgs


def test_saving_again_replaces_the_entry_whole(tmp_path):
    a = tmp_path / 'a'
    _built_checkout(a)
    entry = tmp_path / 'cache' / 'key1'
    assert _cache('save', entry, a).returncode == 0
    (entry / 'leftover').write_text('')
    b = tmp_path / 'b'
    _built_checkout(b)
    assert _cache('save', entry, b).returncode == 0
    assert (entry / 'root').read_text() == str(b) and not (entry / 'leftover').exists()
    assert os.listdir(tmp_path / 'cache') == ['key1']
