// A second chance's prior without a first calibration (issue 14, 3a): the board is the object
// that moves. Each LiDAR board and an image candidate of the same moment (a quadrilateral the
// image search tried, placed by PnP as the declared board) are one correspondence of board
// centres if the candidate is the board. Three of them fix a rigid placement of the LiDAR; the
// placement that puts the most distinct LiDAR board positions on candidates wins. A scene
// rectangle stays where it is while the LiDAR's board moves, so no placement maps several board
// positions onto it.
#include <board_calib/core/pipeline/second_chance.h>
#include <board_calib/core/transform.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>

namespace board_calib {
namespace {

constexpr int kDraws = 4000;  // triples drawn (fixed seed: the same recording, the same prior)
constexpr int kRefits = 3;    // match, refit, match again
constexpr double kSampleVariance = 2.0;  // a drawn placement carries its three pairs' errors too
constexpr double kMaxNoiseRatio = 2.0;   // refitted residual over the noise the pairs predict
constexpr double kMaxScatterOfBoard = 0.25;  // refitted residual per axis, of the board's side

// One LiDAR board and the image candidates of the same moment.
struct Pair {
  Eigen::Vector3d lidar = Eigen::Vector3d::Zero();  // board centre, LiDAR frame
  double lidar_sigma_m = 0.0;
  const std::vector<BoardCandidate>* candidates = nullptr;
};

struct Match {
  size_t pair = 0, candidate = 0;
  double sigmas = 0.0;
};

struct Agreement {
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
  std::vector<Match> matches;  // per pair at most one
  int positions = 0;           // distinct LiDAR board positions among the matches
  double cost = 0.0;           // truncated sum of squared sigmas over every pair (tie-break)
  bool betterThan(const Agreement& other) const {
    return positions != other.positions ? positions > other.positions : cost < other.cost;
  }
};

// Rigid T minimising sum |to_i - T from_i|^2; false when the points lie on a line.
bool alignPoints(const std::vector<Eigen::Vector3d>& from, const std::vector<Eigen::Vector3d>& to,
                 Eigen::Isometry3d* T) {
  const size_t n = from.size();
  if (n < 3 || to.size() != n) return false;
  Eigen::Vector3d mean_from = Eigen::Vector3d::Zero(), mean_to = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    mean_from += from[i] / static_cast<double>(n);
    mean_to += to[i] / static_cast<double>(n);
  }
  std::vector<Eigen::Vector3d> centred_from, centred_to;
  for (size_t i = 0; i < n; ++i) {
    centred_from.push_back(from[i] - mean_from);
    centred_to.push_back(to[i] - mean_to);
  }
  constexpr double kMinRelativeSecond = 1e-9;  // points on a line leave the roll about it free
  const auto R = rotationAligning(centred_from, centred_to, {}, kMinRelativeSecond);
  if (!R) return false;
  T->setIdentity();
  T->linear() = *R;
  T->translation() = mean_to - *R * mean_from;
  return T->matrix().allFinite();
}

// How far T puts a LiDAR board from a candidate, in sigmas: along the candidate's viewing ray
// (its PnP depth is the weak axis) and across it, each with the LiDAR centre's sigma and `slack`
// (the placement's own error) added.
double residualSigmas(const Eigen::Isometry3d& T, const Pair& p, const BoardCandidate& c,
                      double variance_scale, double slack_m) {
  const Eigen::Vector3d e = c.centre - T * p.lidar;
  const Eigen::Vector3d ray = c.centre.normalized();
  const double along = ray.dot(e);
  const double across2 = (e - along * ray).squaredNorm();
  const double shared = p.lidar_sigma_m * p.lidar_sigma_m + slack_m * slack_m;
  const double var_along = variance_scale * (c.depth_sigma_m * c.depth_sigma_m + shared);
  const double var_across = variance_scale * (c.lateral_sigma_m * c.lateral_sigma_m + shared);
  return std::sqrt(along * along / var_along + across2 / var_across);
}

Agreement agreementOf(const Eigen::Isometry3d& T, const std::vector<Pair>& pairs,
                      double variance_scale, double slack_m, double limit_sigmas,
                      double separation_m) {
  Agreement a;
  a.camera_T_lidar = T;
  for (size_t i = 0; i < pairs.size(); ++i) {
    Match best{i, 0, limit_sigmas};
    bool matched = false;
    for (size_t k = 0; k < pairs[i].candidates->size(); ++k) {
      const double s =
          residualSigmas(T, pairs[i], (*pairs[i].candidates)[k], variance_scale, slack_m);
      if (s <= best.sigmas) {
        best = Match{i, k, s};
        matched = true;
      }
    }
    a.cost += best.sigmas * best.sigmas;
    if (matched) a.matches.push_back(best);
  }
  // Distinct positions: the best matches first, each at least `separation_m` from those counted.
  std::vector<Match> order = a.matches;
  std::sort(order.begin(), order.end(),
            [](const Match& x, const Match& y) { return x.sigmas < y.sigmas; });
  std::vector<Eigen::Vector3d> counted;
  for (const Match& m : order) {
    const Eigen::Vector3d& p = pairs[m.pair].lidar;
    bool apart = true;
    for (const auto& q : counted) apart = apart && (p - q).norm() >= separation_m;
    if (apart) counted.push_back(p);
  }
  a.positions = static_cast<int>(counted.size());
  return a;
}

// Refit on the matches; the RMS residual per axis (m) of that fit.
bool refit(const std::vector<Pair>& pairs, const Agreement& a, Eigen::Isometry3d* T,
           double* rms_axis_m) {
  std::vector<Eigen::Vector3d> from, to;
  for (const Match& m : a.matches) {
    from.push_back(pairs[m.pair].lidar);
    to.push_back((*pairs[m.pair].candidates)[m.candidate].centre);
  }
  if (!alignPoints(from, to, T)) return false;
  double sum = 0;
  for (size_t i = 0; i < from.size(); ++i) sum += (to[i] - *T * from[i]).squaredNorm();
  *rms_axis_m = std::sqrt(sum / (3.0 * static_cast<double>(from.size())));
  return true;
}

// Refits a placement on its matches and matches again with the fit's own residual as its
// error, a few rounds; `rms_axis_m` the last fit's residual per axis (0 when none was made).
Agreement refined(const std::vector<Pair>& pairs, Agreement a, double limit, double separation,
                  int min_positions, double* rms_axis_m) {
  *rms_axis_m = 0.0;
  for (int round = 0; round < kRefits; ++round) {
    Eigen::Isometry3d T;
    double r = 0.0;
    if (!refit(pairs, a, &T, &r)) break;
    Agreement again = agreementOf(T, pairs, 1.0, r, limit, separation);
    if (again.positions < min_positions) break;
    a = std::move(again);
    *rms_axis_m = r;
  }
  return a;
}

// Second largest standard deviation of the points about their mean (0: on a line).
double spreadAcrossLine(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 3) return 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p / static_cast<double>(points.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : points) cov += (p - mean) * (p - mean).transpose();
  cov /= static_cast<double>(points.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  return std::sqrt(std::max(0.0, eig.eigenvalues()(1)));
}

}  // namespace

