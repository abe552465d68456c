// Trajectory sources and the C2 spline fit: passes through the input, analytic derivatives agree with
// finite differences, continuity across knots, procedural route revisits.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "sim/trajectory.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

constexpr Timestamp kMs = 1'000'000;

double rotation_error_rad(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return so3_log(a.transpose() * b).norm();
}

// An analytic helix-like motion with a rolling / pitching body, sampled at `rate_hz`.
std::vector<StampedPose> analytic_poses(double duration_s, double rate_hz) {
  std::vector<StampedPose> poses;
  const int n = static_cast<int>(duration_s * rate_hz) + 1;
  for (int i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / rate_hz;
    StampedPose p;
    p.t_ns = 5'000 * kMs + s_to_ns(t);
    p.T_w_b.translation() =
        Eigen::Vector3d(10.0 * std::cos(0.2 * t), 10.0 * std::sin(0.2 * t), 0.5 * std::sin(0.5 * t));
    p.T_w_b.linear() = (Eigen::AngleAxisd(0.2 * t + 0.5 * std::numbers::pi, Eigen::Vector3d::UnitZ()) *
                        Eigen::AngleAxisd(0.1 * std::sin(0.7 * t), Eigen::Vector3d::UnitY()) *
                        Eigen::AngleAxisd(0.05 * std::cos(1.1 * t), Eigen::Vector3d::UnitX()))
                           .toRotationMatrix();
    poses.push_back(p);
  }
  return poses;
}

TEST(SplineTrajectory, PassesThroughInputPoses) {
  const auto poses = analytic_poses(30.0, 10.0);
  const SplineTrajectory spline = SplineTrajectory::fit(poses);
  EXPECT_NEAR(spline.knot_spacing_s(), 0.1, 1e-9);
  double max_pos_m = 0.0;
  double max_rot_rad = 0.0;
  for (const StampedPose& p : poses) {
    const Eigen::Isometry3d T = spline.pose(p.t_ns);
    max_pos_m = std::max(max_pos_m, (T.translation() - p.T_w_b.translation()).norm());
    max_rot_rad = std::max(max_rot_rad, rotation_error_rad(T.linear(), p.T_w_b.linear()));
  }
  std::printf("fit error at the %zu input poses: max position %.3g m, max rotation %.3g rad\n", poses.size(),
              max_pos_m, max_rot_rad);
  EXPECT_LT(max_pos_m, 1e-3);
  EXPECT_LT(max_rot_rad, 1e-4);
}

TEST(SplineTrajectory, BetweenSamplesFollowsTheTrueMotion) {
  // Between the 10 Hz samples, the fit stays close to the analytic motion (the fit is C2, the motion smooth).
  const auto coarse = analytic_poses(30.0, 10.0);
  const auto fine = analytic_poses(30.0, 200.0);
  const SplineTrajectory spline = SplineTrajectory::fit(coarse);
  double max_pos_m = 0.0;
  for (std::size_t i = 20; i + 20 < fine.size(); ++i) {
    max_pos_m =
        std::max(max_pos_m, (spline.pose(fine[i].t_ns).translation() - fine[i].T_w_b.translation()).norm());
  }
  EXPECT_LT(max_pos_m, 1e-3);
}

TEST(SplineTrajectory, AnalyticDerivativesMatchFiniteDifferences) {
  const auto poses = analytic_poses(20.0, 10.0);
  const SplineTrajectory spline = SplineTrajectory::fit(poses);
  const Timestamp h_ns = 100'000;  // 0.1 ms
  const double h_s = ns_to_s(h_ns);
  for (Timestamp t = poses.front().t_ns + 1000 * kMs; t < poses.back().t_ns - 1000 * kMs; t += 37 * kMs) {
    const TrajectoryState s = spline.evaluate(t);
    const TrajectoryState sm = spline.evaluate(t - h_ns);
    const TrajectoryState sp = spline.evaluate(t + h_ns);
    const Eigen::Vector3d v_fd = (sp.T_w_b.translation() - sm.T_w_b.translation()) / (2.0 * h_s);
    const Eigen::Vector3d a_fd = (sp.v_w_mps - sm.v_w_mps) / (2.0 * h_s);
    const Eigen::Vector3d w_fd = so3_log(sm.T_w_b.linear().transpose() * sp.T_w_b.linear()) / (2.0 * h_s);
    EXPECT_LT((s.v_w_mps - v_fd).norm(), 1e-6) << "t_ns " << t;
    EXPECT_LT((s.a_w_mps2 - a_fd).norm(), 1e-5) << "t_ns " << t;
    EXPECT_LT((s.omega_b_radps - w_fd).norm(), 1e-6) << "t_ns " << t;
  }
}

