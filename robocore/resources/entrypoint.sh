#!/bin/bash
# robocore entrypoint: source ROS, the image's underlays (common packages, repositories),
# then the component's install tree if one is mounted, and run the command.
# shellcheck disable=SC1090,SC1091
source "/opt/ros/${ROS_DISTRO}/setup.bash"
# colcon's local_setup scripts run a Python helper each: a quick interpreter for it (see setup-python), unless
# the caller chose one
_robocore_colcon_python="${COLCON_PYTHON_EXECUTABLE-unset}"
if [ "${_robocore_colcon_python}" = unset ] && [ -x /robocore/setup-python ]; then
    export COLCON_PYTHON_EXECUTABLE=/robocore/setup-python
fi
for _robocore_underlay in /opt/robocore/common /opt/robocore/deps; do
    if [ -f "${_robocore_underlay}/local_setup.bash" ]; then
        source "${_robocore_underlay}/local_setup.bash"
    fi
done
unset _robocore_underlay
# local_setup: the underlays it was built on are the ones sourced above
if [ -z "${ROBOCORE_NO_INSTALL:-}" ] && [ -f /robocore/install/local_setup.bash ]; then
    source /robocore/install/local_setup.bash
fi
if [ "${_robocore_colcon_python}" = unset ]; then
    unset COLCON_PYTHON_EXECUTABLE
fi
unset _robocore_colcon_python
# ROS 1 on a bridge network: advertise the container's own address (see plan/discovery/rosmaster.py)
if [ -n "${ROBOCORE_ROS_IP_FROM_CONTAINER:-}" ] && [ -z "${ROS_IP:-}${ROS_HOSTNAME:-}" ]; then
    ROS_IP="$(hostname -i 2>/dev/null | cut -d' ' -f1)"
    export ROS_IP
fi
exec "$@"
