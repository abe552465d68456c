// Dynamic initialisation of the ekf odometry: visual-inertial alignment over a short window of images taken
// while moving (after VINS-Mono, Qin et al. 2018, and the closed-form linear initialisation of Dong-Si and
// Mourikis 2012). Over a sliding window of images:
//   1. structure from motion up to scale (essential matrix between the oldest image and the one with the
//      largest rotation-compensated parallax, triangulation, PnP, alternating refinement): its rotations and
//      its set of consistent tracks;
//   2. IMU pre-integration between consecutive images, with Jacobians on both biases;
//   3. the gyro bias from the rotations of vision against the pre-integrated gyro, then re-integration;
//   4. alignment with the gyro's rotations: the velocity and gravity at the first image, the accelerometer
//      bias (under its prior) and every track's position, from equations linear in all of them; gravity is
//      then held on its sphere and the equations re-weighted into reprojection errors. The metric scale
//      comes from the pre-integrated accelerometer directly.
// It refuses (and says why in status()) when the parallax, the IMU excitation, the gravity norm of the
// unconstrained solve, the reprojection residual, the certainty of the velocity (the scale) or the
// translation is out of bounds (EkfConfig dynamic_init_*).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/initializer.hpp"

namespace loopgate {

class DynamicInitializer {
 public:
  // T_i_c: camera -> IMU (the camera pose in the IMU frame); focal_px turns normalised coordinates into the
  // pixels of the parallax and residual thresholds.
  DynamicInitializer(const EkfConfig& config, const Eigen::Isometry3d& T_i_c, double focal_px);

  // One call per image, in time order. Returns the initial state at this image's time once the alignment
  // over the window succeeds (InitialState::frame counts the images given since construction or reset()).
  std::optional<InitialState> add_frame(const InitFrame& frame);

  // InitialState::scale is the metric translation of the camera between the first and the last image of the
  // window.

  // Why it has not succeeded yet, with the numbers behind it (or what succeeded).
  const std::string& status() const { return status_; }

  void reset();

 private:
  struct Frame {
    Timestamp t_ns = 0;
    std::unordered_map<std::uint64_t, Eigen::Vector2d> features;  // id -> normalised coordinates
    std::vector<ImuSample> imu;  // samples from the previous image's time (interpolated) to this one's
  };

  std::optional<InitialState> try_align();

  EkfConfig config_;
  Eigen::Isometry3d T_i_c_;
  double focal_px_ = 1.0;
  std::deque<Frame> window_;
  std::optional<ImuSample> last_sample_;  // the latest IMU sample seen (start of the next interval)
  std::size_t frames_seen_ = 0;
  std::string status_ = "no image yet";
};

}  // namespace loopgate
