// simulate_bag: writes a synthetic calibration recording (lz4 bag) from a scenario file, with
// the target YAML and the ground truth (result-file format) next to it.
//   rosrun board_calib simulate_bag --scenario FILE.yaml --out X.bag [--seed S]
//       [--target-out T.yaml] [--truth-out G.yaml] [--start-time SEC] [--quiet]
#include <board_calib/conversions.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/sim/scenario.h>

#include <rosbag/bag.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>

namespace {

constexpr double kDefaultStartTime = 1700000000.0;  // s, bag stamps must be > 0

void usage(std::ostream& out) {
  out << "usage: simulate_bag --scenario FILE.yaml --out X.bag [--seed S] [--target-out T.yaml]\n"
         "                    [--truth-out G.yaml] [--start-time SEC] [--quiet]\n"
         "Writes X.bag (lz4) with /<camera>/image_raw, /<camera>/camera_info and /<lidar>/points,\n"
         "the target as X.target.yaml and the ground truth as X.truth.yaml (unless overridden).\n"
         "Scenario format: docs/SIMULATOR.md; examples in config/scenarios/.\n";
}

std::string stem(const std::string& bag_path) {
  const std::string suffix = ".bag";
  if (bag_path.size() > suffix.size() &&
      bag_path.compare(bag_path.size() - suffix.size(), suffix.size(), suffix) == 0)
    return bag_path.substr(0, bag_path.size() - suffix.size());
  return bag_path;
}

int fail(const std::string& reason) {
  std::cerr << "simulate_bag: " << reason << std::endl;
  return 1;
}

struct SimArgs {
  std::string scenario_path, out_path, target_out, truth_out;
  bool have_seed = false, quiet = false;
  unsigned long seed = 0;
  double start_time = kDefaultStartTime;
};

// Parses the command line into `args`; returns the exit code when the tool must stop here
// (help, bad arguments), -1 to go on.
int parseArgs(int argc, char** argv, SimArgs* args) {
  SimArgs& a = *args;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](const char* name) -> const char* {
      if (i + 1 >= argc) return nullptr;
      (void)name;
      return argv[++i];
    };
    if (arg == "-h" || arg == "--help") {
      usage(std::cout);
      return 0;
    } else if (arg == "--quiet") {
      a.quiet = true;
    } else if (arg == "--scenario" || arg == "--out" || arg == "--seed" || arg == "--target-out" ||
               arg == "--truth-out" || arg == "--start-time") {
      const char* v = value(arg.c_str());
      if (!v) return fail("option " + arg + " needs a value");
      try {
        if (arg == "--scenario") a.scenario_path = v;
        if (arg == "--out") a.out_path = v;
        if (arg == "--target-out") a.target_out = v;
        if (arg == "--truth-out") a.truth_out = v;
        if (arg == "--seed") {
          a.seed = std::stoul(v);
          a.have_seed = true;
        }
        if (arg == "--start-time") a.start_time = std::stod(v);
      } catch (const std::exception&) {
        return fail("option " + arg + " needs a number, got '" + std::string(v) + "'");
      }
    } else {
      usage(std::cerr);
      return fail("unknown argument '" + arg + "'");
    }
  }
  if (a.scenario_path.empty() || a.out_path.empty()) {
    usage(std::cerr);
    return fail("--scenario and --out are required");
  }
  if (!(a.start_time > 0)) return fail("--start-time must be > 0");
  if (a.target_out.empty()) a.target_out = stem(a.out_path) + ".target.yaml";
  if (a.truth_out.empty()) a.truth_out = stem(a.out_path) + ".truth.yaml";

  return -1;
}

