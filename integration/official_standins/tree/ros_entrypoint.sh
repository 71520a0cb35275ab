#!/bin/bash
# The official images' entrypoint (stand-in): source ROS, then run the command.
set -e
# shellcheck disable=SC1090
source "/opt/ros/$ROS_DISTRO/setup.bash" --
exec "$@"
