#!/usr/bin/env bash
# Installs what is missing, builds, runs every test (gtest + rostest + checks) and prints the
# summary. Exits non-zero if anything failed or no test ran. ctest's summary is the last line.
#   scripts/test.sh --sanitize   ASan + UBSan build in build/asan; runs every gtest (unit tests
#                                and the fuzzers) and fails on any sanitizer report.
set -eo pipefail
source "$(dirname "$0")/common.sh"
if [ "${1:-}" = "--sanitize" ]; then
  exec bash "$(dirname "$0")/test_sanitize.sh"
fi
board_calib_install_deps
board_calib_build all tests
board_calib_source
cd "${BOARD_CALIB_BUILD}"
set +e
ctest --output-on-failure -j2 --timeout 900 >"${BOARD_CALIB_BUILD}/ctest.log" 2>&1
status=$?
set -e
grep -v -E "tests passed, .* tests failed out of" "${BOARD_CALIB_BUILD}/ctest.log" || true
# Catkin writes every result file; catkin_test_results counts the failures inside them too.
catkin_test_results "${BOARD_CALIB_BUILD}/test_results" || status=1
summary=$(grep -E "tests passed, .* tests failed out of" "${BOARD_CALIB_BUILD}/ctest.log" | tail -n 1)
if [ -z "${summary}" ]; then
  echo "no test ran"
  exit 1
fi
echo "${summary}"
exit ${status}
