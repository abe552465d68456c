#include "core/geometry.hpp"

#include <Eigen/Eigenvalues>
#include <numbers>
#include <stdexcept>
#include <string>

namespace loopgate {

Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi_rad) {
  constexpr double kSmallAngleRad = 1e-10;
  const double angle = phi_rad.norm();
  if (angle < kSmallAngleRad) return Eigen::Matrix3d::Identity() + skew(phi_rad);
  return Eigen::AngleAxisd(angle, phi_rad / angle).toRotationMatrix();
}

Eigen::Vector3d so3_log(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(Eigen::Quaterniond(R).normalized());
  double angle = aa.angle();
  Eigen::Vector3d axis = aa.axis();
  if (angle > std::numbers::pi) {  // keep the angle in [0, pi]
    angle = 2.0 * std::numbers::pi - angle;
    axis = -axis;
  }
  return angle * axis;
}

Eigen::Isometry3d interpolate_pose(const StampedPose& a, const StampedPose& b, Timestamp t_ns) {
  if (b.t_ns == a.t_ns) return a.T_w_b;
  const double alpha = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  const Eigen::Quaterniond qa(a.T_w_b.linear());
  const Eigen::Quaterniond qb(b.T_w_b.linear());
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = qa.slerp(alpha, qb).normalized().toRotationMatrix();
  T.translation() = (1.0 - alpha) * a.T_w_b.translation() + alpha * b.T_w_b.translation();
  return T;
}

Eigen::Vector3d plane_normal(const std::vector<Eigen::Vector3d>& positions) {
  if (positions.size() < 3) throw std::invalid_argument("plane_normal: fewer than 3 positions");
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : positions) mean += p;
  mean /= static_cast<double>(positions.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& p : positions) scatter += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  Eigen::Vector3d normal = solver.eigenvectors().col(0);  // smallest eigenvalue first
  Eigen::Index largest = 0;
  normal.cwiseAbs().maxCoeff(&largest);
  if (normal[largest] < 0) normal = -normal;
  return normal;
}

Eigen::Vector3d project_to_plane(const Eigen::Vector3d& p, CoordinatePlane plane) {
  switch (plane) {
    case CoordinatePlane::kXz: return {p.x(), 0.0, p.z()};
    case CoordinatePlane::kXy: return {p.x(), p.y(), 0.0};
    case CoordinatePlane::kYz: return {0.0, p.y(), p.z()};
    case CoordinatePlane::kXyz: break;
  }
  return p;
}

Eigen::Vector3d axis_vector(std::string_view name) {
  const bool negative = !name.empty() && name.front() == '-';
  const std::string_view axis = negative ? name.substr(1) : name;
  const double sign = negative ? -1.0 : 1.0;
  if (axis == "x") return sign * Eigen::Vector3d::UnitX();
  if (axis == "y") return sign * Eigen::Vector3d::UnitY();
  if (axis == "z") return sign * Eigen::Vector3d::UnitZ();
  throw std::invalid_argument("axis_vector: '" + std::string(name) + "' is not one of x, y, z, -x, -y, -z");
}

Eigen::Vector3d axis_vector(WorldAxis axis) {
  return Eigen::Vector3d::Unit(static_cast<Eigen::Index>(axis));
}

int dominant_axis(const Eigen::Vector3d& v) {
  Eigen::Index axis = 2;
  v.cwiseAbs().maxCoeff(&axis);
  return static_cast<int>(axis);
}

Eigen::Vector3d nearest_signed_axis(const Eigen::Vector3d& v) {
  const int axis = dominant_axis(v);
  Eigen::Vector3d unit = Eigen::Vector3d::Zero();
  unit[axis] = v[axis] > 0.0 ? 1.0 : -1.0;
  return unit;
}

}  // namespace loopgate
