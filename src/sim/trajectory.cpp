#include "sim/trajectory.hpp"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/trajectory_io.hpp"

namespace loopgate::sim {

namespace {

// Uniform cubic B-spline basis (value, first and second derivative in u) for the four controls.
struct Basis {
  Eigen::Vector4d b, db, ddb;
};
Basis bspline_basis(double u) {
  const double u2 = u * u;
  const double u3 = u2 * u;
  const double w = 1.0 - u;
  Basis out;
  out.b << w * w * w / 6.0, (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0, (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
      u3 / 6.0;
  out.db << -w * w / 2.0, (9.0 * u2 - 12.0 * u) / 6.0, (-9.0 * u2 + 6.0 * u + 3.0) / 6.0, u2 / 2.0;
  out.ddb << w, (18.0 * u - 12.0) / 6.0, (-18.0 * u + 6.0) / 6.0, u;
  return out;
}

// Cumulative basis: lambda_j(u) = sum_{k>=j} b_k(u), j = 1..3 (lambda_0 = 1), and d/du.
void cumulative_basis(double u, Eigen::Vector3d* lambda, Eigen::Vector3d* dlambda) {
  const double u2 = u * u;
  const double u3 = u2 * u;
  *lambda << (5.0 + 3.0 * u - 3.0 * u2 + u3) / 6.0, (1.0 + 3.0 * u + 3.0 * u2 - 2.0 * u3) / 6.0, u3 / 6.0;
  *dlambda << (3.0 - 6.0 * u + 3.0 * u2) / 6.0, (3.0 + 6.0 * u - 6.0 * u2) / 6.0, u2 / 2.0;
}

Eigen::Matrix3d orthonormalised(const Eigen::Matrix3d& R) {
  return Eigen::Quaterniond(R).normalized().toRotationMatrix();
}

// Pose of the (time-sorted) samples at t, linear/slerp between neighbours, clamped at the ends.
Eigen::Matrix3d sample_rotation_at(const std::vector<StampedPose>& poses, Timestamp t_ns) {
  if (t_ns <= poses.front().t_ns) return poses.front().T_w_b.linear();
  if (t_ns >= poses.back().t_ns) return poses.back().T_w_b.linear();
  const auto it = std::upper_bound(poses.begin(), poses.end(), t_ns,
                                   [](Timestamp t, const StampedPose& p) { return t < p.t_ns; });
  const StampedPose& b = *it;
  const StampedPose& a = *(it - 1);
  return interpolate_pose(a, b, t_ns).linear();
}

}  // namespace

void TrajectoryFitConfig::validate() const {
  if (!(knot_spacing_s >= 0.0)) throw ConfigError("knot_spacing_s must be >= 0 (0 = automatic)");
  if (!(smoothing_weight >= 0.0)) throw ConfigError("smoothing_weight must be >= 0");
  if (rotation_iterations < 1) throw ConfigError("rotation_iterations must be >= 1");
  if (!(rotation_tolerance_rad > 0.0)) throw ConfigError("rotation_tolerance_rad must be > 0");
}

SplineTrajectory::SplineTrajectory(Timestamp start_t_ns, Timestamp end_t_ns, double knot_spacing_s,
                                   std::vector<Eigen::Vector3d> position_controls_w,
                                   std::vector<Eigen::Matrix3d> rotation_controls_w_b)
    : start_t_ns_(start_t_ns),
      end_t_ns_(end_t_ns),
      dt_s_(knot_spacing_s),
      positions_(std::move(position_controls_w)),
      rotations_(std::move(rotation_controls_w_b)) {
  if (positions_.size() < 4 || rotations_.size() != positions_.size()) {
    throw std::invalid_argument("SplineTrajectory: need >= 4 position and as many rotation controls");
  }
  if (!(dt_s_ > 0.0) || end_t_ns_ < start_t_ns_)
    throw std::invalid_argument("SplineTrajectory: bad time span");
  rotation_deltas_.resize(rotations_.size() - 1);
  for (std::size_t k = 0; k + 1 < rotations_.size(); ++k) {
    rotation_deltas_[k] = so3_log(rotations_[k].transpose() * rotations_[k + 1]);
  }
}

TrajectoryState SplineTrajectory::evaluate(Timestamp t_ns) const {
  TrajectoryState state;
  state.t_ns = t_ns;
  const bool outside = t_ns < start_t_ns_ || t_ns > end_t_ns_;
  const Timestamp t_eval_ns = std::clamp(t_ns, start_t_ns_, end_t_ns_);
  const double tau = ns_to_s(t_eval_ns - start_t_ns_) / dt_s_;
  const std::size_t segments = positions_.size() - 3;
  std::size_t seg = static_cast<std::size_t>(std::max(0.0, std::floor(tau)));
  if (seg >= segments) seg = segments - 1;
  const double u = tau - static_cast<double>(seg);

  const Basis basis = bspline_basis(u);
  Eigen::Vector3d p = Eigen::Vector3d::Zero(), dp = Eigen::Vector3d::Zero(), ddp = Eigen::Vector3d::Zero();
  for (int j = 0; j < 4; ++j) {
    const Eigen::Vector3d& c = positions_[seg + static_cast<std::size_t>(j)];
    p += basis.b[j] * c;
    dp += basis.db[j] * c;
    ddp += basis.ddb[j] * c;
  }

  Eigen::Vector3d lambda, dlambda;
  cumulative_basis(u, &lambda, &dlambda);
  Eigen::Matrix3d R = rotations_[seg];
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d& d = rotation_deltas_[seg + static_cast<std::size_t>(j)];
    const Eigen::Matrix3d A = so3_exp(lambda[j] * d);
    R = R * A;
    omega = A.transpose() * omega + (dlambda[j] / dt_s_) * d;
  }

  state.T_w_b.linear() = orthonormalised(R);
  state.T_w_b.translation() = p;
  if (!outside) {
    state.v_w_mps = dp / dt_s_;
    state.a_w_mps2 = ddp / (dt_s_ * dt_s_);
    state.omega_b_radps = omega;
  }
  return state;
}

SplineTrajectory SplineTrajectory::fit(const std::vector<StampedPose>& poses,
                                       const TrajectoryFitConfig& config) {
  config.validate();
  if (poses.size() < 2) throw std::invalid_argument("trajectory fit needs at least 2 poses");
  for (std::size_t i = 1; i < poses.size(); ++i) {
    if (poses[i].t_ns <= poses[i - 1].t_ns) {
      throw std::invalid_argument("trajectory fit: timestamps must strictly increase (pose " +
                                  std::to_string(i) + ")");
    }
  }
  const Timestamp start_ns = poses.front().t_ns;
  const Timestamp end_ns = poses.back().t_ns;
  double dt_s = config.knot_spacing_s;
  if (dt_s <= 0.0) {
    std::vector<Timestamp> gaps(poses.size() - 1);
    for (std::size_t i = 1; i < poses.size(); ++i) gaps[i - 1] = poses[i].t_ns - poses[i - 1].t_ns;
    std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
    dt_s = ns_to_s(gaps[gaps.size() / 2]);
  }
  const double span_s = ns_to_s(end_ns - start_ns);
  const std::size_t segments =
      std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(span_s / dt_s - 1e-9)));
  const std::size_t n_controls = segments + 3;
  const std::size_t n_samples = poses.size();

