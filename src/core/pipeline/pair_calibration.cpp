#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/report/report.h>

#include <algorithm>
#include <sstream>

namespace board_calib {
namespace {

constexpr double kRotationTolerance = 1e-6;  // |R^T R - I| of a usable guess

bool isRotation(const Eigen::Matrix3d& R) {
  return R.allFinite() &&
         (R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < kRotationTolerance &&
         R.determinant() > 0;
}

}  // namespace

std::string PairCalibrationOptions::validate() const {
  if (auto why = solver.validate(); !why.empty()) return "solver: " + why;
  if (auto why = consistency.validate(); !why.empty()) return "consistency: " + why;
  if (auto why = verdict.validate(); !why.empty()) return "verdict: " + why;
  return {};
}

Expected<std::vector<Method>> parseMethods(const std::string& name) {
  if (name == "all") return std::vector<Method>{Method::kPpc, Method::kPbpc, Method::kMsgPair};
  auto m = parseMethod(name);
  if (!m) return Expected<std::vector<Method>>::failure(m.error() + " (or 'all')");
  return std::vector<Method>{*m};
}

std::optional<MethodRun> pbpcReferee(const std::vector<View>& views, const Target& target,
                                     const ConsistencyReport& consistency,
                                     const SolverOptions& solver, const VerdictOptions& verdict,
                                     bool cross_validate,
                                     const std::optional<Eigen::Isometry3d>& start) {
  MethodRun run;
  run.solution = calibrate(views, Method::kPbpc, solver, start);
  if (!run.solution.success) return std::nullopt;
  SolverOptions fold_options = solver;
  fold_options.compute_covariance = false;
  fold_options.declared_scale_without_covariance = true;  // the scale's spread over folds
  std::function<CalibrationSolution(const std::vector<View>&)> refit;
  if (cross_validate)
    refit = [&](const std::vector<View>& subset) {
      return calibrate(subset, Method::kPbpc, fold_options, start);
    };
  run.verdict = judgeSolution(run.solution, views, target, consistency, refit, verdict);
  if (run.verdict.verdict == Verdict::kFailed) return std::nullopt;
  return run;
}

void judgeAgainstPbpc(const MethodRun& referee, const CalibrationSolution& solution,
                      const VerdictOptions& options, VerdictReport* verdict) {
  const std::string why =
      " (PBPC, solved on the same views as a check: the board planes move with a LiDAR range "
      "offset or a wrong declared size, the edges do not)";
  std::vector<CalibrationSolution> pair{solution, referee.solution};
  std::vector<VerdictReport> judged{*verdict, referee.verdict};
  judgeMethodAgreement(pair, &judged, options);
  VerdictReport& v = judged.front();
  if (v.reason != verdict->reason) v.reason += why;
  if (v.details.size() > verdict->details.size()) v.details.back() += why;
  *verdict = std::move(v);
}

namespace {

// Asked without PBPC, the asked methods are judged against a PBPC solve on the same views.
void checkAgainstPbpc(const std::vector<Method>& methods, const Target& target,
                      const PairCalibration& out, const PairCalibrationOptions& options,
                      const std::optional<Eigen::Isometry3d>& start,
                      std::vector<CalibrationSolution>* solutions,
                      std::vector<VerdictReport>* verdicts) {
  if (!options.check_against_pbpc ||
      std::find(methods.begin(), methods.end(), Method::kPbpc) != methods.end())
    return;
  const auto referee = pbpcReferee(out.used_views, target, out.consistency, options.solver,
                                   options.verdict, options.cross_validate, start);
  if (!referee) return;
  for (size_t i = 0; i < solutions->size(); ++i)
    judgeAgainstPbpc(*referee, (*solutions)[i], options.verdict, &(*verdicts)[i]);
}

}  // namespace

PairCalibration calibratePair(const std::vector<View>& views, const std::vector<Method>& methods,
                              const Target& target, const std::string& camera_frame,
                              const std::string& lidar_frame, const PairCalibrationOptions& options,
                              const std::optional<Eigen::Isometry3d>& guess) {
  PairCalibration out;
  auto failAll = [&](const std::string& why) {
    out.verdict = Verdict::kFailed;
    out.reason = why;
    out.result.method = methods.empty() ? "" : methodName(methods.front());
    out.result.camera_frame = camera_frame;
    out.result.lidar_frame = lidar_frame;
    out.result.verdict = verdictName(Verdict::kFailed);
    out.result.verdict_reason = why;
    return out;
  };
  if (auto why = options.validate(); !why.empty()) return failAll("invalid options: " + why);
  if (methods.empty()) return failAll("no method asked for");
  if (guess && (!guess->matrix().allFinite() || !isRotation(guess->linear())))
    return failAll("the initial guess is not a rigid transform (a zero or non-unit quaternion?)");
  if (views.empty()) return failAll("no views: hold the board still in front of both sensors");

  out.consistency = checkViewConsistency(views, target, options.consistency);
  out.used_views = out.consistency.ok ? consistentViews(views, out.consistency) : views;
  // The consensus is a robust start; a user's guess wins.
  std::optional<Eigen::Isometry3d> start = guess;
  if (!start && out.consistency.ok) start = out.consistency.camera_T_lidar;

  SolverOptions fold_options = options.solver;
  fold_options.compute_covariance = false;
  fold_options.declared_scale_without_covariance = true;  // the scale's spread over folds
  std::vector<CalibrationSolution> solutions;
  std::vector<VerdictReport> verdicts;
  for (Method m : methods) {
    CalibrationSolution sol = calibrate(out.used_views, m, options.solver, start);
    std::function<CalibrationSolution(const std::vector<View>&)> refit;
    if (options.cross_validate)
      refit = [&, m](const std::vector<View>& subset) {
        return calibrate(subset, m, fold_options, start);
      };
    verdicts.push_back(
        judgeSolution(sol, out.used_views, target, out.consistency, refit, options.verdict));
    solutions.push_back(std::move(sol));
  }
  checkAgainstPbpc(methods, target, out, options, start, &solutions, &verdicts);
  judgeMethodAgreement(solutions, &verdicts, options.verdict);
  out.chosen = chooseMethod(solutions, verdicts, &out.choice);
  for (size_t i = 0; i < methods.size(); ++i) out.runs.push_back({solutions[i], verdicts[i]});

  const MethodRun& run = out.shownRun();
  out.verdict = run.verdict.verdict;
  out.reason = run.verdict.reason;
  if (out.verdict != Verdict::kGood && run.verdict.scale_finding.empty()) {
    const std::string size = declaredSizeDoubt(out.used_views, target, run.solution);
    if (!size.empty() && out.reason.find(size) == std::string::npos) out.reason += "; " + size;
  }
  out.result = makeResultFile(run.solution, out.used_views, target, camera_frame, lidar_frame);
  out.result.verdict = verdictName(out.verdict);
  out.result.verdict_reason = out.reason;
  out.result.views_to_check = run.verdict.views_to_check;
  if (run.solution.success) out.result.stddev = run.verdict.stddev;
  out.result.quality["stddev_inflation"] = run.verdict.stddev_inflation;
  out.result.quality["plane_residual_ratio"] = run.verdict.plane_residual_ratio;
  if (run.verdict.cross_validation.heldout_mlre_px)
    out.result.quality["heldout_mlre_px"] = *run.verdict.cross_validation.heldout_mlre_px;
  for (const auto& d : run.verdict.details)
    if (std::find(out.result.notes.begin(), out.result.notes.end(), d) == out.result.notes.end())
      out.result.notes.push_back(d);
  if (methods.size() > 1) out.result.notes.push_back("method: " + out.choice);
  return out;
}

std::string verdictSummary(const PairCalibration& run) {
  std::ostringstream s;
  std::string upper = verdictName(run.verdict);
  std::transform(upper.begin(), upper.end(), upper.begin(), ::toupper);
  s << "VERDICT: " << upper << " - " << run.reason << "\n";
  if (!run.choice.empty()) s << "  method: " << run.choice << "\n";
  const int inconsistent = static_cast<int>(run.consistency.inconsistentIds().size());
  s << "  views: " << run.used_views.size() << " used";
  if (inconsistent) s << ", " << inconsistent << " left out as inconsistent";
  s << "\n";
  if (const MethodRun* chosen = run.chosenRun()) {
    if (!chosen->verdict.views_to_check.empty()) {
      s << "  look at views:";
      for (int id : chosen->verdict.views_to_check) s << " " << id;
      s << "\n";
    }
    for (const auto& d : chosen->verdict.details) s << "  - " << d << "\n";
  } else {
    for (const auto& r : run.runs)
      s << "  " << methodName(r.solution.method) << ": " << r.verdict.reason << "\n";
  }
  switch (run.verdict) {
    case Verdict::kGood: s << "  next: use it (the result file and static TF carry it)\n"; break;
    case Verdict::kDoubtful:
      s << "  next: look at the named views (report overlays), drop bad ones (live ~drop_view, "
           "offline --drop-views) or add views, then solve again\n";
      break;
    case Verdict::kFailed:
      s << "  next: do not use this result; fix the cause above (views, board, sync, target) and "
           "collect again\n";
      break;
  }
  return s.str();
}

}  // namespace board_calib
