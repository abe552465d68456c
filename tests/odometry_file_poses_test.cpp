// The file odometry keeps each pose of the trajectory as the top three rows of its matrix: the poses it gives
// are bit-equal to those of the full isometries (the last pose as read, and interpolated ones).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
#include <vector>

#include "core/geometry.hpp"
#include "stages/odometry/file_odometry.hpp"

namespace loopgate {
namespace {

constexpr Timestamp kS = 1'000'000'000;

TEST(OdometryFilePoses, PosesAreBitEqualToTheFullIsometries) {
  std::mt19937 rng(21);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<StampedPose> poses;
  for (int k = 0; k <= 20; ++k) {
    StampedPose p;
    p.t_ns = (5 + k) * kS;
    p.T_w_b.translation() = Eigen::Vector3d(3.0 * k + noise(rng), noise(rng), 0.1 * noise(rng));
    const Eigen::Quaterniond q(noise(rng), noise(rng), noise(rng), noise(rng));
    p.T_w_b.linear() = q.normalized().toRotationMatrix();
    poses.push_back(p);
  }
  FileOdometry odometry(OdometryConfig{}, poses);
  for (int k = 0; k < 20; ++k) {
    OdometryInput input;
    input.t_ns = poses[k].t_ns + kS / 3;
    const OdometryOutput out = odometry.process(input);
    const Eigen::Isometry3d expected = interpolate_pose(poses[k], poses[k + 1], input.t_ns);
    EXPECT_TRUE(out.pose.T_w_b.matrix() == expected.matrix()) << k;
  }
  OdometryInput last;
  last.t_ns = poses.back().t_ns;  // the exact last pose: the nearest end, as read
  EXPECT_TRUE(odometry.process(last).pose.T_w_b.matrix() == poses.back().T_w_b.matrix());
}

}  // namespace
}  // namespace loopgate
