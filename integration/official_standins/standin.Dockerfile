# A stand-in for ros:@DISTRO@-ros-base, made from what this machine reaches (Debian 12's packages, PyPI's ROS 2
# wheels), with the contract robocore's official base relies on: /ros_entrypoint.sh, /opt/ros/@DISTRO@/setup.bash,
# apt (Debian's mirror plus a local "ROS apt repository"), rosdep with an offline database and (ROS 2) colcon.
# Built by integration/official_standins (which appends the LABEL step); tree/install.sh does the work.
ARG ROOT
FROM ${ROOT}
COPY tree/ /tmp/standin/
RUN ["/bin/bash", "/tmp/standin/install.sh"]
ENV ROS_DISTRO=@DISTRO@ LANG=C.UTF-8 LC_ALL=C.UTF-8 ROSDISTRO_INDEX_URL=file:///etc/ros/rosdistro/index-v4.yaml
ENTRYPOINT ["/ros_entrypoint.sh"]
CMD ["bash"]
