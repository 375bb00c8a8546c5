#!/usr/bin/env bash
# make test-fast: the tests that need no DDS and no node process (`-m 'not dds and not slow'`,
# markers set by the root conftest.py): core math, schemas, control loop, structure, linters.
# Extra arguments go to pytest (make passes `-n N --dist worksteal`: pytest-xdist workers, one
# per core unless JOBS is given).
set -u
cd "$(dirname "$0")/.."
start=$SECONDS
# The linters lint only the files they have not found clean before (test/lint_cache.py);
# CI and a package's colcon test lint every file.
export FREEJOINT_LINT_CACHE=${FREEJOINT_LINT_CACHE-${FREEJOINT_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/freejoint}/lint}
python -m pytest -c pytest.ini -q -m 'not dds and not slow' "$@"
rc=$?
echo "[test-fast] $((SECONDS - start)) s wall"
exit $rc