  // Design matrix: row i holds the four basis weights of sample i.
  std::vector<std::size_t> sample_seg(n_samples);
  std::vector<Eigen::Vector4d> sample_w(n_samples);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(n_samples * 4);
  for (std::size_t i = 0; i < n_samples; ++i) {
    const double tau = ns_to_s(poses[i].t_ns - start_ns) / dt_s;
    std::size_t seg = static_cast<std::size_t>(std::max(0.0, std::floor(tau)));
    if (seg >= segments) seg = segments - 1;
    sample_seg[i] = seg;
    sample_w[i] = bspline_basis(tau - static_cast<double>(seg)).b;
    for (int j = 0; j < 4; ++j) {
      triplets.emplace_back(static_cast<int>(i), static_cast<int>(seg) + j, sample_w[i][j]);
    }
  }
  Eigen::SparseMatrix<double> A(static_cast<int>(n_samples), static_cast<int>(n_controls));
  A.setFromTriplets(triplets.begin(), triplets.end());
  triplets.clear();
  for (std::size_t k = 0; k + 2 < n_controls; ++k) {
    const int row = static_cast<int>(k);
    triplets.emplace_back(row, row, 1.0);
    triplets.emplace_back(row, row + 1, -2.0);
    triplets.emplace_back(row, row + 2, 1.0);
  }
  Eigen::SparseMatrix<double> D(static_cast<int>(n_controls - 2), static_cast<int>(n_controls));
  D.setFromTriplets(triplets.begin(), triplets.end());
  const Eigen::SparseMatrix<double> At = A.transpose();
  Eigen::SparseMatrix<double> M = At * A;
  // A tiny ridge keeps the system definite even with no smoothing and sparse samples.
  constexpr double kRidge = 1e-12;
  Eigen::SparseMatrix<double> I(static_cast<int>(n_controls), static_cast<int>(n_controls));
  I.setIdentity();
  M += config.smoothing_weight * (Eigen::SparseMatrix<double>(D.transpose()) * D) + kRidge * I;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(M);
  if (solver.info() != Eigen::Success) throw std::invalid_argument("trajectory fit: singular system");

