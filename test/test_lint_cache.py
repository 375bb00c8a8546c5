"""The linters' cache of clean files (``make test-fast``): what is linted again, and when."""
import importlib.util
import os

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
_spec = importlib.util.spec_from_file_location('lint_cache_under_test',
                                               os.path.join(HERE, 'lint_cache.py'))
lint_cache = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lint_cache)


class Linter:
    """A stand-in linter: records what it was given; ``bad`` files have a finding."""

    def __init__(self):
        self.calls = []
        self.bad = set()

    def flake8(self, argv):
        self.calls.append(list(argv))
        errors = ['%s:1:1: E000 finding' % path for path in argv if path in self.bad]
        return (1 if errors else 0), errors

    def pep257(self, argv):
        return self.flake8(argv)[0]


@pytest.fixture
def tree(tmp_path):
    """Return a package folder (two modules, a hidden folder) and a cache folder."""
    pkg = tmp_path / 'pkg'
    (pkg / 'sub').mkdir(parents=True)
    (pkg / '.hidden').mkdir()
    (pkg / 'a.py').write_text('A = 1\n')
    (pkg / 'sub' / 'b.py').write_text('B = 2\n')
    (pkg / '.hidden' / 'c.py').write_text('C = 3\n')
    (pkg / 'notes.txt').write_text('not python\n')
    return pkg, str(tmp_path / 'cache')


def test_the_python_files_of_a_folder_leave_out_hidden_and_underscore_folders(tree):
    pkg, _ = tree
    assert lint_cache.python_files([str(pkg)]) == [str(pkg / 'a.py'), str(pkg / 'sub' / 'b.py')]


def test_clean_files_are_linted_once_and_a_changed_one_again(tree):
    pkg, cache = tree
    linter = Linter()
    run = lint_cache.cached_flake8(linter.flake8, cache)
    assert run([str(pkg)]) == (0, [])
    assert linter.calls == [[str(pkg / 'a.py'), str(pkg / 'sub' / 'b.py')]]
    assert run([str(pkg)]) == (0, [])            # both marked clean: not linted
    assert len(linter.calls) == 1
    (pkg / 'a.py').write_text('A = 10\n')
    assert run([str(pkg)]) == (0, [])
    assert linter.calls[-1] == [str(pkg / 'a.py')]


def test_a_file_with_a_finding_fails_every_run_until_mended(tree):
    pkg, cache = tree
    linter = Linter()
    linter.bad.add(str(pkg / 'a.py'))
    run = lint_cache.cached_flake8(linter.flake8, cache)
    for _ in range(2):
        rc, errors = run([str(pkg)])
        assert rc == 1 and errors == ['%s:1:1: E000 finding' % (pkg / 'a.py')]
    linter.bad.clear()
    assert run([str(pkg)]) == (0, [])
    assert run([str(pkg)]) == (0, []) and len(linter.calls) == 3


def test_pep257_marks_apart_from_flake8s(tree):
    pkg, cache = tree
    linter = Linter()
    assert lint_cache.cached_flake8(linter.flake8, cache)([str(pkg)]) == (0, [])
    pep257 = lint_cache.cached_pep257(linter.pep257, cache)
    assert pep257([str(pkg)]) == 0 and len(linter.calls) == 2
    assert pep257([str(pkg)]) == 0 and len(linter.calls) == 2
    linter.bad.add(str(pkg / 'sub' / 'b.py'))
    (pkg / 'sub' / 'b.py').write_text('B = 20\n')
    assert pep257([str(pkg)]) == 1 and pep257([str(pkg)]) == 1


def test_a_new_linter_version_lints_every_file_again(tree, monkeypatch):
    pkg, cache = tree
    linter = Linter()
    run = lint_cache.cached_flake8(linter.flake8, cache)
    run([str(pkg)])
    monkeypatch.setattr(lint_cache, 'linter_key', lambda tool: 'flake8=99.0')
    run([str(pkg)])
    assert linter.calls[-1] == [str(pkg / 'a.py'), str(pkg / 'sub' / 'b.py')]


def test_options_are_passed_on_uncached(tree):
    pkg, cache = tree
    linter = Linter()
    run = lint_cache.cached_flake8(linter.flake8, cache)
    for _ in range(2):
        run(['--linelength', '80', str(pkg)])
    assert linter.calls == [['--linelength', '80', str(pkg)]] * 2


def test_the_key_names_the_installed_flake8_and_its_configuration():
    key = lint_cache.linter_key('flake8')
    assert key.startswith('flake8\npython=3.') and '\nflake8=' in key
    assert any(line.startswith('flake8-quotes=') or line.startswith('flake8_quotes=')
               for line in key.splitlines())
    assert lint_cache.linter_key('pep257') != key


def test_the_real_flake8_through_the_cache_finds_a_long_line(tmp_path):
    from ament_flake8.main import main_with_errors
    bad = tmp_path / 'long.py'
    bad.write_text('"""Doc."""\nX = %r\n' % ('x' * 120))
    run = lint_cache.cached_flake8(main_with_errors, str(tmp_path / 'cache'))
    for _ in range(2):
        rc, errors = run([str(bad)])
        assert rc == 1 and any('E501' in e for e in errors)
    bad.write_text('"""Doc."""\nX = 1\n')
    assert run([str(bad)]) == (0, [])
    assert os.listdir(str(tmp_path / 'cache' / 'flake8'))


def test_a_file_found_clean_in_one_checkout_is_clean_at_the_same_path_in_another(tmp_path):
    cache = str(tmp_path / 'cache')
    linter = Linter()
    trees = []
    for name in ('clone_a', 'clone_b'):
        (tmp_path / name / 'pkg').mkdir(parents=True)
        (tmp_path / name / 'pkg' / 'a.py').write_text('A = 1\n')
        trees.append(tmp_path / name)
    for root in trees:
        run = lint_cache.cached_flake8(linter.flake8, cache, root=str(root))
        assert run([str(root / 'pkg')]) == (0, [])
    assert linter.calls == [[str(trees[0] / 'pkg' / 'a.py')]]     # the second clone: none
    (trees[1] / 'pkg' / 'b.py').write_text('A = 1\n')              # same bytes, other path
    run = lint_cache.cached_flake8(linter.flake8, cache, root=str(trees[1]))
    assert run([str(trees[1] / 'pkg')]) == (0, [])
    assert linter.calls[-1] == [str(trees[1] / 'pkg' / 'b.py')]
