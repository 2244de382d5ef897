#include "pair_bags.h"

#include <board_calib/bag_reader.h>

#include <unistd.h>

#include <iostream>
#include <map>

namespace board_calib {
namespace {

void progress(bool quiet, size_t done, size_t total, size_t views) {
  if (quiet || total == 0) return;
  // A redrawn bar on a terminal; a line per quarter in logs.
  if (!isatty(STDERR_FILENO)) {
    if (done == total || (4 * done / total) != (4 * (done - 1) / total))
      std::cerr << "calibrate_bag: " << done << "/" << total << " frames, " << views << " views\n";
    return;
  }
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(kWidth * done / total);
  std::cerr << "\r[" << std::string(filled, '#') << std::string(kWidth - filled, '.') << "] "
            << done << "/" << total << " frames, " << views << " views" << std::flush;
  if (done == total) std::cerr << "\n";
}

// The second pass's figures: frames recovered per side and why the others were not.
void printSecondChance(const PipelineOptions& options, const SecondChanceStats& sc) {
  if (!options.prior) return;
  std::cerr << "  " << sc.summary() << "\n";
  for (const auto& [why, n] : sc.images_not_recovered)
    std::cerr << "    image not recovered: " << n << " x " << why << "\n";
  for (const auto& [why, n] : sc.clouds_not_recovered)
    std::cerr << "    cloud not recovered: " << n << " x " << why << "\n";
}

}  // namespace

std::string learnImageScene(const PairBagArgs& args, const Target& target,
                            PipelineOptions* options) {
  // A pattern board is unambiguous: no memory, no pre-pass.
  if (target.type != TargetType::kPlain || !options->image_memory.enabled ||
      options->image_prepass.frames_per_static <= 0)
    return {};
  auto prepass =
      ScenePrepass::create(target, options->image, options->image_memory, options->image_prepass);
  if (!prepass) return prepass.error();
  BagFrameCallbacks cb;
  cb.on_image = [&](const ImageFrame& f, const CameraIntrinsics& intrinsics) {
    prepass->add(f.image, intrinsics, f.stamp);
  };
  cb.on_bad_message = [](const std::string&, const std::string&) {};  // told by the main pass
  const auto read = readBagFrames(args.bags, {{args.image_topic}, {args.info_topic}, {}}, cb);
  if (!read) return read.error();
  options->image_known_scene = prepass->scene();
  if (!args.quiet)
    std::cerr << "calibrate_bag: static scene pre-pass: " << prepass->frames() << " images, "
              << options->image_known_scene.rectangles.size() << " static rectangles, "
              << options->image_known_scene.lines_px.size() << " static lines\n";
  return {};
}

// The one bag-reading loop (bag_reader.h).
std::string readPairBags(const PairBagArgs& args, CalibrationPipeline* pipeline,
                         std::string* camera_frame, std::string* lidar_frame) {
  auto counts = bagTopicCounts(args.bags);
  if (!counts) return counts.error();
  const size_t total = (*counts)[args.image_topic] + (*counts)[args.cloud_topic];
  size_t done = 0;
  bool have_intrinsics = false;
  std::map<std::string, int> bad_messages;

  BagTopics topics{{args.image_topic}, {args.info_topic}, {args.cloud_topic}};
  BagFrameCallbacks cb;
  cb.on_image = [&](const ImageFrame& f, const CameraIntrinsics& intrinsics) {
    have_intrinsics = true;
    pipeline->addImage(f.image, intrinsics, f.frame_id, f.stamp);
    if (camera_frame->empty()) *camera_frame = f.frame_id;
    progress(args.quiet, ++done, total, pipeline->session().views().size());
  };
  cb.on_cloud = [&](const std::string&, const LidarCloud& c) {
    pipeline->addCloud(c);
    if (lidar_frame->empty()) *lidar_frame = c.frame_id;
    progress(args.quiet, ++done, total, pipeline->session().views().size());
  };
  cb.on_bad_message = [&](const std::string& topic, const std::string& why) {
    if (bad_messages[topic + ": " + why]++ == 0 && !args.quiet)
      std::cerr << "\ncalibrate_bag: skipping a message on " << topic << ": " << why << "\n";
  };
  const auto read = readBagFrames(args.bags, topics, cb);
  if (!read) return read.error();
  pipeline->finish();
  if (!have_intrinsics) return "no valid camera_info on '" + args.info_topic + "'";
  if (const auto dropped = read->images_dropped.find(args.image_topic);
      dropped != read->images_dropped.end())
    std::cerr << "calibrate_bag: warning: " << dropped->second
              << " images arrived before the first camera_info on " << args.info_topic
              << " and were skipped (was camera_info recorded after the images?)\n";
  const PipelineStats& st = pipeline->stats();
  if (!args.quiet) {
    std::cerr << "calibrate_bag: board found in " << st.images_with_board << "/" << st.images
              << " images and " << st.clouds_with_board << "/" << st.clouds << " clouds; "
              << pipeline->session().views().size() << " views kept\n"
              << "  capture: " << pipeline->session().captureStats().summary() << "\n";
    for (const auto& [why, n] : st.image_failures)
      std::cerr << "  image: " << n << " x " << why << "\n";
    for (const auto& [why, n] : st.cloud_failures)
      std::cerr << "  cloud: " << n << " x " << why << "\n";
    printSecondChance(pipeline->options(), st.second_chance);
  }
  if (st.images_with_board == 0)
    return "the board was never found in the images (" + args.image_topic + ")";
  if (st.clouds_with_board == 0)
    return "the board was never found in the clouds (" + args.cloud_topic + ")";
  return {};
}

}  // namespace board_calib
