// Pose helpers shared by the tests of geometry and trajectories (header-only: only tests that use Eigen
// include it).
#pragma once

#include <Eigen/Geometry>

namespace loopgate::testing {

// Rotation yaw (z) * pitch (y) * roll (x), translation p.
inline Eigen::Isometry3d make_pose(double yaw, double pitch, double roll, const Eigen::Vector3d& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() =
      (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  T.translation() = p;
  return T;
}

// Largest absolute difference of the two 4x4 matrices.
inline double pose_difference(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff();
}

}  // namespace loopgate::testing
