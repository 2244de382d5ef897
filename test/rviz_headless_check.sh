#!/bin/bash
# Headless rviz check: starts a private roscore on a free port, runs
# `rviz -d rviz/calibration.rviz` under Xvfb with software GL, and fails unless rviz is still
# running after start-up, subscribed to every topic of the config, and logged no error.
# A screenshot (PNG, from Xvfb's frame buffer) is written to OUT_DIR/calibration_rviz.png.
#
#   test/rviz_headless_check.sh RVIZ_CONFIG OUT_DIR [DEVEL_SETUP]
# With DEVEL_SETUP (the build's devel/setup.bash) and ../shared/data/basler_os1_plain present,
# the check also feeds a frame of that recording (test/publish_frame.py) through the projection
# nodelet (extrinsic: the source authors' one as a static TF) so the screenshot shows real
# data, and fails unless the projection's overlay and coloured cloud reach rviz's topics.
# Exit 0 pass, 1 fail, 77 skipped (rviz or xvfb-run missing).
#
# Known-benign log lines, not counted as errors:
#  - "[rospack] Error: no such package media_export" and the following
#    "[librospack]: error while executing command": rviz asks rospack for optional
#    media_export plugins, which Debian does not package.
#  - "QStandardPaths: XDG_RUNTIME_DIR not set": Qt default when no desktop session exists.
export PATH=/usr/bin:$PATH

if [ "$1" = "--inner" ]; then
  # Runs inside xvfb-run: start rviz, wait until it subscribed, grab the frame buffer, stop it.
  config=$2 out=$3 fbdir=$4 expected=$5 fixed_frame=$6
  rviz -d "$config" -f "$fixed_frame" > "$out/rviz.log" 2>&1 &
  rviz_pid=$!
  subscribed=0
  for _ in $(seq 1 60); do
    sleep 1
    kill -0 $rviz_pid 2> /dev/null || break
    node=$(rosnode list 2> /dev/null | grep -m1 '^/rviz')
    [ -n "$node" ] || continue
    rosnode info "$node" 2> /dev/null > "$out/rviz_node_info.txt"
    missing=0
    for topic in $expected; do
      grep -q "^ \* /$topic \[" "$out/rviz_node_info.txt" || missing=1
    done
    if [ $missing = 0 ]; then subscribed=1; break; fi
  done
  # With data: wait until the projection's overlay flows (lazy: it starts once rviz listens).
  [ "$WITH_DATA" = 1 ] && timeout 60 rostopic echo -n 1 --noarr /overlay/header > /dev/null 2>&1
  sleep 5  # let it render a few frames with the displays loaded
  alive=0
  kill -0 $rviz_pid 2> /dev/null && alive=1
  cp "$fbdir/Xvfb_screen0" "$out/calibration_rviz.xwd" 2> /dev/null
  kill $rviz_pid 2> /dev/null
  wait $rviz_pid 2> /dev/null
  echo "alive=$alive subscribed=$subscribed" > "$out/inner_status.txt"
  exit 0
fi

config=$(readlink -f "$1")
out=$2
devel_setup=$3
here=$(dirname "$(readlink -f "$0")")
bag="$here/../../shared/data/basler_os1_plain/session.bag"
extrinsic="$here/../../shared/tools/mlre/authors_extrinsic_basler_os1.txt"
if ! command -v rviz > /dev/null || ! command -v xvfb-run > /dev/null; then
  echo "SKIP: rviz or xvfb-run not installed"
  exit 77
fi
[ -f "$config" ] || { echo "FAIL: no rviz config $config"; exit 1; }
mkdir -p "$out"
out=$(readlink -f "$out")
rm -f "$out"/rviz.log "$out"/inner_status.txt "$out"/calibration_rviz.* "$out"/rviz_node_info.txt
fbdir=$(mktemp -d)
# rviz loads the package's own panel plugin (rviz_plugins.xml): it needs the built environment.
if [ -n "$devel_setup" ] && [ -f "$devel_setup" ]; then
  # shellcheck disable=SC1090
  source "$devel_setup"
  rospack find board_calib > /dev/null 2>&1 || export ROS_PACKAGE_PATH="$here/..:$ROS_PACKAGE_PATH"
fi

export ROS_HOME="$out/ros_home" ROS_HOSTNAME=localhost LIBGL_ALWAYS_SOFTWARE=1
port=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("localhost", 0)); print(s.getsockname()[1])')
export ROS_MASTER_URI=http://localhost:$port
roscore -p "$port" > "$out/roscore.log" 2>&1 &
roscore_pid=$!
cleanup() {
  [ -n "$data_pids" ] && kill $data_pids 2> /dev/null
  kill $roscore_pid 2> /dev/null
  wait $roscore_pid 2> /dev/null
  rm -rf "$fbdir"
}
trap cleanup EXIT
for _ in $(seq 1 30); do
  rosnode list > /dev/null 2>&1 && break
  sleep 1
