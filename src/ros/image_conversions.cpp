// SPDX-License-Identifier: BSD-3-Clause
// sensor_msgs/Image <-> cv::Mat: encodings checked before cv_bridge sees them (part of the one
// conversions unit, declared in conversions.h).
#include <board_calib/conversions.h>

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/image_encodings.h>
#include <opencv2/imgproc.hpp>

#include <string>

#include "conversion_internal.h"

namespace board_calib {
using conversion_internal::hostIsBigEndian;
using conversion_internal::kMaxImageBytes;
using conversion_internal::kMaxImageSidePx;

namespace {

bool isMono16(const std::string& encoding) {
  namespace enc = sensor_msgs::image_encodings;
  return encoding == enc::MONO16 || encoding == enc::TYPE_16UC1;
}

bool supportedEncoding(const std::string& encoding) {
  namespace enc = sensor_msgs::image_encodings;
  return encoding == enc::MONO8 || isMono16(encoding) || encoding == enc::BGR8 ||
         encoding == enc::RGB8 || encoding == enc::BGRA8 || encoding == enc::RGBA8 ||
         enc::isBayer(encoding);
}

// 16-bit mono, either endianness, to a host-order CV_16UC1 (cv_bridge mishandles big-endian).
cv::Mat decodeMono16(const sensor_msgs::Image& msg) {
  const bool swap = bool(msg.is_bigendian) != hostIsBigEndian();
  cv::Mat raw(static_cast<int>(msg.height), static_cast<int>(msg.width), CV_16UC1);
  for (int r = 0; r < raw.rows; ++r) {
    const uint8_t* src = msg.data.data() + size_t(r) * msg.step;
    auto* dst = raw.ptr<uint16_t>(r);
    for (int c = 0; c < raw.cols; ++c) {
      uint8_t b[2] = {src[2 * c], src[2 * c + 1]};
      if (swap) std::swap(b[0], b[1]);
      std::memcpy(&dst[c], b, 2);
    }
  }
  return raw;
}

}  // namespace

std::string validateImage(const sensor_msgs::Image& msg) {
  namespace enc = sensor_msgs::image_encodings;
  const uint64_t width = msg.width, height = msg.height, step = msg.step;
  if (width == 0 || height == 0)
    return "image is empty (" + std::to_string(width) + " x " + std::to_string(height) + ")";
  if (width > kMaxImageSidePx || height > kMaxImageSidePx)
    return "image size " + std::to_string(width) + " x " + std::to_string(height) + " exceeds " +
           std::to_string(kMaxImageSidePx) + " px per side";
  if (!supportedEncoding(msg.encoding))
    return "unsupported image encoding '" + msg.encoding +
           "' (supported: mono8, mono16, 16UC1, bgr8, rgb8, bgra8, rgba8, bayer_*)";
  const uint64_t elem_bytes =
      uint64_t(enc::numChannels(msg.encoding)) * uint64_t(enc::bitDepth(msg.encoding)) / 8;
  if (step < width * elem_bytes)
    return "image step " + std::to_string(step) + " is smaller than width*" +
           std::to_string(elem_bytes) + " = " + std::to_string(width * elem_bytes) + " bytes for " +
           msg.encoding;
  if (height * step > kMaxImageBytes)
    return "image height*step = " + std::to_string(height * step) + " bytes exceeds " +
           std::to_string(kMaxImageBytes);
  if (uint64_t(msg.data.size()) < height * step)
    return "image data holds " + std::to_string(msg.data.size()) + " bytes, height*step needs " +
           std::to_string(height * step);
  if (enc::bitDepth(msg.encoding) > 8 && !isMono16(msg.encoding) &&
      bool(msg.is_bigendian) != hostIsBigEndian())
    return "image encoding '" + msg.encoding +
           "' in foreign byte order is not supported (mono16 is)";
  return {};
}

Expected<cv::Mat> imageFromMsg(const sensor_msgs::Image& msg) {
  namespace enc = sensor_msgs::image_encodings;
  if (const std::string why = validateImage(msg); !why.empty())
    return Expected<cv::Mat>::failure(why);
  try {
    if (isMono16(msg.encoding)) {
      const cv::Mat raw = decodeMono16(msg);
      double max_value = 0.0;
      cv::minMaxLoc(raw, nullptr, &max_value);
      cv::Mat out;
      raw.convertTo(out, CV_8U, max_value > 0 ? 255.0 / max_value : 1.0);
      return out;
    }
    if (msg.encoding == enc::MONO8) return cv_bridge::toCvCopy(msg, enc::MONO8)->image;
    return cv_bridge::toCvCopy(msg, enc::BGR8)->image;
  } catch (const cv_bridge::Exception& e) {
    return Expected<cv::Mat>::failure("cannot convert image with encoding '" + msg.encoding +
                                      "': " + e.what());
  } catch (const cv::Exception& e) {
    // e.err is the short description; what() carries source paths and line numbers.
    return Expected<cv::Mat>::failure("cannot convert image with encoding '" + msg.encoding +
                                      "': " + e.err);
  }
}

Expected<sensor_msgs::Image> imageToMsg(const cv::Mat& image, const std_msgs::Header& header) {
  namespace enc = sensor_msgs::image_encodings;
  if (image.empty()) return Expected<sensor_msgs::Image>::failure("image is empty");
  std::string encoding;
  if (image.type() == CV_8UC3)
    encoding = enc::BGR8;
  else if (image.type() == CV_8UC1)
    encoding = enc::MONO8;
  else
    return Expected<sensor_msgs::Image>::failure(
        "only CV_8UC3 (bgr8) and CV_8UC1 (mono8) images can be sent");
  sensor_msgs::Image msg;
  cv_bridge::CvImage(header, encoding, image).toImageMsg(msg);
  return msg;
}

}  // namespace board_calib
