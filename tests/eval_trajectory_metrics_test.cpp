// ATE with SE3 (Umeyama, no scale) and position + yaw alignment, drift per 100 m, time association.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "core/error.hpp"
#include "eval/trajectory_metrics.hpp"

namespace loopgate {
namespace {

std::vector<Eigen::Vector3d> random_path(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> step(0.0, 1.0);
  std::vector<Eigen::Vector3d> p{Eigen::Vector3d::Zero()};
  while (p.size() < n) p.push_back(p.back() + Eigen::Vector3d(step(rng), step(rng), 0.3 * step(rng)));
  return p;
}

std::vector<Eigen::Vector3d> transformed(const Eigen::Isometry3d& T, const std::vector<Eigen::Vector3d>& p) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& x : p) out.push_back(T * x);
  return out;
}

TEST(EvalTrajectoryMetrics, Se3AlignmentRecoversAKnownTransform) {
  const auto p_gt = random_path(200, 1);
  Eigen::Isometry3d T_est_gt = Eigen::Isometry3d::Identity();
  T_est_gt.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  T_est_gt.translation() = Eigen::Vector3d(3.0, -4.0, 10.0);
  const auto p_est = transformed(T_est_gt, p_gt);
  const Eigen::Isometry3d T = align_se3(p_est, p_gt);
  EXPECT_TRUE(T.isApprox(T_est_gt.inverse(), 1e-9)) << T.matrix();
  const AteResult ate = compute_ate(p_est, p_gt);
  EXPECT_LT(ate.rmse_m, 1e-9);
  AteConfig none;
  none.alignment = AteAlignment::kNone;
  EXPECT_GT(compute_ate(p_est, p_gt, none).rmse_m, 1.0);
}

TEST(EvalTrajectoryMetrics, AteOfAKnownOffsetNoise) {
  // Alternate +-0.1 m along z on a planar square path: the best SE3 cannot remove it; RMSE = 0.1.
  std::vector<Eigen::Vector3d> p_gt, p_est;
  for (int i = 0; i < 400; ++i) {
    const double a = 2.0 * std::numbers::pi * i / 400.0;
    p_gt.emplace_back(10 * std::cos(a), 10 * std::sin(a), 0.0);
    p_est.push_back(p_gt.back() + Eigen::Vector3d(0, 0, i % 2 == 0 ? 0.1 : -0.1));
  }
  const AteResult ate = compute_ate(p_est, p_gt);
  EXPECT_NEAR(ate.rmse_m, 0.1, 1e-6);
  EXPECT_NEAR(ate.mean_m, 0.1, 1e-6);
  EXPECT_NEAR(ate.max_m, 0.1, 1e-6);
}

TEST(EvalTrajectoryMetrics, PositionYawAlignmentRecoversYawAndTranslationOnly) {
  const auto p_gt = random_path(150, 2);
  Eigen::Isometry3d T_est_gt = Eigen::Isometry3d::Identity();
  T_est_gt.linear() = Eigen::AngleAxisd(-2.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T_est_gt.translation() = Eigen::Vector3d(-7.0, 1.0, 2.0);
  const auto p_est = transformed(T_est_gt, p_gt);
  EXPECT_TRUE(align_position_yaw(p_est, p_gt).isApprox(T_est_gt.inverse(), 1e-9));
  AteConfig config;
  config.alignment = AteAlignment::kPosyaw;
  EXPECT_LT(compute_ate(p_est, p_gt, config).rmse_m, 1e-9);
  // A roll cannot be undone by a yaw: error remains; SE3 removes it.
  Eigen::Isometry3d roll = Eigen::Isometry3d::Identity();
  roll.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const auto rolled = transformed(roll, p_gt);
  EXPECT_GT(compute_ate(rolled, p_gt, config).rmse_m, 0.1);
  EXPECT_LT(compute_ate(rolled, p_gt).rmse_m, 1e-9);
  // Yaw about y (KITTI camera frame).
  Eigen::Isometry3d yaw_y = Eigen::Isometry3d::Identity();
  yaw_y.linear() = Eigen::AngleAxisd(1.1, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const AteConfig y_up{AteAlignment::kPosyaw, WorldAxis::kY};
  EXPECT_LT(compute_ate(transformed(yaw_y, p_gt), p_gt, y_up).rmse_m, 1e-9);
}

TEST(EvalTrajectoryMetrics, DriftPer100Metres) {
  // 200 m straight along x; the estimate is 1% too long: 2 m at the end -> 1 m per 100 m.
  std::vector<Eigen::Vector3d> p_gt, p_est;
  for (int i = 0; i <= 200; ++i) {
    p_gt.emplace_back(i, 0, 0);
    p_est.emplace_back(1.01 * i, 0, 0);
  }
  AteConfig config;
  config.alignment = AteAlignment::kNone;
  const AteResult ate = compute_ate(p_est, p_gt, config);
  EXPECT_NEAR(ate.path_length_m, 200.0, 1e-9);
  EXPECT_NEAR(ate.final_error_m, 2.0, 1e-9);
  EXPECT_NEAR(ate.drift_per_100m, 1.0, 1e-9);
}

TEST(EvalTrajectoryMetrics, BadInputThrows) {
  EXPECT_THROW(align_se3({Eigen::Vector3d::Zero()}, {}), std::invalid_argument);
  EXPECT_THROW(compute_ate({}, {}), std::invalid_argument);
}

TEST(EvalTrajectoryMetrics, AssociateByNearestTime) {
  auto pose = [](Timestamp t) {
    StampedPose p;
    p.t_ns = t;
    return p;
  };
  const std::vector<StampedPose> est{pose(95), pose(204), pose(500), pose(1000)};
  const std::vector<StampedPose> gt{pose(0), pose(100), pose(200), pose(300), pose(990)};
  const auto pairs = associate_by_time(est, gt, 10);
  const std::vector<std::pair<std::size_t, std::size_t>> expected{{0, 1}, {1, 2}, {3, 4}};
  EXPECT_EQ(pairs, expected);
}

}  // namespace
}  // namespace loopgate
