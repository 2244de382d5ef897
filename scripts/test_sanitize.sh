#!/usr/bin/env bash
# Sanitizer run (scripts/test.sh --sanitize): AddressSanitizer + UndefinedBehaviorSanitizer
# build in build/asan (separate from ws/ci), then every gtest binary (core unit tests,
# conversions, fuzzers) under ctest. Any sanitizer report fails the run: UBSan is built
# non-recoverable and halts, ASan halts by default, and the log is scanned as a safety net.
set -eo pipefail
source "$(dirname "$0")/common.sh"
export BOARD_CALIB_BUILD="${BOARD_CALIB_ROOT}/build/asan"
sanitize="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
BOARD_CALIB_CMAKE_ARGS=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS=${sanitize}"
  "-DCMAKE_EXE_LINKER_FLAGS=-fsanitize=address,undefined" "-DCMAKE_SHARED_LINKER_FLAGS=-fsanitize=address,undefined")
board_calib_install_deps
board_calib_build help >/dev/null  # configures; 'help' builds nothing
# Every catkin gtest (rostests need a master and are left to the normal run).
mapfile -t targets < <(cd "${BOARD_CALIB_BUILD}" && ctest -N -R '_gtest_' |
  sed -n 's/.*_ctest_board_calib_gtest_\([A-Za-z0-9_]*\)$/\1/p')
if [ ${#targets[@]} -eq 0 ]; then
  echo "no gtest found"
  exit 1
fi
board_calib_build "${targets[@]}"
board_calib_source
cd "${BOARD_CALIB_BUILD}"
# Leak checking needs ptrace, which containers often deny; BOARD_CALIB_DETECT_LEAKS=1 turns it on.
export ASAN_OPTIONS="detect_leaks=${BOARD_CALIB_DETECT_LEAKS:-0}:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
set +e
ctest -R '_gtest_' --output-on-failure -j2 --timeout 1800 >"${BOARD_CALIB_BUILD}/ctest.log" 2>&1
status=$?
set -e
grep -v -E "tests passed, .* tests failed out of" "${BOARD_CALIB_BUILD}/ctest.log" || true
# Reports land in the test logs; ctest keeps a test's output only when it fails, so scan both.
if grep -l -E "ERROR: AddressSanitizer|runtime error:|ERROR: LeakSanitizer" "${BOARD_CALIB_BUILD}/ctest.log" \
     "${BOARD_CALIB_BUILD}"/Testing/Temporary/LastTest.log >/dev/null 2>&1; then
  echo "sanitizer reports found (see ${BOARD_CALIB_BUILD}/Testing/Temporary/LastTest.log)"
  status=1
fi
summary=$(grep -E "tests passed, .* tests failed out of" "${BOARD_CALIB_BUILD}/ctest.log" | tail -n 1)
if [ -z "${summary}" ]; then
  echo "no test ran"
  exit 1
fi
echo "${summary}"
exit ${status}
