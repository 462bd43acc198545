# Sourced by the runners of tools/ (from the workspace root): Debian's python3 first, ROS_HOME under out/ unless set,
# the devel space's environment, out/bench/ made.
export PATH=/usr/bin:/bin:$PATH
export ROS_HOME=${ROS_HOME:-$PWD/out/ros}
# In a function, so that catkin's setup.bash does not take the runner's arguments for its own.
exocet_source_devel_space() {
  set +u  # setup.bash reads unset variables
  # shellcheck disable=SC1091
  source devel/setup.bash
  set -u
}
exocet_source_devel_space
mkdir -p out/bench
