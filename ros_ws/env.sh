# Source me: `source ros_ws/env.sh` (bash). Gives the venv, the ROS 2 Jazzy wheel libraries,
# the ament/CMake prefix paths, the workspace overlay and the `fourws` command.
# Option --no-overlay: only the venv part (used by the build itself).
_FOURWS_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export FOURWS_ROOT="$_FOURWS_ROOT"
_FOURWS_VENV="$_FOURWS_ROOT/.venv"
if [ ! -x "$_FOURWS_VENV/bin/python" ]; then
  echo "fourws: no venv at $_FOURWS_VENV; run 'make setup' first" >&2
  return 1 2>/dev/null || exit 1
fi
# The wheels' bootstrapper re-executes Python unless the library path is already set.
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
VIRTUAL_ENV_DISABLE_PROMPT=1 . "$_FOURWS_VENV/bin/activate"
_fourws_sp="$(echo "$_FOURWS_VENV"/lib/python3*/site-packages)"
_fourws_ld="$_FOURWS_VENV/lib"
for _d in "$_fourws_sp"/ros_*.libs; do _fourws_ld="$_fourws_ld:$_d"; done
case ":${LD_LIBRARY_PATH:-}:" in
  *":$_FOURWS_VENV/lib:"*) ;;
  *) export LD_LIBRARY_PATH="$_fourws_ld${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" ;;
esac
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$_FOURWS_VENV:"*) ;;
  *) export AMENT_PREFIX_PATH="$_FOURWS_VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac
case ":${CMAKE_PREFIX_PATH:-}:" in
  *":$_FOURWS_VENV:"*) ;;
  *) export CMAKE_PREFIX_PATH="$_FOURWS_VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" ;;
esac
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
export ROS_DISTRO=jazzy
# Discovery stays on this host; tests and runs pick their own ROS_DOMAIN_ID.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
if [ "${1:-}" != "--no-overlay" ]; then
  if [ -f "$_FOURWS_ROOT/ros_ws/install/local_setup.bash" ]; then
    # shellcheck disable=SC1091
    . "$_FOURWS_ROOT/ros_ws/install/local_setup.bash"
    case ":$PATH:" in
      *":$_FOURWS_ROOT/ros_ws/install/fourws_bringup/lib/fourws_bringup:"*) ;;
      *) export PATH="$_FOURWS_ROOT/ros_ws/install/fourws_bringup/lib/fourws_bringup:$PATH" ;;
    esac
  else
    echo "fourws: workspace not built yet (ros_ws/install missing); run 'make setup'" >&2
  fi
fi
unset _d _fourws_sp _fourws_ld _FOURWS_VENV
