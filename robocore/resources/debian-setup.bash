# ROS 1 from Debian 12's own packages (written by robocore): they live under /usr, where roscore,
# rospack and CMake find them without sourcing anything; this file gives the variables that a
# sourced /opt/ros/<distro>/setup.bash gives on other installations.
export ROS_VERSION=1
export ROS_PYTHON_VERSION=3
export ROS_ROOT="${ROS_ROOT:-/usr/share/ros}"
export ROS_ETC_DIR="${ROS_ETC_DIR:-/etc/ros}"
# Debian's ROS packages are under /usr/share and its CMake files under /usr: after any path already given
case ":${ROS_PACKAGE_PATH:-}:" in
    *:/usr/share:*) ;;
    *) export ROS_PACKAGE_PATH="${ROS_PACKAGE_PATH:+${ROS_PACKAGE_PATH}:}/usr/share" ;;
esac
case ":${CMAKE_PREFIX_PATH:-}:" in
    *:/usr:*) ;;
    *) export CMAKE_PREFIX_PATH="${CMAKE_PREFIX_PATH:+${CMAKE_PREFIX_PATH}:}/usr" ;;
esac
# Debian's catkin environment hook (/etc/catkin/profile.d/1.ros_distro.sh) sets ROS_DISTRO=Debian and
# complains on stdout about any other value, which breaks catkin's generate_cached_setup.py; the
# image links /opt/ros/Debian to this folder, so that sourcing /opt/ros/$ROS_DISTRO still works.
export ROS_DISTRO=Debian
