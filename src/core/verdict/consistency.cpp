#include <board_calib/core/common/format.h>
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/transform.h>
#include <board_calib/core/verdict/consistency.h>

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <sstream>

namespace board_calib {
namespace {

constexpr double kMadToSigma = 1.4826;
constexpr double kMinDistanceFactor = 0.5, kMaxDistanceFactor = 4.0;
constexpr int kRefineRounds = 4;
constexpr double kMinScale = 0.7,
                 kMaxScale = 1.3;           // a board declared more than 30 % off is an error
constexpr double kMaxScaleCondition = 1e4;  // (t, s) fit conditioning before the scale is trusted
constexpr int kMinViewsForScale = 6;

struct Obs {
  int index = 0;
  Eigen::Vector3d nc, nl;
  double dc = 0, dl = 0;
  double fa = 1, fo = 1;  // distance factors of the normal and offset errors
};

// The rotation taking the LiDAR normals to the camera's, each weighted by its normal error; a
// sample of parallel normals still gives one (its views are then judged by the others).
Eigen::Matrix3d kabsch(const std::vector<const Obs*>& obs) {
  std::vector<Eigen::Vector3d> lidar, camera;
  std::vector<double> weights;
  for (const Obs* o : obs) {
    lidar.push_back(o->nl);
    camera.push_back(o->nc);
    weights.push_back(1.0 / (o->fa * o->fa));
  }
  const auto R = rotationAligning(lidar, camera, weights, -1.0);
  return R ? *R : Eigen::Matrix3d::Identity();
}

// t (and s when asked and well determined) from s d_c - d_l = n_c . t, weighted by the offset
// error.
bool fitOffsets(const std::vector<const Obs*>& obs, bool with_scale, Eigen::Vector3d* t,
                double* s) {
  const int cols = with_scale ? 4 : 3;
  Eigen::MatrixXd A(obs.size(), cols);
  Eigen::VectorXd b(obs.size());
  for (size_t i = 0; i < obs.size(); ++i) {
    const double w = 1.0 / obs[i]->fo;
    A.block(static_cast<Eigen::Index>(i), 0, 1, 3) = w * obs[i]->nc.transpose();
    if (with_scale) {
      A(static_cast<Eigen::Index>(i), 3) = -w * obs[i]->dc;
      b(static_cast<Eigen::Index>(i)) = -w * obs[i]->dl;
    } else {
      b(static_cast<Eigen::Index>(i)) = w * (obs[i]->dc - obs[i]->dl);
    }
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const auto& sv = svd.singularValues();
  if (sv(sv.size() - 1) <= 0 || sv(0) / sv(sv.size() - 1) > kMaxScaleCondition) return false;
  const Eigen::VectorXd x = svd.solve(b);
  if (!x.allFinite()) return false;
  *t = x.head<3>();
  *s = with_scale ? x(3) : 1.0;
  return !with_scale || (*s > kMinScale && *s < kMaxScale);
}

double normalResidualRad(const Obs& o, const Eigen::Matrix3d& R) {
  return std::acos(std::clamp(o.nc.dot(R * o.nl), -1.0, 1.0));
}
double offsetResidual(const Obs& o, const Eigen::Vector3d& t, double s) {
  return std::abs(s * o.dc - o.dl - o.nc.dot(t));
}

}  // namespace

std::string ConsistencyOptions::validate() const {
  const double all[] = {inlier_sigmas,
                        min_normal_tolerance_deg,
                        min_offset_tolerance_m,
                        max_normal_tolerance_deg,
                        max_offset_tolerance_m,
                        first_normal_tolerance_deg,
                        first_offset_tolerance_m,
                        min_sample_spread_deg,
                        on_board_margin_m,
                        min_on_board_fraction};
  for (double v : all)
    if (!std::isfinite(v) || v < 0) return "consistency options must be finite and >= 0";
  if (min_normal_tolerance_deg > max_normal_tolerance_deg ||
      min_offset_tolerance_m > max_offset_tolerance_m)
    return "consistency tolerance floors must not exceed their ceilings";
  if (min_on_board_fraction > 1.0) return "min_on_board_fraction must be <= 1";
  if (max_samples < 1) return "max_samples must be >= 1";
  return {};
}

std::vector<int> ConsistencyReport::inconsistentIds() const {
  std::vector<int> ids;
  for (const auto& v : views)
    if (v.usable && !v.consistent && ok) ids.push_back(v.view_id);
  return ids;
}

std::vector<View> consistentViews(const std::vector<View>& views, const ConsistencyReport& report) {
  std::vector<View> out;
  for (size_t i = 0; i < views.size() && i < report.views.size(); ++i)
    if (report.views[i].consistent) out.push_back(views[i]);
  return out;
}

namespace {

// The rigid motion and plane scale a set of views agrees on, with the tolerances it was judged by.
struct Motion {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double s = 1.0;
  double tol_a = 0.0, tol_o = 0.0;  // normal (rad) and offset (m) tolerances at the median range
};

std::vector<const Obs*> inliersOf(const std::vector<Obs>& obs, const Motion& m, double* cost) {
  std::vector<const Obs*> in;
  *cost = 0;
  for (const Obs& x : obs) {
    const double ea = normalResidualRad(x, m.R) / (m.tol_a * x.fa),
                 eo = offsetResidual(x, m.t, m.s) / (m.tol_o * x.fo);
    if (ea <= 1.0 && eo <= 1.0) {
      in.push_back(&x);
      *cost += ea * ea + eo * eo;
    }
  }
  return in;
}

// The usable views as observations (plane normals and offsets of both sensors); the others get
// their reason in `r`. `distances`: camera to board centre of each observation.
std::vector<Obs> observations(const std::vector<View>& views, const Target& target,
                              ConsistencyReport& r, std::vector<double>* distances) {
  std::vector<Obs> obs;
  for (size_t i = 0; i < views.size(); ++i) {
    const View& v = views[i];
    ViewConsistency& vc = r.views[i];
    vc.view_id = v.id;
    const bool ok = v.lidar.found && v.camera.found && v.lidar.plane.normal.allFinite() &&
                    v.camera.plane.normal.allFinite() && std::isfinite(v.lidar.plane.offset) &&
                    std::isfinite(v.camera.plane.offset) && v.lidar.plane.normal.norm() > 0.5 &&
                    v.camera.plane.normal.norm() > 0.5 &&
                    v.camera.camera_T_board.matrix().allFinite();
    if (!ok) {
      vc.reason = "the board is missing or not finite in one sensor";
      continue;
    }
    vc.usable = true;
    Obs x;
    x.index = static_cast<int>(i);
    x.nc = v.camera.plane.normal.normalized();
    x.nl = v.lidar.plane.normal.normalized();
    x.dc = v.camera.plane.offset;
    x.dl = v.lidar.plane.offset;
    obs.push_back(x);
    distances->push_back((v.camera.camera_T_board * target.center()).norm());
  }
  return obs;
}

// Every triple of observations, or `max_samples` random ones when there are more.
std::vector<std::array<int, 3>> sampleTriples(int n, const ConsistencyOptions& o) {
  std::vector<std::array<int, 3>> triples;
  const long long total = static_cast<long long>(n) * (n - 1) * (n - 2) / 6;
  std::mt19937 rng(o.seed);
  if (total <= o.max_samples) {
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b)
        for (int c = b + 1; c < n; ++c) triples.push_back({a, b, c});
  } else {
    std::uniform_int_distribution<int> pick(0, n - 1);
    while (static_cast<int>(triples.size()) < o.max_samples) {
      std::array<int, 3> t{pick(rng), pick(rng), pick(rng)};
      if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) triples.push_back(t);
    }
  }
  return triples;
}

// Consensus over triples whose camera normals span 3D: the motion most views agree on with the
// first (loose) tolerances, and those views.
std::vector<const Obs*> bestConsensus(const std::vector<Obs>& obs, const ConsistencyOptions& o,
                                      Motion* m) {
  const double min_spread = std::sin(o.min_sample_spread_deg * kRadPerDeg);
  std::vector<const Obs*> best;
  double best_cost = 0;
  for (const auto& tri : sampleTriples(static_cast<int>(obs.size()), o)) {
    Eigen::Matrix3d N;
    for (int k = 0; k < 3; ++k) N.col(k) = obs[static_cast<size_t>(tri[k])].nc;
    if (std::abs(N.determinant()) < min_spread * min_spread * min_spread) continue;
    const std::vector<const Obs*> sample{&obs[static_cast<size_t>(tri[0])],
                                         &obs[static_cast<size_t>(tri[1])],
                                         &obs[static_cast<size_t>(tri[2])]};
    const Eigen::Matrix3d Rs = kabsch(sample);
    Eigen::Vector3d ts;
    double ss = 1.0;
    if (!fitOffsets(sample, false, &ts, &ss)) continue;
    Motion candidate = *m;
    candidate.R = Rs;
    candidate.t = ts;
    candidate.s = ss;
    double cost = 0;
    auto in = inliersOf(obs, candidate, &cost);
    if (in.size() > best.size() || (in.size() == best.size() && cost < best_cost)) {
      best = std::move(in);
      best_cost = cost;
      *m = candidate;
    }
  }
  return best;
}

// Refit on the consensus, then set the tolerances from its residuals' robust spread.
void refineConsensus(const std::vector<Obs>& obs, const ConsistencyOptions& o,
                     std::vector<const Obs*>& best, Motion* m) {
  Eigen::Matrix3d& R = m->R;
  Eigen::Vector3d& t = m->t;
  double& s = m->s;
  double& tol_a = m->tol_a;
  double& tol_o = m->tol_o;
  for (int round = 0; round < kRefineRounds; ++round) {
    R = kabsch(best);
    const bool scale =
        static_cast<int>(best.size()) >= kMinViewsForScale && fitOffsets(best, true, &t, &s);
    if (!scale) {
      s = 1.0;
      if (!fitOffsets(best, false, &t, &s)) break;
    }
    std::vector<double> ea, eo;
    for (const Obs* x : best) {
      ea.push_back(normalResidualRad(*x, R) / x->fa);
      eo.push_back(offsetResidual(*x, t, s) / x->fo);
    }
    if (static_cast<int>(best.size()) > 3) {
      tol_a = std::clamp(o.inlier_sigmas * kMadToSigma * medianOf(ea),
                         o.min_normal_tolerance_deg * kRadPerDeg,
                         o.max_normal_tolerance_deg * kRadPerDeg);
      tol_o = std::clamp(o.inlier_sigmas * kMadToSigma * medianOf(eo), o.min_offset_tolerance_m,
                         o.max_offset_tolerance_m);
    }
    double cost = 0;
    auto in = inliersOf(obs, *m, &cost);
    if (in.size() < 3) break;
    const bool same = in == best;
    best = std::move(in);
    if (same && round > 0) break;
  }
}

// Every usable view against the consensus, then its LiDAR points against the camera's board.
void judgeViews(const std::vector<View>& views, const std::vector<Obs>& obs, const Target& target,
                const ConsistencyOptions& o, const Motion& m, ConsistencyReport& r) {
  const Eigen::Matrix3d& R = m.R;
  const Eigen::Vector3d& t = m.t;
  const double s = m.s, tol_a = m.tol_a, tol_o = m.tol_o;
  for (const Obs& x : obs) {
    ViewConsistency& vc = r.views[static_cast<size_t>(x.index)];
    const View& v = views[static_cast<size_t>(x.index)];
    vc.normal_residual_deg = normalResidualRad(x, R) * kDegPerRad;
    vc.offset_residual_m = offsetResidual(x, t, s);
    const double ta = tol_a * kDegPerRad * x.fa, to = tol_o * x.fo;
    const bool planes_agree = vc.normal_residual_deg <= ta && vc.offset_residual_m <= to;
    const Eigen::Isometry3d board_T_lidar = v.camera.camera_T_board.inverse() * r.camera_T_lidar;
    const double margin = o.on_board_margin_m + to;
    int on = 0;
    for (const auto& p : v.lidar.board_points) {
      const Eigen::Vector3d b = board_T_lidar * p;
      on += b.x() >= -margin && b.x() <= target.width + margin && b.y() >= -margin &&
            b.y() <= target.height + margin && std::abs(b.z()) <= margin;
    }
    vc.on_board_fraction =
        v.lidar.board_points.empty() ? 0.0 : static_cast<double>(on) / v.lidar.board_points.size();
    const bool on_board = vc.on_board_fraction >= o.min_on_board_fraction;
    vc.consistent = planes_agree && on_board;
    if (!planes_agree)
      vc.reason = "the two sensors' board planes disagree with the other views (normal " +
                  formatFixed(vc.normal_residual_deg, 2) + " deg, offset " +
                  formatFixed(vc.offset_residual_m * 100, 1) + " cm; allowed " +
                  formatFixed(ta, 2) + " deg, " + formatFixed(to * 100, 1) +
                  " cm): another object taken for the board, or the board moved between the "
                  "sensors' frames";
    else if (!on_board)
      vc.reason =
          "only " + formatFixed(vc.on_board_fraction * 100, 0) +
          " % of the LiDAR board points land on the camera's board: the LiDAR found another object";
    r.consistent_views += vc.consistent;
  }
}

}  // namespace

