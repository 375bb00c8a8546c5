"""
The clean results of the ament linters per file, for ``make test`` and ``make test-fast``.

The Makefile sets ``FREEJOINT_LINT_CACHE`` for both (outside CI) to a folder (default
``${FREEJOINT_CACHE:-~/.cache/freejoint}/lint``, beside the interface cache, shared by
every checkout of the user); the root conftest then gives every ``linter`` test, in place
of ``ament_flake8``'s ``main_with_errors`` and ``ament_pep257``'s ``main``, a call that
lints only the files not found clean before: a file is skipped when a mark of its path in
the checkout, its bytes and the linter (its configuration file, the versions of Python,
the linter packages and their plugins) exists, and marks are written for the files linted
when the linter found them all clean. The path is the one relative to the checkout's root
(the folder above ``test/``): a fresh clone of the same commit finds its files clean, as
the linters are given their configuration explicitly (ament's, not a file of the tree). A
changed file, a changed configuration or a new plugin version is linted again; files
linted with a finding get no mark, so the finding fails every run until mended. Without
the variable (CI, a package's ``colcon test``) every file is linted every time.
"""

import functools
import hashlib
import importlib.metadata
import os
import sys

ENV = 'FREEJOINT_LINT_CACHE'
"""The environment variable naming the cache folder (unset or empty: no cache)."""
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
"""The checkout's root: the marks name a file by its path relative to it."""
LINTER_PACKAGES = ('flake8', 'pycodestyle', 'pyflakes', 'mccabe', 'pep257', 'pydocstyle',
                   'ament-flake8', 'ament_flake8', 'ament-pep257', 'ament_pep257')
"""Distributions (and every ``flake8-*`` plugin) whose versions key the marks."""


def cache_dir():
    """Return the cache folder from the environment, or None (no cache)."""
    return os.environ.get(ENV) or None


@functools.lru_cache(maxsize=None)
def linter_versions():
    """
    Return the sorted ``name=version`` lines of the linter distributions and flake8 plugins.

    Each distribution's metadata is parsed once (``Distribution.metadata`` parses its file
    at every access: a few hundred distributions, about a millisecond each).
    """
    versions = []
    for dist in importlib.metadata.distributions():
        meta = dist.metadata
        name = meta['Name']
        if name and (name in LINTER_PACKAGES or name.lower().startswith('flake8')):
            versions.append('%s=%s' % (name, meta['Version']))
    return tuple(sorted(versions))


@functools.lru_cache(maxsize=None)
def linter_key(tool):
    """
    Return the text that keys the marks of ``tool`` ('flake8' or 'pep257').

    The Python version, the versions of the linter distributions and of every flake8
    plugin, and for flake8 the contents of ament_flake8's configuration file.
    """
    parts = [tool, 'python=' + sys.version.split()[0]] + list(linter_versions())
    if tool == 'flake8':
        import ament_flake8
        config = os.path.join(os.path.dirname(ament_flake8.__file__), 'configuration',
                              'ament_flake8.ini')
        with open(config, 'rb') as fh:
            parts.append(hashlib.sha256(fh.read()).hexdigest())
    return '\n'.join(parts)


def python_files(paths):
    """
    Return the ``.py`` files of ``paths`` (files, or folders walked), sorted.

    Folders whose name starts with ``.`` or ``_`` are not entered (as ament's linters
    exclude them).
    """
    found = []
    for path in paths:
        if not os.path.isdir(path):
            found.append(os.path.abspath(path))
            continue
        for folder, dirs, files in os.walk(path):
            dirs[:] = [d for d in dirs if d[0] not in '._']
            found.extend(os.path.join(os.path.abspath(folder), f) for f in files
                         if f.endswith('.py'))
    return sorted(found)


def _mark(folder, tool, path, root):
    digest = hashlib.sha256()
    digest.update(linter_key(tool).encode())
    digest.update(b'\0' + os.path.relpath(path, root).encode() + b'\0')
    with open(path, 'rb') as fh:
        digest.update(fh.read())
    return os.path.join(folder, tool, digest.hexdigest())


def _write(mark):
    os.makedirs(os.path.dirname(mark), exist_ok=True)
    with open(mark, 'w'):
        pass


def _split(folder, tool, argv, root):
    """Return (options, [(file, mark)] of the files not found clean before)."""
    options = [a for a in argv if a.startswith('-')]
    if options:
        return options, None
    todo = []
    for path in python_files(argv):
        mark = _mark(folder, tool, path, root)
        if not os.path.exists(mark):
            todo.append((path, mark))
    return options, todo


def cached_flake8(run, folder, root=ROOT):
    """
    Return ``main_with_errors(argv)`` of ament_flake8 that lints only unmarked files.

    ``run``: ament_flake8's ``main_with_errors``; ``folder``: the marks; ``root``: the
    checkout the marks' paths are relative to; ``argv``: paths (options, if any, are passed
    on, and then nothing is cached).
    """
    def main_with_errors(argv):
        options, todo = _split(folder, 'flake8', argv, root)
        if options:
            return run(argv=argv)
        if not todo:
            return 0, []
        rc, errors = run(argv=[path for path, _ in todo])
        if rc == 0:
            for _, mark in todo:
                _write(mark)
        return rc, errors
    return main_with_errors


def cached_pep257(run, folder, root=ROOT):
    """Return ``main(argv)`` of ament_pep257 that lints only unmarked files (see above)."""
    def main(argv):
        options, todo = _split(folder, 'pep257', argv, root)
        if options:
            return run(argv=argv)
        if not todo:
            return 0
        rc = run(argv=[path for path, _ in todo])
        if rc == 0:
            for _, mark in todo:
                _write(mark)
        return rc
    return main
