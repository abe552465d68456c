// Small SO(3) helpers used by the filter (rotation vectors in radians).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace loopgate::so3 {

inline Eigen::Matrix3d skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  return m;
}

// Exponential map: rotation vector -> unit quaternion.
inline Eigen::Quaterniond exp_quat(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  if (angle < 1e-12) {
    Eigen::Quaterniond q(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z());
    return q.normalized();
  }
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, phi / angle));
}

inline Eigen::Matrix3d exp(const Eigen::Vector3d& phi) {
  return exp_quat(phi).toRotationMatrix();
}

// Logarithm map: rotation -> rotation vector.
inline Eigen::Vector3d log(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

// Right Jacobian of SO(3).
inline Eigen::Matrix3d right_jacobian(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  const Eigen::Matrix3d K = skew(phi);
  if (angle < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * K;
  const double a2 = angle * angle;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(angle)) / a2 * K +
         (angle - std::sin(angle)) / (a2 * angle) * K * K;
}

}  // namespace loopgate::so3
