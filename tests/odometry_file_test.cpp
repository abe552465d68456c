#include <gtest/gtest.h>

#include <cmath>

#include "stages/odometry/file_odometry.hpp"

namespace loopgate {
namespace {

constexpr Timestamp kS = 1'000'000'000;

// Straight line along x at 2 m/s, yawing at 0.1 rad/s, a pose every second from t = 10 s to 20 s.
std::vector<StampedPose> line() {
  std::vector<StampedPose> poses;
  for (int k = 0; k <= 10; ++k) {
    StampedPose p;
    p.t_ns = (10 + k) * kS;
    p.T_w_b.translation() = Eigen::Vector3d(2.0 * k, 0, 0);
    p.T_w_b.linear() = Eigen::AngleAxisd(0.1 * k, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    poses.push_back(p);
  }
  return poses;
}

OdometryOutput at(FileOdometry& odometry, Timestamp t_ns) {
  OdometryInput input;
  input.t_ns = t_ns;
  return odometry.process(input);
}

TEST(OdometryFile, InterpolatesPoseAndGrowsCovariance) {
  OdometryConfig config;
  config.file_sigma2_a_m2 = 0.04;
  config.file_sigma2_b_m2_per_m = 0.01;
  config.file_rot_sigma2_a_rad2 = 1e-4;
  config.file_rot_sigma2_b_rad2_per_m = 1e-5;
  FileOdometry odometry(config, line());
  const auto out = at(odometry, 12 * kS + kS / 4);  // 2.25 s in: x = 4.5 m
  EXPECT_EQ(out.pose.status, OdometryStatus::kTracking);
  EXPECT_NEAR(out.pose.T_w_b.translation().x(), 4.5, 1e-12);
  const double yaw = Eigen::AngleAxisd(out.pose.T_w_b.rotation()).angle();
  EXPECT_NEAR(yaw, 0.225, 1e-9);
  EXPECT_NEAR(out.pose.cov(0, 0), 0.04 + 0.01 * 4.5, 1e-12);
  EXPECT_NEAR(out.pose.cov(2, 2), 0.04 + 0.01 * 4.5, 1e-12);
  EXPECT_NEAR(out.pose.cov(3, 3), 1e-4 + 1e-5 * 4.5, 1e-15);
  EXPECT_EQ(out.pose.cov(0, 1), 0.0);
  EXPECT_TRUE(out.pose.has_velocity);
  EXPECT_NEAR(out.pose.v_w_mps.x(), 2.0, 1e-12);
  EXPECT_NEAR(odometry.distance_at(20 * kS), 20.0, 1e-12);
  const auto later = at(odometry, 19 * kS);
  EXPECT_GT(later.pose.cov(0, 0), out.pose.cov(0, 0));
}

TEST(OdometryFile, StepCovarianceIsTheModelsGrowthSinceThePreviousPose) {
  OdometryConfig config;
  config.file_sigma2_b_m2_per_m = 0.01;
  config.file_rot_sigma2_b_rad2_per_m = 1e-5;
  config.file_max_gap_s = 0.5;
  auto poses = line();
  poses.erase(poses.begin() + 3, poses.begin() + 8);  // no pose between 12 s and 18 s: lost in between
  FileOdometry odometry(config, poses);
  EXPECT_FALSE(at(odometry, 10 * kS).step_cov.has_value()) << "the first pose has no step";
  const auto second = at(odometry, 11 * kS);
  ASSERT_TRUE(second.step_cov.has_value());
  const double step_m = odometry.distance_at(11 * kS) - odometry.distance_at(10 * kS);
  EXPECT_NEAR((*second.step_cov)(0, 0), 0.01 * step_m, 1e-12);
  EXPECT_NEAR((*second.step_cov)(4, 4), 1e-5 * step_m, 1e-15);
  EXPECT_EQ((*second.step_cov)(0, 3), 0.0);
  EXPECT_EQ(at(odometry, 15 * kS).pose.status, OdometryStatus::kLost);
  EXPECT_FALSE(at(odometry, 18 * kS).step_cov.has_value()) << "no step from a lost pose";
  EXPECT_TRUE(at(odometry, 19 * kS).step_cov.has_value());
}

TEST(OdometryFile, ExactPosesAndEnds) {
  FileOdometry odometry(OdometryConfig{}, line());
  EXPECT_EQ(at(odometry, 10 * kS).pose.status, OdometryStatus::kTracking);
  EXPECT_EQ(at(odometry, 20 * kS).pose.status, OdometryStatus::kTracking);
  EXPECT_NEAR(at(odometry, 20 * kS).pose.T_w_b.translation().x(), 20.0, 1e-12);
  const auto before = at(odometry, 9 * kS);
  EXPECT_EQ(before.pose.status, OdometryStatus::kLost);
  EXPECT_FALSE(before.reason.empty());
  EXPECT_EQ(at(odometry, 21 * kS).pose.status, OdometryStatus::kLost);
}

TEST(OdometryFile, LostInsideALargeGap) {
  auto poses = line();
  poses.erase(poses.begin() + 3, poses.begin() + 8);  // no pose between 12 s and 18 s
  OdometryConfig config;
  config.file_max_gap_s = 0.5;
  FileOdometry odometry(config, poses);
  EXPECT_EQ(at(odometry, 15 * kS).pose.status, OdometryStatus::kLost);
  EXPECT_EQ(at(odometry, 12 * kS + kS / 10).pose.status, OdometryStatus::kTracking);
  EXPECT_THROW(FileOdometry(config, {}), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
