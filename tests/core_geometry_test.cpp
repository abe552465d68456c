// The geometry helpers of core/geometry.hpp: SO(3) maps, pose interpolation, planes and world axes, and
// their exact outputs on fixed inputs (the simulator's renders and the filter depend on these bits).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "core/geometry.hpp"
#include "pose_test_support.hpp"

namespace loopgate {
namespace {

using testing::make_pose;
using testing::pose_difference;

TEST(CoreGeometry, SkewIsTheCrossProduct) {
  const Eigen::Vector3d w(0.3, -1.2, 0.7);
  const Eigen::Vector3d v(-2.0, 0.5, 4.0);
  EXPECT_LT((skew(w) * v - w.cross(v)).norm(), 1e-15);
  EXPECT_EQ(skew(w).transpose(), -skew(w));
}

TEST(CoreGeometry, So3ExpLogRoundTrip) {
  const Eigen::Vector3d phi(0.3, -1.2, 0.7);
  EXPECT_LT((so3_log(so3_exp(phi)) - phi).norm(), 1e-12);
  EXPECT_LT(so3_log(so3_exp(Eigen::Vector3d(1e-12, 0, 0))).norm(), 1e-11);
  const Eigen::Vector3d near_pi(0.0, 0.0, std::numbers::pi - 1e-6);
  EXPECT_NEAR(so3_log(so3_exp(near_pi)).z(), near_pi.z(), 1e-9);
  // Beyond pi the logarithm returns the equivalent rotation with the angle in [0, pi].
  const Eigen::Vector3d beyond_pi(0.0, 0.0, std::numbers::pi + 0.5);
  const Eigen::Vector3d log = so3_log(so3_exp(beyond_pi));
  EXPECT_LE(log.norm(), std::numbers::pi);
  EXPECT_LT(pose_difference(Eigen::Isometry3d(so3_exp(log)), Eigen::Isometry3d(so3_exp(beyond_pi))), 1e-12);
}

TEST(CoreGeometry, So3ExpQuatAgreesWithTheMatrixExp) {
  for (const Eigen::Vector3d& phi : {Eigen::Vector3d(0.3, -1.2, 0.7), Eigen::Vector3d(1e-13, -2e-13, 0.0),
                                     Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(2.5, 0.1, -0.4)}) {
    const Eigen::Quaterniond q = so3_exp_quat(phi);
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    EXPECT_LT((q.toRotationMatrix() - so3_exp(phi)).cwiseAbs().maxCoeff(), 1e-15) << phi.transpose();
  }
}

TEST(CoreGeometry, So3RightJacobianMatchesFiniteDifferences) {
  // Exp(phi + d) ~ Exp(phi) Exp(Jr(phi) d) for small d.
  for (const Eigen::Vector3d& phi : {Eigen::Vector3d(0.3, -1.2, 0.7), Eigen::Vector3d(1e-8, 2e-8, 0.0)}) {
    const Eigen::Matrix3d Jr = so3_right_jacobian(phi);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = 1e-6 * Eigen::Vector3d::Unit(k);
      const Eigen::Matrix3d lhs = so3_exp(phi + d);
      const Eigen::Matrix3d rhs = so3_exp(phi) * so3_exp(Jr * d);
      EXPECT_LT((lhs - rhs).cwiseAbs().maxCoeff(), 1e-11) << "phi " << phi.transpose() << " axis " << k;
    }
  }
}

TEST(CoreGeometry, InterpolatePose) {
  const StampedPose a{1000, make_pose(0.0, 0.0, 0.0, Eigen::Vector3d(0, 0, 0))};
  const StampedPose b{2000, make_pose(1.0, 0.0, 0.0, Eigen::Vector3d(2, 4, -6))};
  const Eigen::Isometry3d mid = interpolate_pose(a, b, 1250);
  EXPECT_LT((mid.translation() - Eigen::Vector3d(0.5, 1.0, -1.5)).norm(), 1e-12);
  EXPECT_LT(pose_difference(mid, make_pose(0.25, 0, 0, mid.translation())), 1e-12);
  EXPECT_LT(pose_difference(interpolate_pose(a, b, 1000), a.T_w_b), 1e-15);
  EXPECT_LT(pose_difference(interpolate_pose(a, b, 2000), b.T_w_b), 1e-12);
  // Two poses at the same time: the first one, exactly.
  const StampedPose same{1000, b.T_w_b};
  EXPECT_EQ(interpolate_pose(a, same, 1000).matrix(), a.T_w_b.matrix());
}

TEST(CoreGeometry, PlaneNormal) {
  std::vector<Eigen::Vector3d> positions;
  for (int k = 0; k < 100; ++k) {
    const double theta = k / 50.0;
    positions.emplace_back(50.0 * std::sin(theta), 50.0 * (1.0 - std::cos(theta)), 1.5);
  }
  const Eigen::Vector3d n = plane_normal(positions);
  EXPECT_NEAR(n.z(), 1.0, 1e-9);
  // KITTI camera frames: the ground plane is x-z, the normal is y.
  for (auto& p : positions) p = Eigen::Vector3d(p.x(), 0.01 * std::sin(p.x()), p.y());
  EXPECT_NEAR(std::abs(plane_normal(positions).y()), 1.0, 1e-3);
  EXPECT_GT(plane_normal(positions).y(), 0.0);  // the largest component is made positive
  positions.resize(2);
  EXPECT_THROW(plane_normal(positions), std::invalid_argument);
}

TEST(CoreGeometry, PlanesAndAxes) {
  const Eigen::Vector3d p(1.5, -2.0, 3.25);
  EXPECT_EQ(project_to_plane(p, CoordinatePlane::kXz), Eigen::Vector3d(1.5, 0.0, 3.25));
  EXPECT_EQ(project_to_plane(p, CoordinatePlane::kXy), Eigen::Vector3d(1.5, -2.0, 0.0));
  EXPECT_EQ(project_to_plane(p, CoordinatePlane::kXyz), p);
  EXPECT_EQ(horizontal_part(p, Eigen::Vector3d::UnitZ()), Eigen::Vector3d(1.5, -2.0, 0.0));
  EXPECT_EQ(horizontal_part(p, -Eigen::Vector3d::UnitY()), Eigen::Vector3d(1.5, 0.0, 3.25));

  EXPECT_EQ(axis_vector("x"), Eigen::Vector3d::UnitX());
  EXPECT_EQ(axis_vector("-y"), -Eigen::Vector3d::UnitY());
  EXPECT_EQ(axis_vector("z"), Eigen::Vector3d::UnitZ());
  EXPECT_THROW(axis_vector("w"), std::invalid_argument);
  EXPECT_THROW(axis_vector(""), std::invalid_argument);
  EXPECT_THROW(axis_vector("-"), std::invalid_argument);

  EXPECT_EQ(dominant_axis(Eigen::Vector3d(0.1, -9.8, 0.3)), 1);
  EXPECT_EQ(dominant_axis(Eigen::Vector3d(2.0, -2.0, 2.0)), 0);  // the first one on ties
  EXPECT_EQ(nearest_signed_axis(Eigen::Vector3d(0.1, -9.8, 0.3)), -Eigen::Vector3d::UnitY());
  EXPECT_EQ(nearest_signed_axis(Eigen::Vector3d(0.2, 0.1, 9.8)), Eigen::Vector3d::UnitZ());
  EXPECT_EQ(enum_name(static_cast<WorldAxis>(dominant_axis(Eigen::Vector3d(0.1, -9.8, 0.3)))), "y");
  EXPECT_EQ(axis_vector(WorldAxis::kX), Eigen::Vector3d::UnitX());
  EXPECT_EQ(axis_vector(WorldAxis::kZ), Eigen::Vector3d::UnitZ());
  EXPECT_EQ(project_to_plane(p, CoordinatePlane::kYz), Eigen::Vector3d(0.0, -2.0, 3.25));
}

// The exact bits of each helper on fixed inputs, as produced by the copies these helpers replaced
// (io's interpolate_pose, the simulator's so3_exp / so3_log, the filter's so3 helpers, the drift source's
// plane_normal). A change here changes simulator renders or filter outputs: make it knowingly.
TEST(CoreGeometry, ArithmeticIsPinned) {
  const Eigen::Vector3d phi(0.3, -1.2, 0.7);
  const Eigen::Matrix3d R = so3_exp(phi);
  EXPECT_EQ(R(0, 1), -0x1.47027636485ebp-1);
  EXPECT_EQ(R(2, 0), 0x1.d8c3c8e1299b4p-1);
  const Eigen::Vector3d log = so3_log(make_pose(0.4, -0.3, 2.9, Eigen::Vector3d::Zero()).linear());
  EXPECT_EQ(log.x(), 0x1.70145fcc1ade9p+1);
  EXPECT_EQ(log.z(), 0x1.01c9f935dbd17p-1);
  const Eigen::Quaterniond q = so3_exp_quat(phi);
  EXPECT_EQ(q.w(), 0x1.8411dc98a56e8p-1);
  EXPECT_EQ(q.y(), -0x1.19fd339e7990fp-1);
  EXPECT_EQ(so3_right_jacobian(phi)(1, 2), -0x1.1304334d25cp-13);

  const StampedPose a{1'000'000, make_pose(0.3, 0.1, -0.2, Eigen::Vector3d(1.0, 2.0, 3.0))};
  const StampedPose b{1'050'000, make_pose(0.35, 0.12, -0.17, Eigen::Vector3d(1.3, 2.1, 2.95))};
  const Eigen::Isometry3d T = interpolate_pose(a, b, 1'017'000);
  EXPECT_EQ(T(0, 0), 0x1.e3b8c213036c7p-1);
  EXPECT_EQ(T(2, 1), -0x1.8069e3950bb6dp-3);
  EXPECT_EQ(T(1, 3), 0x1.045a1cac08312p+1);

  std::vector<Eigen::Vector3d> positions;
  for (int k = 0; k < 20; ++k)
    positions.emplace_back(std::cos(0.3 * k), 0.05 * std::sin(k), std::sin(0.3 * k));
  const Eigen::Vector3d n = plane_normal(positions);
  EXPECT_EQ(n.x(), -0x1.632b32bf7fad1p-10);
  EXPECT_EQ(n.y(), 0x1.ffff6c9521576p-1);
}

}  // namespace
}  // namespace loopgate
