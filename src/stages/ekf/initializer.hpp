// What an initialiser of the ekf odometry hands the filter, and the interface of the initialisers that start
// it from the sensors alone: a static one (the platform is still, vibration allowed) and a dynamic one
// (visual-inertial alignment over a short window of images while moving). Both take the same per-image input
// as VioEkf::process and say, until they succeed, why not yet, with the numbers behind it.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "stages/ekf/imu_propagator.hpp"
#include "stages/ekf/msckf.hpp"

namespace loopgate {

enum class InitMethod { kStatic, kDynamic, kGroundTruth };

// The state the filter starts from, at the time of the image where the initialiser succeeded. The world frame
// of the static and dynamic initialisers has +z up (against gravity) and the yaw of the IMU at that time set
// to zero; the position is zero. The accelerometer bias is left to the filter (zero, with its prior sigma)
// except for ground truth.
struct InitialState {
  InitMethod method = InitMethod::kStatic;
  std::size_t frame = 0;  // index of the image (0-based, images given to the initialiser) where it succeeded
  ImuState state;         // state.t_ns is that image's time
  // Covariance of the start: attitude (world frame, 3 x 3), velocity (m/s, world), gyro bias (rad/s).
  Eigen::Matrix3d rot_cov_world = Eigen::Matrix3d::Identity() * 1e-4;
  Eigen::Matrix3d vel_cov_m2ps2 = Eigen::Matrix3d::Identity() * 1e-2;
  Eigen::Matrix3d gyro_bias_cov = Eigen::Matrix3d::Identity() * 1e-4;
  // The dynamic start's joint covariance of [attitude (body perturbation), velocity (world), gyro bias,
  // accelerometer bias], with the cross terms the alignment leaves between them (a tilt and a horizontal
  // accelerometer bias, the velocity and gravity's direction): the filter starts from it instead of the
  // blocks above, so that a correction of one moves the others as the data say. nullopt: the blocks above,
  // and the accelerometer bias from its prior.
  std::optional<Eigen::Matrix<double, 12, 12>> joint_cov;
  double scale = 1.0;     // dynamic: the metric scale found for the up-to-scale structure (1 otherwise)
  double window_s = 0.0;  // seconds of data the decision used
  std::string detail;     // the numbers behind the decision, for the log and summary.json
};

// One image's input to an initialiser: IMU samples since the previous image (as EkfFrameInput::imu) and the
// tracked features of this image (undistorted normalised coordinates, ids stable along a track).
struct InitFrame {
  Timestamp t_ns = 0;
  std::span<const ImuSample> imu;
  const std::vector<FeatureObservation>* observations = nullptr;
};

}  // namespace loopgate
