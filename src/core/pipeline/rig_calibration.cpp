// One rig calibration run (see rig_calibration.h).
#include <board_calib/core/common/format.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/pipeline/rig_calibration.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

namespace board_calib {
namespace {

using multi_sensor::BoardPoseObservation;
using multi_sensor::MsgProblem;
using multi_sensor::MsgSolution;
using multi_sensor::pairViews;

int rank(Verdict v) { return v == Verdict::kFailed ? 2 : v == Verdict::kDoubtful ? 1 : 0; }

std::vector<std::pair<int, int>> cameraLidarPairs(const MsgProblem& problem) {
  std::vector<std::pair<int, int>> pairs;
  for (size_t c = 0; c < problem.sensors.size(); ++c)
    for (size_t l = 0; l < problem.sensors.size(); ++l)
      if (problem.sensors[c].kind == multi_sensor::SensorKind::kCamera &&
          problem.sensors[l].kind == multi_sensor::SensorKind::kLidar)
        pairs.emplace_back(static_cast<int>(c), static_cast<int>(l));
  return pairs;
}

// Consistency per camera <- LiDAR pair; an observation inconsistent in more than half of the
// pairs it takes part in (both sensors of a lone pair) is removed from its pose: the sensor
// that saw another object, or a moving board, is outvoted by the others.
MsgProblem withoutInconsistent(const MsgProblem& problem, const Target& target,
                               const ConsistencyOptions& options,
                               std::vector<std::string>* left_out) {
  std::map<std::pair<int, int>, std::pair<int, int>>
      votes;  // (pose, sensor) -> (inconsistent, checked)
  std::map<std::pair<int, int>, std::string> why;
  for (const auto& [c, l] : cameraLidarPairs(problem)) {
    const std::vector<View> views = pairViews(problem, c, l);
    const ConsistencyReport report = checkViewConsistency(views, target, options);
    if (!report.ok || !report.checkable) continue;
    for (const auto& v : report.views) {
      if (!v.usable) continue;
      for (int sensor : {c, l}) {
        auto& vote = votes[{v.view_id, sensor}];
        ++vote.second;
        if (!v.consistent) {
          ++vote.first;
          why[{v.view_id, sensor}] =
              problem.sensors[c].frame + " <- " + problem.sensors[l].frame + ": " + v.reason;
        }
      }
    }
  }
  MsgProblem out = problem;
  for (auto& pose : out.poses)
    for (size_t k = 0; k < out.sensors.size(); ++k) {
      const auto it = votes.find({pose.id, static_cast<int>(k)});
      if (it == votes.end() || 2 * it->second.first <= it->second.second) continue;
      pose.cameras.erase(static_cast<int>(k));
      pose.lidars.erase(static_cast<int>(k));
      left_out->push_back("pose " + std::to_string(pose.id) + ", " + out.sensors[k].frame +
                          " left out (" + why[it->first] + ")");
    }
  out.poses.erase(std::remove_if(out.poses.begin(), out.poses.end(),
                                 [](const BoardPoseObservation& p) {
                                   return p.cameras.size() + p.lidars.size() < 2;
                                 }),
                  out.poses.end());
  return out;
}

// The graph's pair as a pair solution: its transform, covariance and residuals on `views`.
CalibrationSolution pairSolution(const std::vector<View>& views, const Eigen::Isometry3d& T,
                                 const std::optional<Matrix6d>& covariance) {
  CalibrationSolution s;
  s.success = true;
  s.method = Method::kMsgPair;
  s.camera_T_lidar = T;
  s.views_used = static_cast<int>(views.size());
  s.mlre_px = meanLineReprojectionErrorPx(views, T);
  if (auto rms = planeRmsM(views, T)) s.plane_rms_mm = *rms * 1e3;
  s.covariance = covariance ? *covariance : Matrix6d::Zero();
  s.stddev = stddevFromCovariance(s.covariance);
  s.observability.well_conditioned =
      true;  // the graph's covariance carries it; judged by the sigma tests
  for (const auto& v : views) {
    ViewResidual r;
    r.view_id = v.id;
    r.used = true;
    r.mlre_px = viewLineReprojectionErrorPx(v, T);
    for (int j = 0; j < kNumEdges; ++j)
      r.edges[static_cast<size_t>(j)].mlre_px = edgeLineReprojectionErrorPx(v, j, T);
    s.views.push_back(r);
  }
  return s;
}

// The pair's camera planes against its LiDAR's with one free depth scale (a tag_size or a focal
// length off): MSG pairwise on the pair's views, from the graph's pose. Its move applies to the
// graph's pair as well; the verdict judges it as for the pairwise methods.
DeclaredScaleCheck declaredScaleOf(const std::vector<View>& views, const Eigen::Isometry3d& T) {
  SolverOptions options;
  options.compute_covariance = true;
  const CalibrationSolution pair = calibrate(views, Method::kMsgPair, options, T);
  return pair.success ? pair.declared_scale : DeclaredScaleCheck();
}

// The problem without the sensors in `drop`; `index` maps old sensor indices to new ones (-1:
// dropped). The reference moves to `fallback_reference` when it is dropped.
MsgProblem withoutSensors(const MsgProblem& problem, const std::set<int>& drop,
                          int fallback_reference, std::vector<int>* index) {
  MsgProblem out;
  index->assign(problem.sensors.size(), -1);
  for (size_t s = 0; s < problem.sensors.size(); ++s)
    if (!drop.count(static_cast<int>(s))) {
      (*index)[s] = static_cast<int>(out.sensors.size());
      out.sensors.push_back(problem.sensors[s]);
    }
  const int ref =
      drop.count(problem.reference_sensor) ? fallback_reference : problem.reference_sensor;
  out.reference_sensor = (*index)[static_cast<size_t>(ref)];
  for (const auto& p : problem.poses) {
    BoardPoseObservation o;
    o.id = p.id;
    for (const auto& [k, f] : p.cameras)
      if ((*index)[static_cast<size_t>(k)] >= 0) o.cameras[(*index)[static_cast<size_t>(k)]] = f;
    for (const auto& [k, f] : p.lidars)
      if ((*index)[static_cast<size_t>(k)] >= 0) o.lidars[(*index)[static_cast<size_t>(k)]] = f;
    if (!o.cameras.empty() || !o.lidars.empty()) out.poses.push_back(std::move(o));
  }
  return out;
}

// The graph solved; sensors it cannot place (cut off from the reference, too few poses) are
// named in `not_calibrated` and the rest solved without them, so a LiDAR that rarely saw the
// board does not cost the other pairs their results. `problem` becomes the solved one.
MsgSolution solveWithoutUnplaced(MsgProblem* problem, const multi_sensor::MsgGraphOptions& options,
                                 std::vector<std::string>* not_calibrated,
                                 std::vector<int>* solved_index) {
  solved_index->resize(problem->sensors.size());
  for (size_t s = 0; s < solved_index->size(); ++s) (*solved_index)[s] = static_cast<int>(s);
  MsgSolution sol = multi_sensor::solveMsgGraph(*problem, options);
  while (!sol.success && !sol.unplaced.empty()) {
    std::set<int> cut;
    for (const auto& u : sol.unplaced) cut.insert(u.sensor);
    int cameras = 0, first_lidar = -1;
    for (size_t s = 0; s < problem->sensors.size(); ++s) {
      if (cut.count(static_cast<int>(s))) continue;
      if (problem->sensors[s].kind == multi_sensor::SensorKind::kCamera)
        ++cameras;
      else if (first_lidar < 0)
        first_lidar = static_cast<int>(s);
    }
    if (cameras == 0 || first_lidar < 0) break;  // no camera <- LiDAR pair would be left
    for (const auto& u : sol.unplaced)
      not_calibrated->push_back(problem->sensors[static_cast<size_t>(u.sensor)].frame + ": " +
                                u.reason);
    std::vector<int> index;
    *problem = withoutSensors(*problem, cut, first_lidar, &index);
    for (int& k : *solved_index)
      if (k >= 0) k = index[static_cast<size_t>(k)];
    problem->poses.erase(std::remove_if(problem->poses.begin(), problem->poses.end(),
                                        [](const BoardPoseObservation& p) {
                                          return p.cameras.size() + p.lidars.size() < 2;
                                        }),
                         problem->poses.end());
    sol = multi_sensor::solveMsgGraph(*problem, options);
  }
  return sol;
}

// The graph solved without some poses, once per set left out (pairs sharing poses share solves).
// A fold can cut a third sensor off the graph (its few poses were the ones left out), which
// says nothing about this pair: such a fold is solved again without the other sensors that
// lost poses, so the pair's check is not failed by another sensor's thin data.
class FoldSolver {
 public:
  FoldSolver(const MsgProblem& problem, const multi_sensor::MsgGraphOptions& options)
      : problem_(problem), options_(options) {
    options_.compute_covariance = false;
  }
  CalibrationSolution pair(const std::vector<View>& train, const std::vector<View>& all, int camera,
                           int lidar) {
    std::set<int> kept;
    for (const auto& v : train) kept.insert(v.id);
    std::set<int> left;
    for (const auto& v : all)
      if (!kept.count(v.id)) left.insert(v.id);
    MsgProblem fold = problem_;
    fold.poses.erase(
        std::remove_if(fold.poses.begin(), fold.poses.end(),
                       [&](const BoardPoseObservation& p) { return left.count(p.id) > 0; }),
        fold.poses.end());
    auto it = cache_.find(left);
    if (it == cache_.end())
      it = cache_.emplace(left, multi_sensor::solveMsgGraph(fold, options_)).first;
    CalibrationSolution s;
    s.method = Method::kMsgPair;
    Expected<Eigen::Isometry3d> T = it->second.success
                                        ? multi_sensor::sensorTSensor(it->second, camera, lidar)
                                        : Expected<Eigen::Isometry3d>::failure(it->second.reason);
    if (!T) {
      std::set<int> thinned;  // other sensors in a left-out pose
      for (const auto& p : problem_.poses)
        if (left.count(p.id)) {
          for (const auto& c : p.cameras) thinned.insert(c.first);
          for (const auto& l : p.lidars) thinned.insert(l.first);
        }
      thinned.erase(camera);
      thinned.erase(lidar);
      if (!thinned.empty()) {
        std::vector<int> index;
        const MsgProblem reduced = withoutSensors(fold, thinned, lidar, &index);
        const MsgSolution again = multi_sensor::solveMsgGraph(reduced, options_);
        if (again.success)
          T = multi_sensor::sensorTSensor(again, index[static_cast<size_t>(camera)],
                                          index[static_cast<size_t>(lidar)]);
      }
    }
    s.success = static_cast<bool>(T);
    if (T)
      s.camera_T_lidar = *T;
    else
      s.reason = T.error();
    return s;
  }