ConsistencyReport checkViewConsistency(const std::vector<View>& views, const Target& target,
                                       const ConsistencyOptions& o) {
  ConsistencyReport r;
  r.views.resize(views.size());
  std::vector<double> distances;
  std::vector<Obs> obs = observations(views, target, r, &distances);
  if (auto why = o.validate(); !why.empty()) {
    r.reason = "invalid consistency options: " + why;
    return r;
  }
  if (obs.size() < 3) {
    r.reason = std::to_string(obs.size()) +
               " usable view(s): a calibration needs at least 3 with different tilts";
    return r;
  }
  const double d_med = std::max(1e-3, medianOf(distances));
  for (size_t k = 0; k < obs.size(); ++k) {
    const double f = std::clamp(distances[k] / d_med, kMinDistanceFactor, kMaxDistanceFactor);
    obs[k].fa = f;
    obs[k].fo = f * f;
  }
  Motion m;
  m.tol_a = o.first_normal_tolerance_deg * kRadPerDeg;
  m.tol_o = o.first_offset_tolerance_m;
  std::vector<const Obs*> best = bestConsensus(obs, o, &m);
  if (best.size() < 3) {
    r.reason = "no three views agree on one rigid motion (the board normals must differ by " +
               formatFixed(o.min_sample_spread_deg, 0) +
               " deg or more, and the two sensors must see the same board)";
    return r;
  }
  refineConsensus(obs, o, best, &m);
  r.camera_T_lidar = makeTransform(m.R, m.t);
  r.plane_scale = m.s;
  r.normal_tolerance_deg = m.tol_a * kDegPerRad;
  r.offset_tolerance_m = m.tol_o;
  r.checkable = obs.size() > 3;
  judgeViews(views, obs, target, o, m, r);
  r.ok = r.consistent_views >= 3;
  if (!r.ok) r.reason = "fewer than 3 views agree with each other";
  return r;
}

}  // namespace board_calib