TEST(SplineTrajectory, DerivativesMatchTheTrueMotion) {
  // Velocity of the helix: radius 10 m at 0.2 rad/s -> 2 m/s horizontal; yaw rate about 0.2 rad/s.
  const auto poses = analytic_poses(30.0, 10.0);
  const SplineTrajectory spline = SplineTrajectory::fit(poses);
  const double t = 15.0;
  const TrajectoryState s = spline.evaluate(poses.front().t_ns + s_to_ns(t));
  const Eigen::Vector3d v_true(-2.0 * std::sin(0.2 * t), 2.0 * std::cos(0.2 * t), 0.25 * std::cos(0.5 * t));
  const Eigen::Vector3d a_true(-0.4 * std::cos(0.2 * t), -0.4 * std::sin(0.2 * t),
                               -0.125 * std::sin(0.5 * t));
  EXPECT_LT((s.v_w_mps - v_true).norm(), 2e-3);
  EXPECT_LT((s.a_w_mps2 - a_true).norm(), 2e-2);
  // World-frame angular velocity projected on world z is the yaw rate 0.2 (plus small tilt terms).
  const Eigen::Vector3d omega_w = s.T_w_b.linear() * s.omega_b_radps;
  EXPECT_NEAR(omega_w.z(), 0.2, 0.02);
}

TEST(SplineTrajectory, IsC2AcrossKnots) {
  const auto poses = analytic_poses(10.0, 10.0);
  const SplineTrajectory spline = SplineTrajectory::fit(poses);
  const Timestamp knot = spline.start_t_ns() + s_to_ns(5.0 * spline.knot_spacing_s());
  const TrajectoryState before = spline.evaluate(knot - 1);
  const TrajectoryState after = spline.evaluate(knot + 1);
  EXPECT_LT((before.v_w_mps - after.v_w_mps).norm(), 1e-6);
  EXPECT_LT((before.a_w_mps2 - after.a_w_mps2).norm(), 1e-5);
  EXPECT_LT((before.omega_b_radps - after.omega_b_radps).norm(), 1e-6);
}

TEST(SplineTrajectory, HoldsTheEndPosesOutsideTheSpan) {
  const auto poses = analytic_poses(5.0, 10.0);
  const SplineTrajectory spline = SplineTrajectory::fit(poses);
  const TrajectoryState before = spline.evaluate(spline.start_t_ns() - 1000 * kMs);
  EXPECT_LT((before.T_w_b.translation() - spline.pose(spline.start_t_ns()).translation()).norm(), 1e-12);
  EXPECT_EQ(before.v_w_mps, Eigen::Vector3d::Zero());
  EXPECT_EQ(before.omega_b_radps, Eigen::Vector3d::Zero());
  const TrajectoryState after = spline.evaluate(spline.end_t_ns() + 1000 * kMs);
  EXPECT_LT((after.T_w_b.translation() - poses.back().T_w_b.translation()).norm(), 1e-3);
}

TEST(SplineTrajectory, RejectsUnusableInput) {
  std::vector<StampedPose> poses(3);
  poses[0].t_ns = 0;
  poses[1].t_ns = 100 * kMs;
  poses[2].t_ns = 100 * kMs;
  EXPECT_THROW(SplineTrajectory::fit(poses), std::invalid_argument);
  EXPECT_THROW(SplineTrajectory::fit(std::vector<StampedPose>(1)), std::invalid_argument);
  TrajectoryFitConfig bad;
  bad.smoothing_weight = -1.0;
  EXPECT_THROW(bad.validate(), ConfigError);
}