// Every frame of the timeline into the bag; the counts of images and clouds written.
board_calib::Status writeBag(const SimArgs& args, const board_calib::sim::Scenario& scenario,
                             const board_calib::sim::Timeline& timeline,
                             board_calib::sim::FrameGenerator& generator, size_t* images,
                             size_t* clouds) {
  using board_calib::Status;
  try {
    rosbag::Bag bag;
    bag.open(args.out_path, rosbag::bagmode::Write);
    bag.setCompression(rosbag::compression::LZ4);
    std::vector<sensor_msgs::CameraInfo> infos;
    for (const auto& c : scenario.cameras) infos.push_back(board_calib::toCameraInfo(c.intrinsics));
    const auto& frames = timeline.frames;
    for (size_t i = 0; i < frames.size(); ++i) {
      const auto& f = frames[i];
      const ros::Time stamp(args.start_time + f.stamp);
      if (f.is_camera) {
        const auto& camera = scenario.cameras[static_cast<size_t>(f.sensor)];
        std_msgs::Header header;
        header.stamp = stamp;
        header.frame_id = camera.frame_id;
        header.seq = static_cast<uint32_t>(*images);
        const cv::Mat image = generator.image(f, i);
        if (image.empty())
          return Status::failure("camera '" + camera.name +
                                 "': rendering failed (invalid render options?)");
        auto msg = board_calib::imageToMsg(image, header);
        if (!msg) return Status::failure(msg.error());
        sensor_msgs::CameraInfo info = infos[static_cast<size_t>(f.sensor)];
        info.header = header;
        bag.write("/" + camera.name + "/image_raw", stamp, *msg);
        bag.write("/" + camera.name + "/camera_info", stamp, info);
        ++*images;
      } else {
        const auto& lidar = scenario.lidars[static_cast<size_t>(f.sensor)];
        sensor_msgs::PointCloud2 msg = board_calib::toPointCloud2(generator.cloud(f, i));
        msg.header.stamp = stamp;
        msg.header.frame_id = lidar.frame_id;
        bag.write("/" + lidar.name + "/points", stamp, msg);
        ++*clouds;
      }
      if (!args.quiet && (i + 1) % 25 == 0)
        std::cerr << "\r" << (i + 1) << "/" << frames.size() << " frames" << std::flush;
    }
    bag.close();
  } catch (const rosbag::BagException& e) {
    return Status::failure("cannot write bag '" + args.out_path + "': " + e.what());
  }
  return Status::success();
}

}  // namespace

int simulate(const SimArgs& args);

int main(int argc, char** argv) {
  SimArgs args;
  if (const int code = parseArgs(argc, argv, &args); code >= 0) return code;
  // A scenario within every bound can still ask for more than the machine holds.
  try {
    return simulate(args);
  } catch (const std::bad_alloc&) {
    return fail(
        "out of memory: the scenario asks for more frames, points or pixels than this "
        "machine holds (fewer poses, shorter holds, lower rates or smaller images)");
  } catch (const std::exception& e) {
    return fail(std::string("simulation failed: ") + e.what());
  }
}

int simulate(const SimArgs& args) {
  const std::string& scenario_path = args.scenario_path;
  const std::string& out_path = args.out_path;
  auto scenario = board_calib::sim::loadScenario(scenario_path);
  if (!scenario) return fail(scenario.error());
  if (args.have_seed) scenario->seed = static_cast<unsigned int>(args.seed);

  const auto t0 = std::chrono::steady_clock::now();
  auto timeline = board_calib::sim::makeTimeline(*scenario);
  if (!timeline) return fail(scenario_path + ": " + timeline.error());
  auto generator = board_calib::sim::FrameGenerator::create(*scenario);
  if (!generator) return fail(generator.error());

  // Write the side files first: a bag without its truth is useless for tests.
  const board_calib::Status target_status = board_calib::writeFileAtomic(
      args.target_out, board_calib::targetToYaml(scenario->scene.target));
  if (!target_status) return fail(target_status.reason);
  const board_calib::Status truth_status =
      board_calib::writeResultFile(args.truth_out, board_calib::sim::groundTruth(*scenario));
  if (!truth_status) return fail(truth_status.reason);

  size_t images = 0, clouds = 0;
  if (const board_calib::Status st =
          writeBag(args, *scenario, *timeline, *generator, &images, &clouds);
      !st)
    return fail(st.reason);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!args.quiet) std::cerr << "\r";
  std::ifstream sized(out_path, std::ios::binary | std::ios::ate);
  const double megabytes = sized ? static_cast<double>(sized.tellg()) / 1e6 : 0.0;
  std::printf(
      "wrote %s: %d poses, %zu images, %zu clouds, %.1f s of recording, %.1f MB, generated in %.1f "
      "s\n",
      out_path.c_str(), scenario->motion.poses, images, clouds, timeline->duration_s, megabytes,
      seconds);
  std::printf("target: %s\ntruth:  %s\n", args.target_out.c_str(), args.truth_out.c_str());
  return 0;
}
