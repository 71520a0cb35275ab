#!/bin/bash
# The stand-in's whole content, run once in a container of its root, which official_standins then commits as one
# layer (each commit costs seconds on these roots). Its settings come from standin.env beside it, the dev machine's
# proxy settings from proxy.env (both written by official_standins).
set -euo pipefail
here="$(dirname "$0")"
# shellcheck disable=SC1091
source "$here/standin.env"  # DISTRO, GENERATION, WHEELS, INSTALLER
set -a
# shellcheck disable=SC1091
source "$here/proxy.env"
set +a
export DEBIAN_FRONTEND=noninteractive
prefix="/opt/ros/${DISTRO}"
mkdir -p "$prefix/bin"
if [ "$GENERATION" = 2 ]; then
    # ROS 2 from PyPI wheels as a ROS prefix (bin, lib, share, include) beside the system python3, as the real
    # images have it; uv (pinned) fetched by the pip wheel Debian's python3-venv ships. The downloads trust the
    # dev machine's CA bundle, which does not stay in the image.
    pip_wheel=$(ls /usr/share/python-wheels/pip-*.whl | head -n 1)
    PIP_CERT="$here/host-ca.pem" python3 "$pip_wheel/pip" install -q --disable-pip-version-check --no-compile \
        --target /tmp/standin-uv "$INSTALLER"
    # shellcheck disable=SC2086
    SSL_CERT_FILE="$here/host-ca.pem" UV_CACHE_DIR=/tmp/standin-uv/cache /tmp/standin-uv/bin/uv pip install \
        --no-progress --compile-bytecode --python /usr/bin/python3 --break-system-packages --prefix "$prefix" $WHEELS
    rm -rf /tmp/standin-uv
    sed "s/@DISTRO@/${DISTRO}/g" "$here/ros2-setup.bash" > "$prefix/setup.bash"
    install -m 755 "$here/ros2" "$prefix/bin/ros2"
else
    sed "s/@DISTRO@/${DISTRO}/g" "$here/ros1-setup.bash" > "$prefix/setup.bash"
    # Debian's ROS environment hook says ROS_DISTRO=Debian (and complains about any other value); the real
    # images' hook says the distro's name
    for hook in /etc/catkin/profile.d/1.ros_distro.sh /usr/share/ros_environment/catkin_env_hook/1.ros_distro.sh; do
        dpkg-divert --quiet --local --rename --add "$hook"
        printf 'export ROS_DISTRO=%s\n' "$DISTRO" > "$hook"
    done
fi
install -m 755 "$here/ros_entrypoint.sh" /ros_entrypoint.sh
python3 "$here/make_ros_repo.py" "$DISTRO" "$GENERATION" "$prefix"
apt-get update
ros=()
if [ "$GENERATION" = 2 ]; then ros=(python3-colcon-common-extensions "ros-${DISTRO}-ros-base"); fi
apt-get install -y --no-install-recommends python3-rosdep2 "${ros[@]}"
# the offline database: Debian's own map of its ROS 1 packages (10-debian.list, for ROS 1 only: it maps std_msgs
# to ROS 1's), the system keys (20-default.list), and the distribution of the rosdistro index
if [ "$GENERATION" = 2 ]; then rm -f /etc/ros/rosdep/sources.list.d/10-debian.list; fi
install -m 644 "$here/20-default.list" /etc/ros/rosdep/sources.list.d/20-default.list
install -D -m 644 "$here/base.yaml" /etc/ros/rosdep/standin/base.yaml
rm -rf /var/lib/apt/lists/* "$here"