TEST(ProceduralRoute, TwoLapsRevisitTheSamePlaces) {
  ProceduralRouteConfig config;
  const auto poses = make_procedural_route(config);
  ASSERT_EQ(poses.size(), 600u);
  EXPECT_EQ(poses[1].t_ns - poses[0].t_ns, 100 * kMs);
  // The second lap passes within 2 m of every place of the first lap.
  std::size_t revisited = 0;
  for (std::size_t i = 0; i < 300; ++i) {
    double best = 1e9;
    for (std::size_t j = 300; j < 600; ++j) {
      best = std::min(best, (poses[i].T_w_b.translation() - poses[j].T_w_b.translation()).norm());
    }
    if (best < 2.0) ++revisited;
  }
  EXPECT_GE(revisited, 295u);
  // Constant camera height, closed circuit: the last frame is back near the first.
  EXPECT_NEAR(poses[123].T_w_b.translation().z(), config.camera_height_m, 1e-12);
  EXPECT_LT((poses.front().T_w_b.translation() - poses.back().T_w_b.translation()).norm(), 2.0);
  // Driving forward: the body x axis points along the motion.
  const Eigen::Vector3d motion = poses[11].T_w_b.translation() - poses[9].T_w_b.translation();
  EXPECT_GT(motion.normalized().dot(poses[10].T_w_b.linear().col(0)), 0.99);
  ProceduralRouteConfig bad;
  bad.corner_radius_m = 100.0;
  EXPECT_THROW(bad.validate(), ConfigError);
}

TEST(ProceduralRoute, WaypointsParseAndRejectMalformedLists) {
  const auto points = parse_route_waypoints(" -25,-25; 40.5 , -25;40,25e0 ;");
  ASSERT_EQ(points.size(), 3u);
  EXPECT_EQ(points[0], Eigen::Vector2d(-25.0, -25.0));
  EXPECT_EQ(points[1], Eigen::Vector2d(40.5, -25.0));
  EXPECT_EQ(points[2], Eigen::Vector2d(40.0, 25.0));
  for (const char* bad :
       {"", "1,2", "1,2; 3", "1,2; 3,4,5", "1,2; x,4", "1,2;; 3,4", "1,2; 3,4m", "1,2; nan,4"}) {
    try {
      parse_route_waypoints(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("route.waypoints"), std::string::npos) << e.what();
    }
  }
  ProceduralRouteConfig config;
  config.shape = sim::RouteShape::kWaypoints;
  config.waypoints = "0,0; 100,0; 100,50";
  EXPECT_NO_THROW(config.validate());
  config.waypoints = "0,0; 100,0; 100,10";  // 10 m segment, two 12 m fillets would need 12 m
  config.corner_radius_m = 12.0;
  EXPECT_THROW(config.validate(), ConfigError);
  config.waypoints = "0,0; 100,0; 0,0.1";  // a U-turn
  EXPECT_THROW(config.validate(), ConfigError);
  config.waypoints = "0,0; 0,0; 10,0";  // coincident points
  EXPECT_THROW(config.validate(), ConfigError);
}

