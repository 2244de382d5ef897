# Shared by the scripts: Debian packages, environment and build steps. Source, don't run.
# ROS Python tools need Debian's python3 (the first python3 on PATH may lack ROS modules).
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:${PATH}"

BOARD_CALIB_ROOT="$(cd -P "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Not under build/: rosrun skips every executable below <package>/build/ (and the package is the
# repository root). Personal builds under build/<you> stay invisible to rosrun, so it never sees
# two copies of a tool.
BOARD_CALIB_BUILD="${BOARD_CALIB_BUILD:-${BOARD_CALIB_ROOT}/ws/ci}"

BOARD_CALIB_PACKAGES=(
  catkin ros-base-dev rosbash python3-dynamic-reconfigure libtf2-ros-dev libtf2-eigen-dev
  libcv-bridge-dev libimage-transport-dev libmessage-filters-dev libdiagnostic-updater-dev
  libopencv-dev libceres-dev libeigen3-dev libapriltag-dev libyaml-cpp-dev python3-rostest python3-sensor-msgs libgtest-dev
  python3-tf2-msgs python3-yaml python3-numpy cmake g++ make rviz xvfb ccache
  # To watch a session: rostopic echo /diagnostics, tf_echo / view_frames, a tf2 listener in
  # Python, image_view for the overlay (Debian 12 ships no rqt; image_view's package.xml and
  # nodelet plugin description are in libimage-view-dev, without them it cannot load its nodelet).
  python3-diagnostic-msgs tf-tools python3-tf2-ros ros-image-view libimage-view-dev
  # The rviz panel (librviz-dev) and its headless test (xdotool clicks, std_srvs from Python).
  librviz-dev xdotool python3-std-srvs
  # bench_pcl only (PCL's components against the detector's geometry, docs/DEVELOPING.md): the
  # package itself does not use PCL.
  libpcl-dev
)

# Installs whatever is missing (an installed machine skips apt entirely).
board_calib_install_deps() {
  if dpkg -s "${BOARD_CALIB_PACKAGES[@]}" >/dev/null 2>&1; then
    return 0
  fi
  echo "[board_calib] installing Debian packages (first run only, a few minutes)..."
  local sudo=""
  if [ "$(id -u)" != "0" ]; then sudo="sudo"; fi
  $sudo apt-get update
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y --no-install-recommends "${BOARD_CALIB_PACKAGES[@]}"
}

# ROS environment of the scripts' own runs (build, tests, demo): logs, caches and results stay
# inside the build folder, no litter in the home directory.
board_calib_ros_env() {
  export ROS_HOME="${BOARD_CALIB_BUILD}/ros_home"
  export ROS_LOG_DIR="${ROS_HOME}/log"
  export ROS_HOSTNAME=localhost
  export ROSCONSOLE_STDOUT_LINE_BUFFERED=1
  mkdir -p "${ROS_LOG_DIR}"
}

# The user's environment (scripts/env.sh): their own ROS_HOME (default ~/.ros), so results land
# in ~/.ros/board_calib as README says; localhost unless they chose a host or IP.
board_calib_user_ros_env() {
  if [ -z "${ROS_HOSTNAME}" ] && [ -z "${ROS_IP}" ]; then export ROS_HOSTNAME=localhost; fi
  export ROSCONSOLE_STDOUT_LINE_BUFFERED=1
}

board_calib_build() {
  local targets=("$@")
  # Paths relative to the build's parent folder so clones elsewhere share the cache.
  export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$(dirname "${BOARD_CALIB_ROOT}")}"
  mkdir -p "${BOARD_CALIB_BUILD}"
  board_calib_ros_env
  if [ ! -f "${BOARD_CALIB_BUILD}/Makefile" ]; then
    # ccache: rebuilds of unchanged translation units (other clones, worktrees) come from the cache.
    local launcher=()
    if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
    # BOARD_CALIB_CMAKE_ARGS (an array) adds or overrides settings, e.g. the sanitizer build.
    cmake -S "${BOARD_CALIB_ROOT}" -B "${BOARD_CALIB_BUILD}" -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" \
      -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=ON "${BOARD_CALIB_CMAKE_ARGS[@]}" \
      >"${BOARD_CALIB_BUILD}/configure.log" 2>&1 \
      || { cat "${BOARD_CALIB_BUILD}/configure.log"; return 1; }
  fi
  make -C "${BOARD_CALIB_BUILD}" -j"$(nproc)" "${targets[@]:-all}"
}

# Sources the built workspace (not under set -u: ROS profile scripts read unset variables).
#   board_calib_source        the scripts' own runs (ROS_HOME inside the build folder)
#   board_calib_source user   a user's commands (scripts/env.sh: their ROS_HOME)
board_calib_source() {
  if [ "$1" = user ]; then board_calib_user_ros_env; else board_calib_ros_env; fi
  set +u
  # shellcheck disable=SC1091
  source "${BOARD_CALIB_BUILD}/devel/setup.bash"
  # The package root is the repository: make it findable by rospack without a workspace.
  export ROS_PACKAGE_PATH="${BOARD_CALIB_ROOT}:${ROS_PACKAGE_PATH}"
}
