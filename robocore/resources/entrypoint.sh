#!/bin/bash
# robocore entrypoint: source ROS, the image's underlays (common packages, repositories),
# then the component's install tree if one is mounted, and run the command.
# shellcheck disable=SC1090,SC1091
source "/opt/ros/${ROS_DISTRO}/setup.bash"
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
# ROS 1 on a bridge network: advertise the container's own address (see plan/discovery/rosmaster.py)
if [ -n "${ROBOCORE_ROS_IP_FROM_CONTAINER:-}" ] && [ -z "${ROS_IP:-}${ROS_HOSTNAME:-}" ]; then
    ROS_IP="$(hostname -i 2>/dev/null | cut -d' ' -f1)"
    export ROS_IP
fi
exec "$@"
