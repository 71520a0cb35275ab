# robocore dev shell: the environment of every login shell (sourced from /etc/profile.d).
# shellcheck shell=sh disable=SC1090,SC1091
if [ -r /run/robocore/path ]; then
    IFS= read -r PATH </run/robocore/path
    export PATH
fi
if [ -n "${BASH_VERSION:-}" ]; then
    _robocore_distro="${ROS_DISTRO:-${ROBOCORE_ROS_DISTRO:-}}"
    if [ -n "$_robocore_distro" ] && [ -f "/opt/ros/$_robocore_distro/setup.bash" ]; then
        . "/opt/ros/$_robocore_distro/setup.bash"
    fi
    for _robocore_underlay in /opt/robocore/common /opt/robocore/deps; do
        if [ -f "$_robocore_underlay/local_setup.bash" ]; then
            . "$_robocore_underlay/local_setup.bash"
        fi
    done
    if [ -f /robocore/install/setup.bash ]; then
        . /robocore/install/setup.bash
    fi
    unset _robocore_distro _robocore_underlay
fi
