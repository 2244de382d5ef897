#!/usr/bin/env bash
# Runs a command inside the built environment, e.g.
#   scripts/env.sh rosrun board_calib calibrate_bag --help
set -eo pipefail
source "$(dirname "$0")/common.sh"
if [ ! -f "${BOARD_CALIB_BUILD}/devel/setup.bash" ]; then
  echo "board_calib is not built yet: run scripts/build.sh first" >&2
  exit 1
fi
board_calib_source
if [ $# -eq 0 ]; then
  echo "usage: scripts/env.sh CMD [ARGS...]" >&2
  exit 2
fi
exec "$@"
