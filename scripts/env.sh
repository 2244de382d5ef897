#!/usr/bin/env bash
# Runs a command inside the built environment, e.g.
#   scripts/env.sh rosrun board_calib calibrate_bag --help
#   scripts/env.sh bash        (a shell for README's roslaunch / rosservice commands)
# Keeps the caller's ROS_HOME (default ~/.ros): results land in ~/.ros/board_calib.
set -eo pipefail
source "$(dirname "$0")/common.sh"
if [ ! -f "${BOARD_CALIB_BUILD}/devel/setup.bash" ]; then
  echo "board_calib is not built yet: run scripts/build.sh first" >&2
  exit 1
fi
board_calib_source user
if [ $# -eq 0 ]; then
  echo "usage: scripts/env.sh CMD [ARGS...]" >&2
  exit 2
fi
exec "$@"
