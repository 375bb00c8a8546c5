#!/usr/bin/env bash
# make test-fast: the tests that need no DDS and no node process (`-m 'not dds and not slow'`,
# markers set by the root conftest.py): core math, schemas, control loop, structure, linters.
# Extra arguments go to pytest (make passes `-n N --dist worksteal`: pytest-xdist workers, one
# per core unless JOBS is given).
set -u
cd "$(dirname "$0")/.."
start=$SECONDS
# The linters lint only the files they have not found clean before where FREEJOINT_LINT_CACHE
# names a folder (make test-fast sets it, as make test does: test/lint_cache.py); CI and a
# package's colcon test lint every file.
python -m pytest -c pytest.ini -q -m 'not dds and not slow' "$@"
rc=$?
echo "[test-fast] $((SECONDS - start)) s wall"
exit $rc