  // Positions: linear least squares.
  Eigen::MatrixXd P(static_cast<int>(n_samples), 3);
  for (std::size_t i = 0; i < n_samples; ++i)
    P.row(static_cast<int>(i)) = poses[i].T_w_b.translation().transpose();
  const Eigen::MatrixXd C = solver.solve(At * P);
  std::vector<Eigen::Vector3d> positions(n_controls);
  for (std::size_t k = 0; k < n_controls; ++k) positions[k] = C.row(static_cast<int>(k)).transpose();

  // Rotations: start from the samples interpolated at the controls' centre times, then Gauss-Newton with
  // the (non-cumulative) basis as approximate Jacobian of a right perturbation of each control.
  std::vector<Eigen::Matrix3d> rotations(n_controls);
  for (std::size_t k = 0; k < n_controls; ++k) {
    const double t_rel_s = (static_cast<double>(k) - 1.0) * dt_s;
    rotations[k] = sample_rotation_at(poses, start_ns + s_to_ns(t_rel_s));
  }
  const Timestamp spline_end_ns = start_ns + s_to_ns(static_cast<double>(segments) * dt_s);
  for (int iter = 0; iter < config.rotation_iterations; ++iter) {
    const SplineTrajectory current(start_ns, std::max(end_ns, spline_end_ns), dt_s, positions, rotations);
    Eigen::MatrixXd R_res(static_cast<int>(n_samples), 3);
    double max_residual_rad = 0.0;
    for (std::size_t i = 0; i < n_samples; ++i) {
      const Eigen::Matrix3d R_spline = current.evaluate(poses[i].t_ns).T_w_b.linear();
      const Eigen::Vector3d r = so3_log(R_spline.transpose() * poses[i].T_w_b.linear());
      R_res.row(static_cast<int>(i)) = r.transpose();
      max_residual_rad = std::max(max_residual_rad, r.norm());
    }
    if (max_residual_rad < config.rotation_tolerance_rad) break;
    const Eigen::MatrixXd delta = solver.solve(At * R_res);
    for (std::size_t k = 0; k < n_controls; ++k) {
      rotations[k] = orthonormalised(rotations[k] * so3_exp(delta.row(static_cast<int>(k)).transpose()));
    }
  }
  return SplineTrajectory(start_ns, end_ns, dt_s, std::move(positions), std::move(rotations));
}

std::vector<StampedPose> load_kitti_trajectory(const std::filesystem::path& poses_file,
                                               const std::filesystem::path& times_file) {
  return read_kitti_poses(poses_file, times_file);
}

std::vector<StampedPose> load_euroc_trajectory(const std::filesystem::path& csv_file) {
  const std::vector<GroundTruthState> states = read_euroc_groundtruth(csv_file);
  std::vector<StampedPose> poses;
  poses.reserve(states.size());
  for (const GroundTruthState& s : states) poses.push_back(StampedPose{s.t_ns, s.T_w_b});
  return poses;
}

std::vector<StampedPose> load_tum_trajectory(const std::filesystem::path& file) {
  return read_tum(file);
}

