// Pinhole camera with optional distortion (none, radtan k1 k2 p1 p2, equidistant k1..k4), EuRoC/Kalibr
// conventions. Camera frame: x right, y down, z forward. Pixel centres are at integer coordinates.
#pragma once

#include <Eigen/Core>

#include "core/types.hpp"

namespace loopgate {

class CameraModel {
 public:
  // Throws ConfigError when the coefficient count does not match the distortion model or the
  // focal lengths are not positive.
  explicit CameraModel(const CameraCalibration& calibration);

  const CameraCalibration& calibration() const { return calibration_; }

  // Projects a point in the camera frame to pixels (distortion applied); false if z <= 1e-9.
  bool project(const Eigen::Vector3d& p_c, Eigen::Vector2d* uv_px) const;
  // Undistorted normalised image coordinates -> distorted normalised coordinates.
  Eigen::Vector2d distort_normalized(const Eigen::Vector2d& xy) const;
  // Pixel -> undistorted normalised coordinates (iterative inversion of the distortion).
  Eigen::Vector2d undistort_normalized(const Eigen::Vector2d& uv_px) const;
  // Pixel -> unit bearing in the camera frame.
  Eigen::Vector3d unproject_ray(const Eigen::Vector2d& uv_px) const;

 private:
  CameraCalibration calibration_;
};

}  // namespace loopgate
