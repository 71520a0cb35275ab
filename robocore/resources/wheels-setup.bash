# ROS 2 @DISTRO@ from PyPI wheels (written by robocore): the environment the official
# images' /opt/ros/<distro>/setup.bash gives, for the virtual environment below.
# shellcheck disable=SC2155
_robocore_venv="/opt/ros/@DISTRO@/venv"

_robocore_prepend() {
    # _robocore_prepend VAR DIR: put DIR first in the colon list VAR, once.
    local current="${!1:-}"
    case ":${current}:" in
        *":$2:"*) ;;
        *) if [ -n "${current}" ]; then export "$1=$2:${current}"; else export "$1=$2"; fi ;;
    esac
}

export ROS_DISTRO="@DISTRO@"
export ROS_VERSION=2
export ROS_PYTHON_VERSION=3
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
export VIRTUAL_ENV="${_robocore_venv}"
_robocore_prepend PATH "${_robocore_venv}/bin"
_robocore_prepend AMENT_PREFIX_PATH "${_robocore_venv}"
for _robocore_libs in "${_robocore_venv}"/lib/python3*/site-packages/*.libs; do
    if [ -d "${_robocore_libs}" ]; then
        _robocore_prepend LD_LIBRARY_PATH "${_robocore_libs}"
    fi
done
_robocore_prepend LD_LIBRARY_PATH "${_robocore_venv}/lib"
unset _robocore_libs _robocore_venv
unset -f _robocore_prepend
