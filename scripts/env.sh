# Source this file (bash) to get the project's environment: the ROS 2 underlay
# (/opt/ros/jazzy from apt, or the PyPI wheels in .venv/) and the colcon overlay
# in ros_ws/install. Used by ./sslfr, the Makefile and .ci/run; people normally
# never need to source it by hand.
SSLFR_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export SSLFR_ROOT
# Start from a clean slate so a half-sourced shell (or a test's stripped environment)
# cannot make colcon's setup scripts skip themselves.
unset COLCON_PREFIX_PATH AMENT_PREFIX_PATH CMAKE_PREFIX_PATH AMENT_CURRENT_PREFIX
if [ -f /opt/ros/jazzy/setup.bash ] && [ -z "${SSLFR_FORCE_PYPI_ROS:-}" ]; then
  # shellcheck disable=SC1091
  set +u; . /opt/ros/jazzy/setup.bash; set -u 2>/dev/null || true
  export SSLFR_ROS_SOURCE=apt
else
  export SSLFR_ROS_SOURCE=pypi
fi
if [ -x "$SSLFR_ROOT/.venv/bin/python" ]; then
  export VIRTUAL_ENV="$SSLFR_ROOT/.venv"
  export PATH="$VIRTUAL_ENV/bin:$PATH"
  if [ "$SSLFR_ROS_SOURCE" = pypi ]; then
    export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
    export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
    # What the wheels' ros_wheels_bootstrapper.pth does by re-executing every Python
    # process: put the ROS shared libraries on LD_LIBRARY_PATH. Done once here, so
    # node processes start once (faster, and a stale guard variable cannot break it).
    _sslfr_libs="$VIRTUAL_ENV/lib"
    for _d in "$VIRTUAL_ENV"/lib/python3*/site-packages/ros_*.libs; do
      [ -d "$_d" ] && _sslfr_libs="$_sslfr_libs:$_d"
    done
    export LD_LIBRARY_PATH="$_sslfr_libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
    unset _sslfr_libs _d
  fi
fi
if [ -f "$SSLFR_ROOT/ros_ws/install/setup.bash" ]; then
  # colcon's setup scripts reference unset variables
  set +u; . "$SSLFR_ROOT/ros_ws/install/setup.bash"
fi
# Keep DDS traffic on this machine unless the operator opens it (docs/deploy.md).
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