namespace {

// Largest turn at a waypoint: a U-turn cannot be rounded by a fillet.
constexpr double kMaxWaypointTurnRad = 170.0 * std::numbers::pi / 180.0;
// Turns below this are treated as straight on (no fillet).
constexpr double kStraightTurnRad = 1e-9;

// One piece of a waypoint route: a straight, or a circular arc (signed turn, + = left).
struct RoutePiece {
  Eigen::Vector2d start = Eigen::Vector2d::Zero();
  double heading_rad = 0.0;  // at the start of the piece
  double length_m = 0.0;
  double turn_rad = 0.0;  // 0 for a straight
  double radius_m = 0.0;
};

// The straights and corner arcs of a waypoint polyline with every corner rounded with `radius_m`.
// Throws ConfigError (route.waypoints) when consecutive points coincide, a turn is a U-turn or a segment
// is too short for the fillets at its ends.
std::vector<RoutePiece> waypoint_pieces(const std::vector<Eigen::Vector2d>& points, double radius_m) {
  const std::size_t n = points.size();
  std::vector<Eigen::Vector2d> dir(n - 1);
  std::vector<double> length(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const Eigen::Vector2d d = points[k + 1] - points[k];
    length[k] = d.norm();
    if (!(length[k] > 0.0)) {
      throw ConfigError("route.waypoints: points " + std::to_string(k) + " and " + std::to_string(k + 1) +
                        " coincide (expected distinct consecutive points)");
    }
    dir[k] = d / length[k];
  }
  // Turn and tangent length (distance from the waypoint to where its arc starts / ends) per interior point.
  std::vector<double> turn(n, 0.0), tangent(n, 0.0);
  for (std::size_t k = 1; k + 1 < n; ++k) {
    const Eigen::Vector2d& a = dir[k - 1];
    const Eigen::Vector2d& b = dir[k];
    turn[k] = std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
    if (std::abs(turn[k]) > kMaxWaypointTurnRad) {
      throw ConfigError("route.waypoints: the turn at point " + std::to_string(k) +
                        " is a U-turn (expected turns of at most 170 degrees)");
    }
    if (std::abs(turn[k]) < kStraightTurnRad) turn[k] = 0.0;
    tangent[k] = radius_m * std::tan(0.5 * std::abs(turn[k]));
  }
  std::vector<RoutePiece> pieces;
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const double straight_m = length[k] - tangent[k] - tangent[k + 1];
    if (straight_m < 0.0) {
      throw ConfigError("route.waypoints: segment " + std::to_string(k) + " -> " + std::to_string(k + 1) +
                        " (" + std::to_string(length[k]) + " m) is shorter than its rounded corners need (" +
                        std::to_string(tangent[k] + tangent[k + 1]) + " m with route.corner_radius_m " +
                        std::to_string(radius_m) + ")");
    }
    const double heading = std::atan2(dir[k].y(), dir[k].x());
    RoutePiece straight;
    straight.start = points[k] + tangent[k] * dir[k];
    straight.heading_rad = heading;
    straight.length_m = straight_m;
    pieces.push_back(straight);
    if (k + 2 < n && turn[k + 1] != 0.0) {
      RoutePiece arc;
      arc.start = points[k + 1] - tangent[k + 1] * dir[k];
      arc.heading_rad = heading;
      arc.turn_rad = turn[k + 1];
      arc.radius_m = radius_m;
      arc.length_m = radius_m * std::abs(turn[k + 1]);
      pieces.push_back(arc);
    }
  }
  return pieces;
}

// Point and heading at distance `along_m` into a piece.
void piece_point(const RoutePiece& piece, double along_m, Eigen::Vector2d* p, double* heading_rad) {
  const Eigen::Vector2d d(std::cos(piece.heading_rad), std::sin(piece.heading_rad));
  if (piece.turn_rad == 0.0) {
    *p = piece.start + along_m * d;
    *heading_rad = piece.heading_rad;
    return;
  }
  const double side = piece.turn_rad > 0.0 ? 1.0 : -1.0;  // left turn: centre on the left
  const Eigen::Vector2d left(-d.y(), d.x());
  const Eigen::Vector2d centre = piece.start + side * piece.radius_m * left;
  const double h = piece.heading_rad + side * along_m / piece.radius_m;
  // The point is at -side * radius * left(h) from the centre.
  *p = centre - side * piece.radius_m * Eigen::Vector2d(-std::sin(h), std::cos(h));
  *heading_rad = h;
}

}  // namespace

std::vector<Eigen::Vector2d> parse_route_waypoints(const std::string& text) {
  std::vector<Eigen::Vector2d> points;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find(';', start);
    if (end == std::string::npos) end = text.size();
    const std::string item = text.substr(start, end - start);
    start = end + 1;
    if (item.find_first_not_of(" \t") == std::string::npos) {
      if (end == text.size()) break;  // a trailing ';'
      throw ConfigError("route.waypoints: empty point " + std::to_string(points.size()) +
                        " (expected 'x,y; x,y; ...')");
    }
    const std::size_t comma = item.find(',');
    double xy[2] = {0.0, 0.0};
    bool ok = comma != std::string::npos && item.find(',', comma + 1) == std::string::npos;
    for (int c = 0; ok && c < 2; ++c) {
      std::string field = c == 0 ? item.substr(0, comma) : item.substr(comma + 1);
      const std::size_t b = field.find_first_not_of(" \t");
      const std::size_t e = field.find_last_not_of(" \t");
      field = b == std::string::npos ? std::string() : field.substr(b, e - b + 1);
      const char* first = field.data();
      const char* last = field.data() + field.size();
      const auto [ptr, ec] = std::from_chars(first, last, xy[c]);
      ok = !field.empty() && ec == std::errc() && ptr == last && std::isfinite(xy[c]);
    }
    if (!ok) {
      throw ConfigError("route.waypoints: point " + std::to_string(points.size()) + " '" + item +
                        "' is not 'x,y' with two finite numbers in metres");
    }
    points.emplace_back(xy[0], xy[1]);
  }
  if (points.size() < 2) {
    throw ConfigError("route.waypoints: " + std::to_string(points.size()) +
                      " points given, expected at least 2 ('x0,y0; x1,y1; ...')");
  }
  return points;
}

