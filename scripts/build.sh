#!/usr/bin/env bash
# Builds board_calib (and its tests) into the git-ignored ws/ci folder.
# Usage: scripts/build.sh [make targets...]   (default: all and tests)
set -eo pipefail
source "$(dirname "$0")/common.sh"
board_calib_install_deps
if [ $# -eq 0 ]; then set -- all tests; fi
board_calib_build "$@"
echo "[board_calib] built in ${BOARD_CALIB_BUILD}; run tools with scripts/env.sh CMD ARGS..."