TEST(ProceduralRoute, WaypointsAreDrivenOnceWithRoundedCorners) {
  // A left turn then a right turn: 0,0 -> 100,0 -> 100,60 -> 160,60, corners of radius 10.
  ProceduralRouteConfig config;
  config.shape = sim::RouteShape::kWaypoints;
  config.waypoints = "0,0; 100,0; 100,60; 160,60";
  config.corner_radius_m = 10.0;
  config.frames = 501;
  config.speed_variation = 0.0;
  config.heading_wobble_rad = 0.0;
  config.lap_lateral_offset_m = 0.0;
  const auto poses = make_procedural_route(config);
  ASSERT_EQ(poses.size(), 501u);
  // Length: 100 + 60 + 60 - 4 * 10 (tangents) + 2 * (pi / 2 * 10) (arcs), at constant speed.
  const double length_m = 180.0 + 10.0 * std::numbers::pi;
  const Eigen::Vector3d first = poses.front().T_w_b.translation();
  const Eigen::Vector3d last = poses.back().T_w_b.translation();
  EXPECT_LT((first - Eigen::Vector3d(0.0, 0.0, config.camera_height_m)).norm(), 1e-9);
  EXPECT_LT((last - Eigen::Vector3d(160.0, 60.0, config.camera_height_m)).norm(), 1e-9);
  double travelled_m = 0.0, max_step_m = 0.0, min_step_m = 1e9;
  for (std::size_t i = 1; i < poses.size(); ++i) {
    const double step = (poses[i].T_w_b.translation() - poses[i - 1].T_w_b.translation()).norm();
    travelled_m += step;
    max_step_m = std::max(max_step_m, step);
    min_step_m = std::min(min_step_m, step);
    // Heading continuous and along the motion.
    const Eigen::Vector3d motion = poses[i].T_w_b.translation() - poses[i - 1].T_w_b.translation();
    EXPECT_GT(motion.normalized().dot(poses[i].T_w_b.linear().col(0)), 0.995) << i;
    EXPECT_LT(rotation_error_rad(poses[i].T_w_b.linear(), poses[i - 1].T_w_b.linear()), 0.06) << i;
  }
  EXPECT_NEAR(travelled_m, length_m, 0.05);
  EXPECT_NEAR(max_step_m, min_step_m, 1e-3);  // chords on the arcs are a hair shorter than the arc
  // Halfway along the first straight, heading east; the middle of the second straight heading north; the
  // left corner's arc midpoint lies 10 * (sqrt(2) - 1) m inside the waypoint.
  const auto frame_at = [&](double s_m) {
    return static_cast<std::size_t>(std::lround(s_m / length_m * 500));
  };
  const Eigen::Isometry3d& mid_first = poses[frame_at(45.0)].T_w_b;
  EXPECT_NEAR(mid_first.translation().y(), 0.0, 1e-9);
  EXPECT_NEAR(mid_first.linear().col(0).x(), 1.0, 1e-9);
  const Eigen::Isometry3d& mid_second = poses[frame_at(90.0 + 5.0 * std::numbers::pi + 20.0)].T_w_b;
  EXPECT_NEAR(mid_second.translation().x(), 100.0, 1e-9);
  EXPECT_NEAR(mid_second.linear().col(0).y(), 1.0, 1e-9);
  double corner_m = 1e9;
  for (const StampedPose& p : poses)
    corner_m = std::min(corner_m, (p.T_w_b.translation().head<2>() - Eigen::Vector2d(100.0, 0.0)).norm());
  EXPECT_NEAR(corner_m, 10.0 * (std::sqrt(2.0) - 1.0), 0.02);
  // The right turn: the last straight heads east again, on y = 60.
  EXPECT_NEAR(poses[495].T_w_b.translation().y(), 60.0, 1e-9);
  EXPECT_NEAR(poses[495].T_w_b.linear().col(0).x(), 1.0, 1e-9);

  // Speed modulation and the lateral offset keep the end points: the last frame at the last waypoint, the
  // offset grown to lap_lateral_offset_m (to the left of the last heading, east: +y).
  config.speed_variation = 0.15;
  config.speed_cycles_per_lap = 1.5;
  config.lap_lateral_offset_m = 0.6;
  const auto modulated = make_procedural_route(config);
  EXPECT_LT(
      (modulated.back().T_w_b.translation() - Eigen::Vector3d(160.0, 60.6, config.camera_height_m)).norm(),
      1e-9);
  EXPECT_LT((modulated.front().T_w_b.translation() - first).norm(), 1e-12);
}

TEST(SplineTrajectory, FitsKitti00) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/poses.txt");
  const auto dir = loopgate::testing::shared_data_dir() / "kitti" / "00";
  const auto poses = load_kitti_trajectory(dir / "poses.txt", dir / "times.txt");
  ASSERT_EQ(poses.size(), 4541u);
  const SplineTrajectory spline = SplineTrajectory::fit(poses);
  double max_pos_m = 0.0;
  double sum_pos_m = 0.0;
  double max_rot_rad = 0.0;
  for (const StampedPose& p : poses) {
    const Eigen::Isometry3d T = spline.pose(p.t_ns);
    const double e = (T.translation() - p.T_w_b.translation()).norm();
    max_pos_m = std::max(max_pos_m, e);
    sum_pos_m += e;
    max_rot_rad = std::max(max_rot_rad, rotation_error_rad(T.linear(), p.T_w_b.linear()));
  }
  std::printf("KITTI 00 fit: %zu controls, mean position error %.3g m, max %.3g m, max rotation %.3g rad\n",
              spline.control_count(), sum_pos_m / static_cast<double>(poses.size()), max_pos_m, max_rot_rad);
  EXPECT_LT(max_pos_m, 0.05);
  EXPECT_LT(max_rot_rad, 5e-3);
}

}  // namespace
}  // namespace loopgate::sim
