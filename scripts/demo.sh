#!/usr/bin/env bash
# The main job on its embedded default: installs what is missing, builds, simulates a
# plain-board session (VLP-32C + 1920x1200 camera, ground truth known), calibrates it offline
# with PPC, PBPC and MSG side by side, and prints the result, its quality figures and its
# error against the ground truth. Exit 0 on success.
#   scripts/demo.sh [SCENARIO.yaml]     (default: config/scenarios/plain_vlp32c_1920.yaml)
set -eo pipefail
source "$(dirname "$0")/common.sh"
scenario="${1:-${BOARD_CALIB_ROOT}/config/scenarios/plain_vlp32c_1920.yaml}"

board_calib_install_deps
board_calib_build all
board_calib_source

out="${BOARD_CALIB_BUILD}/demo"
bin="${BOARD_CALIB_BUILD}/devel/lib/board_calib"
mkdir -p "${out}"
echo
echo "== 1. simulating a calibration session: ${scenario}"
"${bin}/simulate_bag" --scenario "${scenario}" --out "${out}/session.bag"

echo
echo "== 2. calibrating it offline (calibrate_bag --method all)"
"${bin}/calibrate_bag" --bag "${out}/session.bag" --target "${out}/session.target.yaml" \
  --image-topic /camera/image_raw --camera-info-topic /camera/camera_info --cloud-topic /lidar/points \
  --method all --output "${out}/result.yaml" --report "${out}/report" --truth "${out}/session.truth.yaml"

echo
echo "== 3. result file (${out}/result.yaml)"
cat "${out}/result.yaml"
echo
echo "Report with per-view residuals and overlay images: ${out}/report/report.md"
echo "Live: roslaunch board_calib calibration.launch (see README.md); several cameras and LiDARs: rig_calibration.launch (docs/MSG.md)."
