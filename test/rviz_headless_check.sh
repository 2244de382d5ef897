#!/bin/bash
# Headless rviz check: starts a private roscore on a free port, runs
# `rviz -d rviz/calibration.rviz` under Xvfb with software GL, and fails unless rviz is still
# running after start-up, subscribed to every topic of the config, and logged no error.
# A screenshot (PNG, from Xvfb's frame buffer) is written to OUT_DIR/calibration_rviz.png.
#
#   test/rviz_headless_check.sh RVIZ_CONFIG OUT_DIR
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
  config=$2 out=$3 fbdir=$4 expected=$5
  rviz -d "$config" > "$out/rviz.log" 2>&1 &
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
if ! command -v rviz > /dev/null || ! command -v xvfb-run > /dev/null; then
  echo "SKIP: rviz or xvfb-run not installed"
  exit 77
fi
[ -f "$config" ] || { echo "FAIL: no rviz config $config"; exit 1; }
mkdir -p "$out"
out=$(readlink -f "$out")
rm -f "$out"/rviz.log "$out"/inner_status.txt "$out"/calibration_rviz.* "$out"/rviz_node_info.txt
fbdir=$(mktemp -d)

export ROS_HOME="$out/ros_home" ROS_HOSTNAME=localhost LIBGL_ALWAYS_SOFTWARE=1
port=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("localhost", 0)); print(s.getsockname()[1])')
export ROS_MASTER_URI=http://localhost:$port
roscore -p "$port" > "$out/roscore.log" 2>&1 &
roscore_pid=$!
cleanup() {
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

# Topics the config subscribes to (relative names resolve to / in the root namespace).
expected="points colored_cloud markers calibration_markers overlay tf"
xvfb-run -a -s "-screen 0 1400x900x24 -fbdir $fbdir" bash "$0" --inner "$config" "$out" "$fbdir" "$expected"

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
if [ $fail != 0 ]; then
  echo "--- rviz.log"
  cat "$out/rviz.log"
  exit 1
fi
echo "PASS: rviz ran headless with $config, subscribed to: $expected; no errors in its log"
exit 0
