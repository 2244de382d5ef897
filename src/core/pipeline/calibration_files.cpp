// The calibrator's output files (see calibration_files.h).
#include <board_calib/core/file_io.h>
#include <board_calib/core/pipeline/calibration_files.h>

#include <filesystem>
#include <iomanip>
#include <sstream>

namespace board_calib {
Expected<std::string> writeCalibrationFiles(const std::string& dir, const std::string& name,
                                            const ResultFile& file,
                                            const std::vector<Snippet>& snippets,
                                            std::vector<std::string>* warnings) {
  if (Status st = createFolder(dir); !st) return Expected<std::string>::failure(st.reason);
  const std::string base = dir + "/" + name;
  if (Status st = writeResultFile(base + "_result.yaml", file); !st)
    return Expected<std::string>::failure(st.reason);
  for (const auto& [suffix, text] : snippets)
    if (Status st = writeFileAtomic(base + suffix, text); !st && warnings)
      warnings->push_back(st.reason);
  return base + "_result.yaml";
}

Expected<std::string> writeFailedCalibrationFile(const std::string& dir, const std::string& name,
                                                 const ResultFile& file) {
  if (Status st = createFolder(dir); !st) return Expected<std::string>::failure(st.reason);
  const std::string path = failedResultPath(dir + "/" + name + "_result.yaml");
  if (Status st = writeResultFile(path, file); !st)
    return Expected<std::string>::failure(st.reason);
  return path;
}

std::string rigStaticTransformsLaunch(const multi_sensor::MsgSolution& s,
                                      const std::string& child_suffix) {
  std::ostringstream launch;
  launch << std::setprecision(9) << "<launch>\n"
         << "  <!-- Needs tf2_ros's static_transform_publisher (ROS Noetic; Debian's ROS "
            "packages lack it: there run\n"
         << "       roslaunch board_calib publish_calibration.launch "
            "result_file:=msg_rig_result.yaml) -->\n";
  const std::string& parent = s.sensors[static_cast<size_t>(s.reference_sensor)].frame;
  for (size_t k = 0; k < s.sensors.size(); ++k) {
    if (static_cast<int>(k) == s.reference_sensor) continue;
    const auto& e = s.sensors[k];
    const Eigen::Vector3d t = e.reference_T_sensor.translation();
    const Eigen::Quaterniond q(e.reference_T_sensor.linear());
    launch << "  <node pkg=\"tf2_ros\" type=\"static_transform_publisher\" name=\"board_calib_"
           << e.frame << "\" args=\"" << t.x() << " " << t.y() << " " << t.z() << " " << q.x()
           << " " << q.y() << " " << q.z() << " " << q.w() << " " << parent << " "
           << e.frame + child_suffix << "\"/>\n";
  }
  launch << "</launch>\n";
  return launch.str();
}

std::vector<std::string> rigHealthLines(const std::vector<multi_sensor::RigSensorHealth>& health) {
  std::vector<std::string> lines;
  for (const auto& h : health)
    lines.push_back("`" + h.name + "` (" + h.frame + "): board in " +
                    std::to_string(h.counts.found) + "/" + std::to_string(h.counts.messages) +
                    " frames, in " + std::to_string(h.pose_ids.size()) + " poses");
  return lines;
}

Expected<std::string> autosavePath(const std::string& output_dir, const std::string& file_name) {
  if (Status st = createFolder(output_dir); !st) return Expected<std::string>::failure(st.reason);
  return output_dir + "/" + file_name;
}

AutosaveRun checkAutosaveRun(const std::string& path, const std::string& run_id) {
  const std::string run_id_path = path + ".run_id";
  std::error_code error;
  AutosaveRun run;
  run.exists = std::filesystem::exists(path, error);
  if (run.exists) {
    const auto previous_run = readTextFile(run_id_path, "autosave run id");
    run.respawned = previous_run && !run_id.empty() && *previous_run == run_id;
  }
  (void)writeFileAtomic(run_id_path, run_id);  // bookkeeping only: a failure costs one resume
  return run;
}

Expected<std::string> moveAutosaveAside(const std::string& path, long long stamp_s) {
  const std::string aside = path + "." + std::to_string(stamp_s);
  std::error_code error;
  std::filesystem::rename(path, aside, error);
  if (error)
    return Expected<std::string>::failure("could not move it aside (" + error.message() + ")");
  return aside;
}

}  // namespace board_calib
