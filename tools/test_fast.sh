#!/usr/bin/env bash
# make test-fast: the tests that need no DDS and no node process (`-m 'not dds and not slow'`,
# markers set by the root conftest.py), in two pytest processes at once, one per core of a
# 2-core machine: the linters, and the rest (core math, schemas, control loop, structure).
# Extra arguments go to both (e.g. -x). Exit status: non-zero if either failed.
set -u
cd "$(dirname "$0")/.."
SELECT='not dds and not slow'
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
start=$SECONDS
python -m pytest -c pytest.ini -q -m "($SELECT) and linter" "$@" >"$out/linters" 2>&1 &
linters=$!
python -m pytest -c pytest.ini -q -m "($SELECT) and not linter" "$@" >"$out/rest" 2>&1
rest=$?
wait "$linters"
lint=$?
cat "$out/rest"
echo '-- linters:'
cat "$out/linters"
# 5: no test collected (the arguments selected none of one group)
[ "$rest" = 5 ] && rest=0
[ "$lint" = 5 ] && lint=0
echo "[test-fast] $((SECONDS - start)) s wall"
[ "$rest" = 0 ] && [ "$lint" = 0 ]