done
rosnode list > /dev/null 2>&1 || { echo "FAIL: roscore did not start on port $port"; cat "$out/roscore.log"; exit 1; }

data_pids=""
fixed_frame=lidar
with_data=0
if [ -n "$devel_setup" ] && [ -f "$devel_setup" ] && [ -f "$bag" ] && [ -f "$extrinsic" ]; then
  with_data=1
  fixed_frame=os1_lidar
  # Static TF os1_lidar -> camera from the 3x4 camera_T_lidar (the transform carries the
  # child's pose in the parent: lidar_T_camera).
  tf_yaml=$(/usr/bin/python3 - "$extrinsic" << 'PY'
import sys
import numpy as np
T = np.loadtxt(sys.argv[1]).reshape(3, 4)
R, t = T[:, :3], T[:, 3]
Ri, ti = R.T, -R.T @ t
w = np.sqrt(max(1e-12, 1 + np.trace(Ri))) / 2
q = [(Ri[2, 1] - Ri[1, 2]) / (4 * w), (Ri[0, 2] - Ri[2, 0]) / (4 * w), (Ri[1, 0] - Ri[0, 1]) / (4 * w), w]
print("{transforms: [{header: {frame_id: os1_lidar}, child_frame_id: camera, transform: "
      "{translation: {x: %.9f, y: %.9f, z: %.9f}, rotation: {x: %.9f, y: %.9f, z: %.9f, w: %.9f}}}]}"
      % tuple(list(ti) + q))
PY
)
  # (tf2_ros's static_transform_publisher is not packaged here: publish /tf_static latched.)
  rostopic pub -l /tf_static tf2_msgs/TFMessage "$tf_yaml" > "$out/static_tf.log" 2>&1 &
  data_pids="$data_pids $!"
  (source "$devel_setup" && exec roslaunch board_calib projection.launch start_manager:=true) \
    > "$out/projection.log" 2>&1 &
  data_pids="$data_pids $!"
  # Frame 0 of the recording, re-stamped at 1 Hz (cheaper and steadier than playing the bag).
  /usr/bin/python3 "$here/publish_frame.py" "$bag" /camera/image_raw /camera/camera_info /os1/points 1.0 \
    > "$out/publish_frame.log" 2>&1 &
  data_pids="$data_pids $!"
fi

# Topics the config subscribes to (relative names resolve to / in the root namespace).
expected="points colored_cloud markers calibration_markers camera_frustum overlay tf"
export WITH_DATA=$with_data
xvfb-run -a -s "-screen 0 1400x900x24 -fbdir $fbdir" bash "$0" --inner "$config" "$out" "$fbdir" "$expected" \
  "$fixed_frame"
if [ $with_data = 1 ]; then
  # The projection must have fed rviz's topics while it ran.
  data_ok=1
  for topic in /overlay /colored_cloud; do
    timeout 20 rostopic echo -n 1 --noarr "$topic/header" > /dev/null 2>&1 || { echo "FAIL: nothing on $topic"; data_ok=0; }
  done
fi

status=$(cat "$out/inner_status.txt" 2> /dev/null)
errors=$(grep -E 'ERROR|Error|error|Failed|failed|FATAL|Segmentation' "$out/rviz.log" |
  grep -v -e 'no such package media_export' -e '\[librospack\]: error while executing command')
fail=0
case "$status" in *alive=1*) ;; *) echo "FAIL: rviz exited during start-up"; fail=1 ;; esac
case "$status" in *subscribed=1*) ;; *) echo "FAIL: rviz did not subscribe to all of: $expected"; fail=1 ;; esac
if [ -n "$errors" ]; then
  echo "FAIL: rviz logged errors:"
  echo "$errors"
  fail=1
fi
if [ -f "$out/calibration_rviz.xwd" ]; then
  /usr/bin/python3 "$(dirname "$0")/xwd_to_png.py" "$out/calibration_rviz.xwd" "$out/calibration_rviz.png" &&
    rm -f "$out/calibration_rviz.xwd" && echo "screenshot: $out/calibration_rviz.png"
fi
if [ $with_data = 1 ] && [ $data_ok != 1 ]; then
  echo "--- projection.log"
  tail -20 "$out/projection.log"
  fail=1
fi
if [ $fail != 0 ]; then
  echo "--- rviz.log"
  cat "$out/rviz.log"
  exit 1
fi
data_note=""
[ $with_data = 1 ] && data_note=" (with a basler_os1_plain frame through the projection nodelet)"
echo "PASS: rviz ran headless with $config$data_note, subscribed to: $expected; no errors in its log"
exit 0
