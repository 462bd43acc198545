# Sourced by the runners of tools/ (from the workspace root): Debian's python3 first, ROS_HOME under out/ unless set,
# the devel space's environment, out/bench/ made.
export PATH=/usr/bin:/bin:$PATH
export ROS_HOME=${ROS_HOME:-$PWD/out/ros}
set +u  # setup.bash reads unset variables
# shellcheck disable=SC1091
source devel/setup.bash
set -u
mkdir -p out/bench
