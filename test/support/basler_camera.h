// SPDX-License-Identifier: BSD-3-Clause
// The camera of the basler_os1_plain recording (1920x1200, plumb bob): a realistic lens for the
// projection tests and bench. Header only, so the geometry test needs no support library.
#pragma once

#include <board_calib/core/camera_model.h>

namespace board_calib {
namespace sim {

/// The recording's intrinsics with `model`; its own distortion for plumb bob, none otherwise
/// (callers of other models set their coefficients).
inline CameraIntrinsics baslerIntrinsics(DistortionModel model = DistortionModel::kPlumbBob) {
  CameraIntrinsics in;
  in.width = 1920;
  in.height = 1200;
  in.fx = 2813.64;
  in.fy = 2808.33;
  in.cx = 969.29;
  in.cy = 624.05;
  in.model = model;
  if (model == DistortionModel::kPlumbBob) in.coeffs = {-0.1343, -0.0259, 0.00218, 0.00084, 0.0};
  return in;
}

}  // namespace sim
}  // namespace board_calib
