// Dynamic initialisation of the ekf odometry: visual-inertial alignment over a short window of images taken
// while moving (after VINS-Mono, Qin et al. 2018, § V "Estimator initialization", and the closed-form
// alignment of Dong-Si and Mourikis 2012). Over a sliding window of images:
//   1. structure from motion up to scale: the essential matrix between the oldest image and the image with
//      the largest rotation-compensated parallax, triangulation, then PnP of the other images and a second
//      pass of triangulation and PnP over all of them (camera poses in the oldest camera frame c0);
//   2. IMU pre-integration between consecutive images (delta R, v, p and their gyro-bias Jacobians);
//   3. gyro bias from the rotations of vision against the pre-integrated gyro (3 x 3 least squares), then
//      re-integration;
//   4. linear alignment: the velocity of every image, gravity in c0 and the metric scale; then gravity
//      refined on its sphere of radius gravity_mps2 (2-DoF tangent refinement).
// It refuses (and says why in status()) when the parallax, the IMU excitation, the scale, the gravity norm,
// the translation, the conditioning or the residual is out of bounds (EkfConfig dynamic_init_*). The
// accelerometer bias is not estimated (left to the filter).
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
  // T_i_c: camera -> IMU (the camera pose in the IMU frame).
  DynamicInitializer(const EkfConfig& config, const Eigen::Isometry3d& T_i_c);

  // One call per image, in time order. Returns the initial state at this image's time once the alignment
  // over the window succeeds (InitialState::frame counts the images given since construction or reset()).
  std::optional<InitialState> add_frame(const InitFrame& frame);

  // InitialState::scale is the metric length of the up-to-scale structure's unit, which is the distance
  // between the first and the last camera of the window: the metric translation over the window.

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
  std::deque<Frame> window_;
  std::optional<ImuSample> last_sample_;  // the latest IMU sample seen (start of the next interval)
  std::size_t frames_seen_ = 0;
  std::string status_ = "no image yet";
};

}  // namespace loopgate