void ProceduralRouteConfig::validate() const {
  if (!(corner_radius_m > 0.0)) throw ConfigError("corner_radius_m must be > 0");
  if (shape == RouteShape::kCircuit &&
      (!(length_x_m >= 2.0 * corner_radius_m) || !(length_y_m >= 2.0 * corner_radius_m))) {
    throw ConfigError("length_x_m and length_y_m must be >= 2 * corner_radius_m");
  }
  if (shape == RouteShape::kWaypoints) waypoint_pieces(parse_route_waypoints(waypoints), corner_radius_m);
  if (laps < 1 || laps > 1000) throw ConfigError("route.laps: must be in [1, 1000]");
  if (frames < 2 || frames > 10'000'000) throw ConfigError("route.frames: must be in [2, 10000000]");
  if (!(rate_hz > 0.0 && rate_hz <= 1000.0)) throw ConfigError("route.rate_hz: must be in (0, 1000] Hz");
  if (!(speed_variation >= 0.0 && speed_variation < 1.0))
    throw ConfigError("speed_variation must be in [0, 1)");
  if (!(heading_wobble_period_s > 0.0)) throw ConfigError("heading_wobble_period_s must be > 0");
  if (!(std::abs(revisit_lateral_offset_m) <= 20.0)) {
    throw ConfigError("route.revisit_lateral_offset_m: " + std::to_string(revisit_lateral_offset_m) +
                      " is not in [-20, 20] m (a lane is ~3.5 m wide)");
  }
  if (!(revisit_radius_m > 0.0 && revisit_radius_m <= 100.0)) {
    throw ConfigError("route.revisit_radius_m: " + std::to_string(revisit_radius_m) +
                      " is not in (0, 100] m");
  }
  if (!(revisit_min_travel_m >= 0.0 && std::isfinite(revisit_min_travel_m))) {
    throw ConfigError("route.revisit_min_travel_m: " + std::to_string(revisit_min_travel_m) +
                      " must be a finite number >= 0 m");
  }
  if (!(revisit_lane_change_m >= 0.0 && std::isfinite(revisit_lane_change_m))) {
    throw ConfigError("route.revisit_lane_change_m: " + std::to_string(revisit_lane_change_m) +
                      " must be a finite number >= 0 m");
  }
}

