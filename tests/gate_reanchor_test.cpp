// Re-anchoring a frame through a verified loop (stages/gate/reanchor.hpp): known answers for the pose and the
// covariance, the identity when the loop agrees with the odometry, and the PSD projection of a covariance
// growth that is not monotone (a filter's).
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <numbers>

#include "stages/gate/reanchor.hpp"

namespace loopgate {
namespace {

Eigen::Isometry3d pose(double x, double y, double z, double yaw_rad) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// Odometry drifted: it puts q at (10, 0, 0) heading +x, and frame i 2 m further on. The loop says q is 1 m
// ahead of the map's reference r, which is at the origin heading +y. So i is 3 m ahead of r, at (0, 3, 0)
// heading +y; the odometry's covariance growth since q turns with the correction (+90 degrees about z).
TEST(GateReanchor, KnownAnswer) {
  LoopAnchor a;
  a.T_w_q_odo = pose(10, 0, 0, 0);
  a.P_q_odo_m2 = Eigen::Vector3d(0.5, 0.5, 0.5).asDiagonal();
  a.T_w_r = pose(0, 0, 0, std::numbers::pi / 2);
  a.P_r_m2 = Eigen::Vector3d(0.01, 0.01, 0.01).asDiagonal();
  a.T_r_q = pose(1, 0, 0, 0);
  a.P_loop_r_m2 = Eigen::Vector3d(0.09, 0.04, 0.01).asDiagonal();  // in r's body frame
  const Eigen::Matrix3d P_i_m2 = Eigen::Vector3d(4.5, 1.5, 0.75).asDiagonal();
  const ReanchoredPose out = reanchor(a, pose(12, 0, 0, 0), P_i_m2);

  EXPECT_NEAR((out.T_w_i.translation() - Eigen::Vector3d(0, 3, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((out.T_w_i.linear() - pose(0, 0, 0, std::numbers::pi / 2).linear()).norm(), 0.0, 1e-12);
  // P_r + R_w_r P_loop R_w_r^T (x <-> y) + R_c (P_i - P_q) R_c^T (growth diag(4, 1, 0.25), x <-> y).
  const Eigen::Matrix3d expected_m2 =
      Eigen::Vector3d(0.01 + 0.04 + 1.0, 0.01 + 0.09 + 4.0, 0.01 + 0.01 + 0.25).asDiagonal();
  EXPECT_NEAR((out.P_m2 - expected_m2).norm(), 0.0, 1e-12) << out.P_m2;
  EXPECT_FALSE(out.growth_clamped);
}

// A loop that agrees with the odometry (r's pose and T_r_q as the odometry has them) changes no pose, and the
// covariance is r's + the loop's + the growth since q.
TEST(GateReanchor, ConsistentLoopKeepsThePose) {
  LoopAnchor a;
  a.T_w_q_odo = pose(4, -2, 1, 0.7);
  a.T_w_r = pose(3.5, -1.0, 1.2, 0.4);
  a.T_r_q = a.T_w_r.inverse() * a.T_w_q_odo;
  a.P_q_odo_m2 = 0.2 * Eigen::Matrix3d::Identity();
  a.P_r_m2 = 0.1 * Eigen::Matrix3d::Identity();
  a.P_loop_r_m2 = 0.05 * Eigen::Matrix3d::Identity();
  const Eigen::Isometry3d T_w_i = pose(9, 3, 1.5, 1.9);
  const ReanchoredPose out = reanchor(a, T_w_i, 0.5 * Eigen::Matrix3d::Identity());
  EXPECT_NEAR((out.T_w_i.matrix() - T_w_i.matrix()).norm(), 0.0, 1e-12);
  EXPECT_NEAR((out.P_m2 - 0.45 * Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-12);
}

// An EKF's covariance can shrink along an axis after q: the growth P_i - P_q then has a negative eigenvalue,
// which is set to 0, so P_i' stays PSD and at least P_r + P_loop.
TEST(GateReanchor, NonMonotoneGrowthIsProjectedOnPsd) {
  LoopAnchor a;
  a.P_q_odo_m2 = Eigen::Vector3d(1.0, 1.0, 1.0).asDiagonal();
  a.P_r_m2 = 0.1 * Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  // Growth diag(2, -0.5, 0) in a rotated basis.
  const Eigen::Matrix3d P_i_m2 =
      a.P_q_odo_m2 + R * Eigen::Vector3d(2.0, -0.5, 0.0).asDiagonal() * R.transpose();
  const ReanchoredPose out = reanchor(a, Eigen::Isometry3d::Identity(), P_i_m2);
  EXPECT_TRUE(out.growth_clamped);
  const Eigen::Matrix3d expected_m2 =
      0.1 * Eigen::Matrix3d::Identity() + R * Eigen::Vector3d(2.0, 0.0, 0.0).asDiagonal() * R.transpose();
  EXPECT_NEAR((out.P_m2 - expected_m2).norm(), 0.0, 1e-12) << out.P_m2;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(out.P_m2 - 0.1 * Eigen::Matrix3d::Identity());
  EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-12);
}

TEST(GateReanchor, PsdPartKeepsPsdMatrices) {
  bool clamped = true;
  const Eigen::Matrix3d P_m2 = Eigen::Vector3d(3.0, 0.0, 1.0).asDiagonal();
  EXPECT_EQ(psd_part(P_m2, 1e-12, clamped), P_m2);
  EXPECT_FALSE(clamped);
  EXPECT_EQ(psd_part(-P_m2, 1e-12, clamped), Eigen::Matrix3d::Zero());
  EXPECT_TRUE(clamped);
}

}  // namespace
}  // namespace loopgate
