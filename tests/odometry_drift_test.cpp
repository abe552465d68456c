#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "stages/odometry/drift_odometry.hpp"

namespace loopgate {
namespace {

// A planar drive on a circle of radius 50 m in the x-y plane (z up), 1 m per frame.
Eigen::Isometry3d circle_pose(int k) {
  const double radius_m = 50.0;
  const double theta = static_cast<double>(k) / radius_m;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(radius_m * std::sin(theta), radius_m * (1.0 - std::cos(theta)), 1.5);
  T.linear() = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

// The source's outputs on `frames` frames of the circle, 10 Hz.
std::vector<OdometryOutput> run_outputs(const OdometryConfig& config, int frames) {
  DriftOdometry odometry(config, Eigen::Vector3d::UnitZ());
  std::vector<OdometryOutput> out;
  for (int k = 0; k < frames; ++k) {
    OdometryInput input;
    input.frame = static_cast<std::size_t>(k);
    input.t_ns = k * 100'000'000LL;
    input.T_w_b_true = circle_pose(k);
    out.push_back(odometry.process(input));
  }
  return out;
}

std::vector<PoseEstimate> run(const OdometryConfig& config, int frames) {
  std::vector<PoseEstimate> poses;
  for (const OdometryOutput& out : run_outputs(config, frames)) poses.push_back(out.pose);
  return poses;
}

// Drift strong enough for the Monte-Carlo tests to see every term of the model.
OdometryConfig strong_drift() {
  OdometryConfig config;
  config.drift_heading_sigma_rad_per_sqrt_m = 0.002;
  config.drift_scale_sigma_per_sqrt_m = 0.003;
  config.drift_position_sigma_m_per_sqrt_m = 0.02;
  return config;
}

TEST(OdometryDrift, DeterministicBySeed) {
  OdometryConfig config;
  const auto a = run(config, 200);
  const auto b = run(config, 200);
  config.seed = 2;
  const auto c = run(config, 200);
  ASSERT_EQ(a.size(), 200u);
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_TRUE(a[i].T_w_b.isApprox(b[i].T_w_b, 0.0));
    EXPECT_EQ(a[i].cov, b[i].cov);
  }
  EXPECT_GT((a.back().T_w_b.translation() - c.back().T_w_b.translation()).norm(), 1e-6);
  // The covariance does not depend on the seed (it follows the truth), the estimate does.
  EXPECT_TRUE(a.back().cov.isApprox(c.back().cov, 1e-12));
}

TEST(OdometryDrift, StartsAtTruthAndDrifts) {
  const auto poses = run(OdometryConfig{}, 300);
  EXPECT_TRUE(poses[0].T_w_b.isApprox(circle_pose(0), 1e-12));
  EXPECT_EQ(poses[0].status, OdometryStatus::kTracking);
  const double error_m = (poses.back().T_w_b.translation() - circle_pose(299).translation()).norm();
  EXPECT_GT(error_m, 1e-4);
  EXPECT_LT(error_m, 10.0);
}

TEST(OdometryDrift, CovarianceGrowsWithDistance) {
  const auto poses = run(OdometryConfig{}, 300);
  double previous = -1;
  for (const auto& pose : poses) {
    const double trace = pose.position_cov_m2().trace();
    EXPECT_GE(trace, previous);
    previous = trace;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> solver(pose.cov);
    EXPECT_GT(solver.eigenvalues().minCoeff(), 0.0);  // positive definite thanks to the floors
  }
  EXPECT_GT(poses.back().position_cov_m2().trace(), 10.0 * poses[1].position_cov_m2().trace());
  EXPECT_NEAR(poses[0].position_cov_m2().trace(), 3 * 0.01 * 0.01, 1e-15);
}

// The covariance matches the drift it describes: over many seeds, the mean squared position error is
// the predicted trace (within Monte-Carlo noise), and the normalised error squared averages 3.
TEST(OdometryDrift, CovarianceConsistentWithDriftMonteCarlo) {
  OdometryConfig config = strong_drift();
  constexpr int kRuns = 300;
  constexpr int kFrames = 150;
  double sum_sq_m2 = 0;
  double sum_nees = 0;
  double predicted_m2 = 0;
  for (int seed = 0; seed < kRuns; ++seed) {
    config.seed = seed;
    const auto poses = run(config, kFrames);
    const Eigen::Vector3d error = poses.back().T_w_b.translation() - circle_pose(kFrames - 1).translation();
    sum_sq_m2 += error.squaredNorm();
    const Eigen::Matrix3d P = poses.back().position_cov_m2();
    sum_nees += error.dot(P.ldlt().solve(error));
    predicted_m2 = P.trace();
  }
  const double ratio = sum_sq_m2 / kRuns / predicted_m2;
  EXPECT_GT(ratio, 0.8) << "mean squared error / predicted trace";
  EXPECT_LT(ratio, 1.25);
  EXPECT_NEAR(sum_nees / kRuns, 3.0, 0.6);
}

// The step covariance (the pose graph's odometry edges) against the spread of the estimated step
// T_prev_this over seeds: position whitened by the prediction, rotation about the heading axis by variance.
TEST(OdometryDrift, StepCovarianceConsistentWithTheStepsMonteCarlo) {
  OdometryConfig config = strong_drift();
  constexpr int kRuns = 2000;
  constexpr int kFrame = 80;
  const Eigen::Isometry3d T_step_true = circle_pose(kFrame - 1).inverse() * circle_pose(kFrame);
  Eigen::Matrix3d empirical_p = Eigen::Matrix3d::Zero();
  double empirical_yaw = 0;
  PoseCov predicted = PoseCov::Zero();
  for (int seed = 0; seed < kRuns; ++seed) {
    config.seed = seed;
    const std::vector<OdometryOutput> outputs = run_outputs(config, kFrame + 1);
    for (int k = 0; k <= kFrame; ++k) ASSERT_EQ(outputs[k].step_cov.has_value(), k > 0) << "frame " << k;
    const Eigen::Isometry3d T_step = outputs[kFrame - 1].pose.T_w_b.inverse() * outputs[kFrame].pose.T_w_b;
    const Eigen::Vector3d e_p = T_step_true.translation() - T_step.translation();
    const Eigen::Vector3d e_r = so3_log(T_step.rotation().transpose() * T_step_true.rotation());
    empirical_p += e_p * e_p.transpose() / kRuns;
    empirical_yaw += e_r.z() * e_r.z() / kRuns;
    predicted = *outputs[kFrame].step_cov;
  }
  const Eigen::Matrix3d P = predicted.topLeftCorner<3, 3>();
  const Eigen::Matrix3d L = P.llt().matrixL();
  const Eigen::Matrix3d whitened =
      L.triangularView<Eigen::Lower>().solve(L.triangularView<Eigen::Lower>().solve(empirical_p).transpose());
  EXPECT_LT((whitened - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 0.12) << whitened;
  EXPECT_NEAR(empirical_yaw / predicted(5, 5), 1.0, 0.12);
  EXPECT_NEAR(predicted(3, 3), 0.0, 1e-15);  // no roll or pitch in this model
}

TEST(OdometryDrift, LostWithoutTruthHoldsLastEstimate) {
  DriftOdometry odometry(OdometryConfig{}, Eigen::Vector3d::UnitZ());
  OdometryInput input;
  input.T_w_b_true = circle_pose(0);
  const auto first = odometry.process(input);
  input.T_w_b_true.reset();
  input.t_ns = 1;
  const auto lost = odometry.process(input);
  EXPECT_EQ(lost.pose.status, OdometryStatus::kLost);
  EXPECT_FALSE(lost.step_cov.has_value());
  input.T_w_b_true = circle_pose(1);
  EXPECT_FALSE(odometry.process(input).step_cov.has_value()) << "no step from a lost frame";
  input.T_w_b_true = circle_pose(2);
  EXPECT_TRUE(odometry.process(input).step_cov.has_value());
  EXPECT_FALSE(lost.reason.empty());
  EXPECT_TRUE(lost.pose.T_w_b.isApprox(first.pose.T_w_b, 0.0));
}

TEST(OdometryDrift, ConfigValidation) {
  OdometryConfig config;
  config.source = OdometrySourceKind::kFile;
  EXPECT_THROW(config.validate(), ConfigError);  // no file
  config.file = "traj.txt";
  EXPECT_NO_THROW(config.validate());
  config.drift_scale_sigma_per_sqrt_m = -1;
  EXPECT_THROW(config.validate(), ConfigError);
}

}  // namespace
}  // namespace loopgate