namespace {

// The body pose at time t_s on a procedural route: the route point p with its heading, shifted left by the
// lateral offset grown to `offset_fraction` of lap_lateral_offset_m, camera height, heading wobble.
StampedPose route_pose(const ProceduralRouteConfig& config, double t_s, double offset_fraction,
                       Eigen::Vector2d p, double heading) {
  const Eigen::Vector2d left(-std::sin(heading), std::cos(heading));
  p += config.lap_lateral_offset_m * offset_fraction * left;
  const double yaw = heading + config.heading_wobble_rad *
                                   std::sin(2.0 * std::numbers::pi * t_s / config.heading_wobble_period_s);
  StampedPose pose;
  pose.t_ns = config.start_t_ns + s_to_ns(t_s);
  pose.T_w_b.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.T_w_b.translation() = Eigen::Vector3d(p.x(), p.y(), config.camera_height_m);
  return pose;
}

std::vector<StampedPose> make_waypoint_route(const ProceduralRouteConfig& config) {
  const std::vector<RoutePiece> pieces =
      waypoint_pieces(parse_route_waypoints(config.waypoints), config.corner_radius_m);
  std::vector<double> piece_start_m(pieces.size(), 0.0);
  double total_m = 0.0;
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    piece_start_m[k] = total_m;
    total_m += pieces[k].length_m;
  }
  const auto route_point = [&](double s, Eigen::Vector2d* p, double* heading) {
    s = std::clamp(s, 0.0, total_m);
    std::size_t k = static_cast<std::size_t>(std::upper_bound(piece_start_m.begin(), piece_start_m.end(), s) -
                                             piece_start_m.begin());
    k = k == 0 ? 0 : k - 1;
    piece_point(pieces[k], s - piece_start_m[k], p, heading);
  };
  // Speed modulation over the whole route, rescaled so that the last frame is at the last waypoint.
  const double cycles = config.speed_cycles_per_lap;
  const auto progress = [&](double tau) {
    const double modulation = cycles > 0.0 ? config.speed_variation / (2.0 * std::numbers::pi * cycles) *
                                                 std::sin(2.0 * std::numbers::pi * cycles * tau)
                                           : 0.0;
    return tau + modulation;
  };
  const double progress_end = progress(1.0);
  std::vector<StampedPose> poses;
  poses.reserve(static_cast<std::size_t>(config.frames));
  for (int i = 0; i < config.frames; ++i) {
    const double tau = static_cast<double>(i) / static_cast<double>(config.frames - 1);
    const double t_s = static_cast<double>(i) / config.rate_hz;
    const double s = total_m * progress(tau) / progress_end;
    Eigen::Vector2d p;
    double heading = 0.0;
    route_point(s, &p, &heading);
    poses.push_back(route_pose(config, t_s, s / total_m, p, heading));
  }
  return poses;
}

}  // namespace

std::vector<StampedPose> make_procedural_route(const ProceduralRouteConfig& config) {
  config.validate();
  if (config.shape == RouteShape::kWaypoints) return make_waypoint_route(config);
  const double r = config.corner_radius_m;
  const double straight_x = config.length_x_m - 2.0 * r;
  const double straight_y = config.length_y_m - 2.0 * r;
  const double arc = 0.5 * std::numbers::pi * r;
  const double perimeter = 2.0 * (straight_x + straight_y) + 4.0 * arc;
  const double total_m = perimeter * static_cast<double>(config.laps);
  const double start_offset_m = 0.5 * straight_x;  // start mid-way along the first straight

  // Point, heading at arc length s (mod perimeter) on the circuit; counter-clockwise, left turns.
  auto circuit = [&](double s, Eigen::Vector2d* p, double* heading) {
    s = std::fmod(s, perimeter);
    if (s < 0.0) s += perimeter;
    Eigen::Vector2d pos(-0.5 * config.length_x_m + r, -0.5 * config.length_y_m);
    for (int piece = 0; piece < 4; ++piece) {
      const double theta = 0.5 * std::numbers::pi * piece;
      const Eigen::Vector2d dir(std::cos(theta), std::sin(theta));
      const double straight = (piece % 2 == 0) ? straight_x : straight_y;
      if (s <= straight) {
        *p = pos + s * dir;
        *heading = theta;
        return;
      }
      s -= straight;
      pos += straight * dir;
      const Eigen::Vector2d centre = pos + r * Eigen::Vector2d(-dir.y(), dir.x());
      if (s <= arc || piece == 3) {
        const double phi = std::min(s, arc) / r;
        *p = centre + r * Eigen::Vector2d(std::sin(theta + phi), -std::cos(theta + phi));
        *heading = theta + phi;
        return;
      }
      s -= arc;
      pos = centre + r * Eigen::Vector2d(std::sin(theta + 0.5 * std::numbers::pi),
                                         -std::cos(theta + 0.5 * std::numbers::pi));
    }
  };

  const double cycles = config.speed_cycles_per_lap * static_cast<double>(config.laps);
  std::vector<StampedPose> poses;
  poses.reserve(static_cast<std::size_t>(config.frames));
  for (int i = 0; i < config.frames; ++i) {
    const double tau = static_cast<double>(i) / static_cast<double>(config.frames - 1);
    const double t_s = static_cast<double>(i) / config.rate_hz;
    const double modulation = cycles > 0.0 ? config.speed_variation / (2.0 * std::numbers::pi * cycles) *
                                                 std::sin(2.0 * std::numbers::pi * cycles * tau)
                                           : 0.0;
    const double s = total_m * (tau + modulation);
    Eigen::Vector2d p;
    double heading = 0.0;
    circuit(start_offset_m + s, &p, &heading);
    poses.push_back(route_pose(config, t_s, s / perimeter, p, heading));
  }
  return poses;
}

}  // namespace loopgate::sim
