# shellcheck shell=bash
# Source me: `. tools/env.sh` gives a shell with the freejoint workspace (what
# `source install/setup.bash` does on a full ROS 2 install, plus the project's .venv).
# Set up with a sourced ROS 2 Jazzy, that install stays the underlay; otherwise .venv is.
_fj_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
export VIRTUAL_ENV="$_fj_root/.venv"
case ":$PATH:" in *":$VIRTUAL_ENV/bin:"*) ;; *) export PATH="$VIRTUAL_ENV/bin:$PATH" ;; esac
if ! grep -qs system "$_fj_root/.stamps/venv"; then
  # The venv is laid out like a ROS install prefix (lib/, share/ament_index/).
  case ":${AMENT_PREFIX_PATH:-}:" in *":$VIRTUAL_ENV:"*) ;; *)
    export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;; esac
  case ":${CMAKE_PREFIX_PATH:-}:" in *":$VIRTUAL_ENV:"*) ;; *)
    export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" ;; esac
fi
if [ "${1:-}" != --no-install ] && [ -f "$_fj_root/install/local_setup.bash" ]; then
  # shellcheck disable=SC1091
  COLCON_CURRENT_PREFIX="$_fj_root/install" . "$_fj_root/install/local_setup.bash"
fi
if ! grep -qs system "$_fj_root/.stamps/venv"; then
  # No ros2 on this path: the node executables (what `ros2 run` starts) and `fj` on PATH.
  for _fj_lib in "$_fj_root"/install/*/lib/*/; do
    _fj_lib=${_fj_lib%/}
    [ "${_fj_lib##*/}" = "$(basename "$(dirname "$(dirname "$_fj_lib")")")" ] || continue
    case ":$PATH:" in *":$_fj_lib:"*) ;; *) export PATH="$PATH:$_fj_lib" ;; esac
  done
  unset _fj_lib
fi
# The project's Fast DDS profile (config/fastdds.xml: a restarted node discovered sooner
# with localhost discovery, a killed one forgotten after 5 s instead of 20 s), unless one
# is chosen already. FASTRTPS_*: Fast DDS 2.x (Jazzy); FASTDDS_*: Fast DDS 3.x.
if [ -z "${FASTRTPS_DEFAULT_PROFILES_FILE:-}${FASTDDS_DEFAULT_PROFILES_FILE:-}" ]; then
  export FASTRTPS_DEFAULT_PROFILES_FILE="$_fj_root/config/fastdds.xml"
  export FASTDDS_DEFAULT_PROFILES_FILE="$_fj_root/config/fastdds.xml"
fi
# numpy's OpenBLAS on one thread per process unless chosen: the arrays are at most an arm's
# (7 x 7), too small for OpenBLAS to split, and its thread pool costs every process's start
# about 0.1 CPU-s and puts idle threads beside the control loop.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
unset _fj_root