std::optional<SecondChancePrior> consensusPrior(const BoardSightings& first_pass,
                                                double pair_tolerance_s, const Target& target,
                                                const SecondChanceOptions& options,
                                                std::string* why_not, std::string* summary) {
  auto refuse = [&](const std::string& why) {
    if (why_not) *why_not = why;
    return std::nullopt;
  };
  const double board_side = std::min(target.width, target.height);
  // A board moved by half its smaller side is at another position.
  const double separation = 0.5 * board_side;
  std::vector<Pair> pairs;
  for (const auto& [stamp, lidar] : first_pass.clouds) {
    auto it = first_pass.image_candidates.lower_bound(stamp - pair_tolerance_s);
    const std::vector<BoardCandidate>* nearest = nullptr;
    double best_dt = pair_tolerance_s;
    for (; it != first_pass.image_candidates.end() && it->first <= stamp + pair_tolerance_s; ++it)
      if (!it->second.empty() && std::abs(it->first - stamp) <= best_dt) {
        best_dt = std::abs(it->first - stamp);
        nearest = &it->second;
      }
    if (!nearest) continue;
    Pair p;
    p.candidates = nearest;
    if (lidar.corners_valid) {
      for (const auto& c : lidar.corners) p.lidar += 0.25 * c;
    } else {
      p.lidar = lidar.centroid;
    }
    // The centre moves with the scan lines that fall on the board: up to half a line gap (a
    // tenth of the board when the gap is unknown).
    p.lidar_sigma_m =
        std::max(lidar.line_spacing_m > 0 ? 0.5 * lidar.line_spacing_m : 0.1 * board_side,
                 options.min_translation_sigma_m);
    if (p.lidar.allFinite() && p.lidar.norm() > 0) pairs.push_back(p);
  }
  if (static_cast<int>(pairs.size()) < options.min_consensus_boards)
    return refuse(std::to_string(pairs.size()) +
                  " moments with a LiDAR board and image candidates (need " +
                  std::to_string(options.min_consensus_boards) + ")");

  const double limit = options.sigma_factor;
  std::mt19937 rng(20261203u);
  std::uniform_int_distribution<size_t> pick(0, pairs.size() - 1);
  Agreement best;
  // Every drawn placement that met the count, with its count (for the ambiguity check).
  std::vector<std::pair<Eigen::Isometry3d, int>> strong;
  for (int draw = 0; draw < kDraws; ++draw) {
    const size_t i = pick(rng), j = pick(rng), k = pick(rng);
    const Eigen::Vector3d &a = pairs[i].lidar, &b = pairs[j].lidar, &c = pairs[k].lidar;
    if ((b - a).norm() < separation || (c - a).norm() < separation || (c - b).norm() < separation ||
        0.5 * (b - a).cross(c - a).norm() < separation * separation)
      continue;
    std::vector<Eigen::Vector3d> from{a, b, c}, to;
    for (size_t p : {i, j, k}) {
      std::uniform_int_distribution<size_t> cand(0, pairs[p].candidates->size() - 1);
      to.push_back((*pairs[p].candidates)[cand(rng)].centre);
    }
    Eigen::Isometry3d T;
    if (!alignPoints(from, to, &T)) continue;
    Agreement agreed = agreementOf(T, pairs, kSampleVariance, 0.0, limit, separation);
    if (agreed.positions >= options.min_consensus_boards)
      strong.emplace_back(agreed.camera_T_lidar, agreed.positions);
    if (agreed.betterThan(best)) best = std::move(agreed);
  }
  if (best.positions < options.min_consensus_boards)
    return refuse("no placement of the LiDAR puts more than " + std::to_string(best.positions) +
                  " distinct board positions on the image candidates of the same moments (need " +
                  std::to_string(options.min_consensus_boards) + ")");
  // Refit on the matches, match again with the fit's own residual as the placement's error.
  double rms = 0.0;
  best = refined(pairs, std::move(best), limit, separation, options.min_consensus_boards, &rms);
  // The agreeing boards must scatter as their own noise predicts: a placement that gathers
  // candidates only within wide tolerances (far sparse boards) is chance, not the board.
  double expected_sq = 0;
  for (const Match& m : best.matches) {
    const BoardCandidate& c = (*pairs[m.pair].candidates)[m.candidate];
    expected_sq +=
        (pairs[m.pair].lidar_sigma_m * pairs[m.pair].lidar_sigma_m +
         (c.depth_sigma_m * c.depth_sigma_m + 2 * c.lateral_sigma_m * c.lateral_sigma_m) / 3.0) /
        static_cast<double>(best.matches.size());
  }
  if (rms > kMaxNoiseRatio * std::sqrt(expected_sq))
    return refuse(
        "the " + std::to_string(best.positions) + " board positions that agree best scatter " +
        std::to_string(rms / std::sqrt(expected_sq)) + "x as far as their noise explains");
  // The prior must put the board within a fraction of its size, or its second chance searches
  // the whole scene around it: far sparse boards (a LiDAR centre known to half a scan-line gap)
  // let wide placements gather chance candidates.
  if (rms > kMaxScatterOfBoard * board_side)
    return refuse("the " + std::to_string(best.positions) +
                  " board positions that agree best scatter " + std::to_string(rms * 1e3) +
                  " mm per axis, more than a quarter of the board");
  std::vector<Eigen::Vector3d> agreeing;
  for (const Match& m : best.matches) agreeing.push_back(pairs[m.pair].lidar);
  const double spread = spreadAcrossLine(agreeing);
  if (spread < separation)
    return refuse("the " + std::to_string(best.positions) +
                  " board positions that agree lie along a line: move the board sideways and in "
                  "depth");
  // How far another placement moves the agreeing boards from the best one's, on average.
  const auto meanMove = [&](const Eigen::Isometry3d& other) {
    double moved = 0;
    for (const auto& p : agreeing)
      moved += (other * p - best.camera_T_lidar * p).norm() / static_cast<double>(agreeing.size());
    return moved;
  };
  // Another placement as well supported once refitted, elsewhere: the candidates cannot tell
  // which is right. (Drawn placements carry their triple's error: judged after their refit.)
  for (const auto& [other_T, other_positions] : strong) {
    if (other_positions < best.positions || meanMove(other_T) <= limit * std::max(rms, separation))
      continue;
    double other_rms = 0.0;
    const Agreement other =
        refined(pairs, agreementOf(other_T, pairs, kSampleVariance, 0.0, limit, separation), limit,
                separation, options.min_consensus_boards, &other_rms);
    const double moved = meanMove(other.camera_T_lidar);
    if (other.positions >= best.positions && other_rms <= kMaxScatterOfBoard * board_side &&
        moved > limit * std::max(rms, separation))
      return refuse("two placements of the LiDAR agree with " + std::to_string(best.positions) +
                    " board positions each, " + std::to_string(moved) + " m apart");
  }
  // The fit's error over the distinct positions that fix it; the rotation's over their spread.
  SecondChancePrior prior;
  prior.camera_T_lidar = best.camera_T_lidar;
  const double n = static_cast<double>(best.positions);
  prior.translation_sigma_m =
      std::max(std::sqrt(3.0) * rms / std::sqrt(n), options.min_translation_sigma_m);
  prior.rotation_sigma_rad = std::max(std::sqrt(3.0) * rms / (spread * std::sqrt(n)),
                                      options.min_rotation_sigma_deg * M_PI / 180.0);
  prior.first_pass = first_pass;
  if (summary) {
    std::ostringstream s;
    s.precision(3);
    s << best.positions << " distinct board positions (" << best.matches.size() << " of "
      << pairs.size() << " moments) agree on one placement of the LiDAR in the images, residual "
      << rms * 1e3 << " mm per axis";
    *summary = s.str();
  }
  return prior;
}

}  // namespace board_calib
