# /opt/ros/@DISTRO@/setup.bash of the stand-in: the variables the real one sets, for Debian 12's own ROS 1
# packages (under /usr, where roscore, rospack and CMake find them).
export ROS_DISTRO=@DISTRO@
export ROS_VERSION=1
export ROS_PYTHON_VERSION=3
export ROS_ROOT=/usr/share/ros
export ROS_ETC_DIR=/etc/ros
export ROS_MASTER_URI="${ROS_MASTER_URI:-http://localhost:11311}"
case ":${ROS_PACKAGE_PATH:-}:" in
    *:/usr/share:*) ;;
    *) export ROS_PACKAGE_PATH="${ROS_PACKAGE_PATH:+${ROS_PACKAGE_PATH}:}/usr/share" ;;
esac
case ":${CMAKE_PREFIX_PATH:-}:" in
    *:/usr:*) ;;
    *) export CMAKE_PREFIX_PATH="${CMAKE_PREFIX_PATH:+${CMAKE_PREFIX_PATH}:}/usr" ;;
esac