 private:
  const MsgProblem& problem_;
  multi_sensor::MsgGraphOptions options_;
  std::map<std::set<int>, MsgSolution> cache_;
};

// Loop closure of the pairwise estimates and the known extrinsics, against the graph's own
// uncertainty. Returns the worst verdict of these checks; findings go to `findings`.
Verdict judgeRigChecks(const MsgSolution& sol, const RigConfig& rig,
                       const std::vector<int>& solved_index, const std::vector<RigPairRun>& pairs,
                       const RigCalibrationOptions& o, std::vector<std::string>* findings) {
  Verdict worst = Verdict::kGood;
  double sigma_rot = 0.0, sigma_trans = 0.0;
  for (const auto& p : pairs) {
    sigma_rot = std::max(sigma_rot, p.verdict.stddev.rotation_deg.maxCoeff());
    sigma_trans = std::max(sigma_trans, p.verdict.stddev.translation_m.maxCoeff());
  }
  const double loop_rot = std::max(o.min_loop_rotation_deg, o.loop_sigmas * sigma_rot);
  const double loop_trans = std::max(o.min_loop_translation_m, o.loop_sigmas * sigma_trans);
  if (sol.loop_rotation_max_deg > loop_rot || sol.loop_translation_max_mm * 1e-3 > loop_trans) {
    worst = Verdict::kDoubtful;
    findings->push_back("the pairwise estimates do not close their loops: up to " +
                        formatFixed(sol.loop_rotation_max_deg, 2) + " deg / " +
                        formatFixed(sol.loop_translation_max_mm, 1) + " mm (allowed " +
                        formatFixed(loop_rot, 2) + " deg / " + formatFixed(loop_trans * 1e3, 1) +
                        " mm): a sensor's views disagree with the others'");
  }
  for (const auto& known : rig.known_extrinsics) {
    // The rig's order is the given problem's; a sensor left out shifts the solution's indices.
    auto solved = [&](int k) {
      return k >= 0 && k < static_cast<int>(solved_index.size())
                 ? solved_index[static_cast<size_t>(k)]
                 : -1;
    };
    const int a = solved(rig.sensorIndex(known.a)), b = solved(rig.sensorIndex(known.b));
    if (a < 0 || b < 0 || a >= static_cast<int>(sol.sensors.size()) ||
        b >= static_cast<int>(sol.sensors.size()))
      continue;
    const auto consistency = multi_sensor::stereoConsistency(sol, a, b, known.a_T_b);
    if (!consistency) continue;
    const auto cov = multi_sensor::relativeCovariance(sol, a, b);
    const PoseStddev sd = cov ? stddevFromCovariance(*cov) : PoseStddev{};
    const double rot_tol = o.known_floor_rotation_deg + o.known_sigmas * sd.rotation_deg.norm();
    const double trans_tol = o.known_floor_translation_m + o.known_sigmas * sd.translation_m.norm();
    const std::string text =
        known.a + " <- " + known.b +
        " against the known extrinsic: " + formatFixed(consistency->rotation_deg, 3) + " deg / " +
        formatFixed(consistency->translation_mm, 1) + " mm (allowed " + formatFixed(rot_tol, 3) +
        " deg / " + formatFixed(trans_tol * 1e3, 1) + " mm)";
    const bool off =
        consistency->rotation_deg > rot_tol || consistency->translation_mm * 1e-3 > trans_tol;
    findings->push_back(text);
    if (off) worst = Verdict::kDoubtful;
  }
  return worst;
}

void addVerdicts(RigCalibration* run) {
  ResultFile& r = run->result;
  r.verdict = verdictName(run->verdict);
  r.verdict_reason = run->reason;
  r.views_to_check = run->views_to_check;
  for (size_t i = 0; i < run->pairs.size() && i < r.pairs.size(); ++i) {
    const RigPairRun& p = run->pairs[i];
    PairEntry& e = r.pairs[i];
    e.verdict = verdictName(p.verdict.verdict);
    e.verdict_reason = p.verdict.reason;
    e.views_to_check = p.verdict.views_to_check;
    e.stddev = p.verdict.stddev;  // grown with the residuals beyond the noise model
  }
  if (!run->pairs.empty() && !r.pairs.empty()) r.stddev = r.pairs.front().stddev;
  for (const auto& text : run->left_out) r.notes.push_back(text);
  for (const auto& text : run->rig_findings) r.notes.push_back(text);
  for (const auto& text : run->not_calibrated) r.notes.push_back("not calibrated: " + text);
}

}  // namespace

std::string RigCalibrationOptions::validate() const {
  if (auto why = graph.validate(); !why.empty()) return "graph: " + why;
  if (auto why = consistency.validate(); !why.empty()) return "consistency: " + why;
  if (auto why = verdict.validate(); !why.empty()) return "verdict: " + why;
  for (double v : {loop_sigmas, min_loop_rotation_deg, min_loop_translation_m, known_sigmas,
                   known_floor_rotation_deg, known_floor_translation_m})
    if (!std::isfinite(v) || !(v > 0))
      return "loop and known-extrinsic tolerances must be finite and > 0";
  return {};
}

RigCalibration calibrateRig(const MsgProblem& problem, const RigConfig& rig, const Target& target,
                            const RigCalibrationOptions& options) {
  RigCalibration run;
  run.problem = problem;
  auto fail = [&](const std::string& why) {
    run.verdict = Verdict::kFailed;
    run.reason = why;
    run.result.method = "msg";
    run.result.verdict = verdictName(Verdict::kFailed);
    run.result.verdict_reason = why;
    return run;
  };
  if (auto why = options.validate(); !why.empty()) return fail("invalid options: " + why);
  if (problem.poses.empty())
    return fail("no board poses: hold the board still where at least two sensors see it");
  run.problem = withoutInconsistent(problem, target, options.consistency, &run.left_out);
  run.solution =
      solveWithoutUnplaced(&run.problem, options.graph, &run.not_calibrated, &run.solved_index);
  if (!run.solution.success) {
    std::string cut;
    for (const auto& n : run.not_calibrated) cut += "; without " + n;
    return fail("MSG graph failed: " + run.solution.reason + cut);
  }
  run.result = multi_sensor::msgResultFile(run.problem, run.solution);

  FoldSolver folds(run.problem, options.graph);
  std::set<int> to_check;
  for (const auto& est : run.solution.pairs) {
    RigPairRun p;
    p.camera = est.camera;
    p.lidar = est.lidar;
    p.camera_frame = run.solution.sensors[static_cast<size_t>(est.camera)].frame;
    p.lidar_frame = run.solution.sensors[static_cast<size_t>(est.lidar)].frame;
    const std::vector<View> views = pairViews(run.problem, est.camera, est.lidar);
    p.consistency = checkViewConsistency(views, target, options.consistency);
    p.views = p.consistency.ok ? consistentViews(views, p.consistency) : views;
    p.solution =
        pairSolution(p.views, est.camera_T_lidar,
                     est.has_covariance ? std::optional<Matrix6d>(est.covariance) : std::nullopt);
    p.solution.declared_scale = declaredScaleOf(p.views, est.camera_T_lidar);
    if (est.has_covariance) {
      p.solution.covariance += declaredScaleUncertainty(p.solution.declared_scale);
      p.solution.stddev = stddevFromCovariance(p.solution.covariance);
    }
    std::function<CalibrationSolution(const std::vector<View>&)> refit;
    if (options.cross_validate)
      refit = [&](const std::vector<View>& train) {
        return folds.pair(train, p.views, est.camera, est.lidar);
      };
    p.verdict = judgeSolution(p.solution, p.views, target, p.consistency, refit, options.verdict);
    if (options.check_against_pbpc)
      if (const auto referee =
              pbpcReferee(p.views, target, p.consistency, options.pbpc_solver, options.verdict,
                          options.cross_validate, est.camera_T_lidar))
        judgeAgainstPbpc(*referee, p.solution, options.verdict, &p.verdict);
    to_check.insert(p.verdict.views_to_check.begin(), p.verdict.views_to_check.end());
    run.pairs.push_back(std::move(p));
  }
  // Overall: the worst pair, then the rig's own checks.
  const RigPairRun* worst = nullptr;
  for (const auto& p : run.pairs)
    if (!worst || rank(p.verdict.verdict) > rank(worst->verdict.verdict)) worst = &p;
  const Verdict rig_checks =
      judgeRigChecks(run.solution, rig, run.solved_index, run.pairs, options, &run.rig_findings);
  run.verdict = worst ? worst->verdict.verdict : Verdict::kFailed;
  run.reason =
      worst ? worst->camera_frame + " <- " + worst->lidar_frame + ": " + worst->verdict.reason
            : "the rig has no camera <- LiDAR pair to judge";
  if (rank(rig_checks) > rank(run.verdict)) {
    run.verdict = rig_checks;
    run.reason = run.rig_findings.front();
  }
  if (!run.not_calibrated.empty()) {
    std::string names;
    for (const auto& n : run.not_calibrated) names += (names.empty() ? "" : "; ") + n;
    run.verdict = Verdict::kFailed;
    run.reason = "not every sensor could be calibrated: " + names + ". The other sensors were " +
                 (run.not_calibrated.size() == 1 ? "solved without it" : "solved without them") +
                 "; their pairs are for inspection";
    const std::string& reference = run.solution.sensors[run.solution.reference_sensor].frame;
    if (reference != problem.sensors[static_cast<size_t>(problem.reference_sensor)].frame)
      run.reason += " (relative to '" + reference + "', the reference being left out)";
  }
  run.views_to_check.assign(to_check.begin(), to_check.end());
  addVerdicts(&run);
  return run;
}

std::string rigVerdictSummary(const RigCalibration& run) {
  std::ostringstream s;
  std::string upper = verdictName(run.verdict);
  std::transform(upper.begin(), upper.end(), upper.begin(), ::toupper);
  s << "VERDICT: " << upper << " - " << run.reason << "\n";
  s << "  board poses: " << run.problem.poses.size() << " solved";
  if (!run.left_out.empty())
    s << ", " << run.left_out.size() << " observation(s) left out as inconsistent";
  s << "\n";
  for (const auto& p : run.pairs) {
    s << "  " << p.camera_frame << " <- " << p.lidar_frame << ": " << verdictName(p.verdict.verdict)
      << " - " << p.verdict.reason << "\n";
    for (const auto& d : p.verdict.details) s << "    - " << d << "\n";
  }
  for (const auto& f : run.rig_findings) s << "  rig: " << f << "\n";
  for (const auto& f : run.not_calibrated) s << "  not calibrated: " << f << "\n";
  for (const auto& f : run.left_out) s << "  " << f << "\n";
  if (!run.views_to_check.empty()) {
    s << "  look at board poses:";
    for (int id : run.views_to_check) s << " " << id;
    s << "\n";
  }
  switch (run.verdict) {
    case Verdict::kGood: s << "  next: use it (the result file and static TF carry it)\n"; break;
    case Verdict::kDoubtful:
      s << "  next: look at the named poses and pairs, drop bad poses or add poses, then solve "
           "again\n";
      break;
    case Verdict::kFailed:
      if (!run.not_calibrated.empty()) {
        s << "  next: capture poses where the sensors not calibrated see the board together with "
             "another sensor (the capture tells how often each found it), or take them out of "
             "the rig file to calibrate the others\n";
        break;
      }
      s << "  next: do not use this result; fix the cause above (poses, board, sync, sensors) and "
           "collect again\n";
      break;
  }
  return s.str();
}

}  // namespace board_calib
