# /opt/ros/@DISTRO@/setup.bash of the stand-in: the variables the real one sets, for ROS 2 @DISTRO@ installed
# from PyPI wheels under this prefix (a ROS prefix like the real one: bin, lib, share, include).
_standin_prefix="/opt/ros/@DISTRO@"
_standin_prepend() {
    local current="${!1:-}"
    case ":${current}:" in
        *":$2:"*) ;;
        *) if [ -n "${current}" ]; then export "$1=$2:${current}"; else export "$1=$2"; fi ;;
    esac
}
export ROS_DISTRO=@DISTRO@
export ROS_VERSION=2
export ROS_PYTHON_VERSION=3
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
_standin_prepend PATH "${_standin_prefix}/bin"
_standin_prepend AMENT_PREFIX_PATH "${_standin_prefix}"
_standin_prepend CMAKE_PREFIX_PATH "${_standin_prefix}"
for _standin_site in "${_standin_prefix}"/lib/python3*/site-packages; do
    _standin_prepend PYTHONPATH "${_standin_site}"
    for _standin_libs in "${_standin_site}"/*.libs; do
        if [ -d "${_standin_libs}" ]; then _standin_prepend LD_LIBRARY_PATH "${_standin_libs}"; fi
    done
done
_standin_prepend LD_LIBRARY_PATH "${_standin_prefix}/lib"
unset _standin_prefix _standin_site _standin_libs
unset -f _standin_prepend
