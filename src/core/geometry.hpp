// Small geometry helpers, each defined once for every module: SO(3) maps, pose interpolation, best-fit
// planes and world axes. Simulator renders, filter outputs and evaluation figures depend on their exact
// arithmetic (the build uses -ffp-contract=off so that it does not change with the optimiser): change an
// expression here only knowingly, and check `loopgate simulate` output stays byte-identical.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <span>
#include <string_view>
#include <vector>

#include "core/enum_names.hpp"
#include "core/types.hpp"

namespace loopgate {

// ---- SO(3): rotation vectors in radians ----
// (The filter calls skew, so3_exp_quat and so3_right_jacobian in its inner loops: they stay inline.)

// [w]x, so that skew(w) * v == w.cross(v).
inline Eigen::Matrix3d skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  return m;
}

// Exponential map as a rotation matrix: I + [phi]x below 1e-10 rad, else the angle-axis rotation.
Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi_rad);

// Exponential map as a unit quaternion (the filter's state updates): (1, phi/2) normalised below
// 1e-12 rad, else the angle-axis rotation.
inline Eigen::Quaterniond so3_exp_quat(const Eigen::Vector3d& phi_rad) {
  const double angle = phi_rad.norm();
  if (angle < 1e-12) {
    Eigen::Quaterniond q(1.0, 0.5 * phi_rad.x(), 0.5 * phi_rad.y(), 0.5 * phi_rad.z());
    return q.normalized();
  }
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, phi_rad / angle));
}

// Logarithm map: the rotation vector of R, angle in [0, pi].
Eigen::Vector3d so3_log(const Eigen::Matrix3d& R);

// Right Jacobian of SO(3) at phi (first-order form below 1e-6 rad).
inline Eigen::Matrix3d so3_right_jacobian(const Eigen::Vector3d& phi_rad) {
  const double angle = phi_rad.norm();
  const Eigen::Matrix3d K = skew(phi_rad);
  if (angle < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * K;
  const double a2 = angle * angle;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(angle)) / a2 * K +
         (angle - std::sin(angle)) / (a2 * angle) * K * K;
}

// ---- Poses ----

// The pose at t_ns between two stamped poses: position linear, rotation slerp (normalised), with
// alpha = (t - t_a) / (t_b - t_a); a itself when both have the same time. No clamping: t_ns outside
// [t_a, t_b] extrapolates.
Eigen::Isometry3d interpolate_pose(const StampedPose& a, const StampedPose& b, Timestamp t_ns);

// ---- Planes and world axes ----

// Normal of the best-fit plane of `positions` (smallest principal axis of their scatter), sign chosen so
// that its largest component is positive. Throws std::invalid_argument with fewer than 3 positions.
Eigen::Vector3d plane_normal(const std::vector<Eigen::Vector3d>& positions);

// A coordinate plane of the world, or the whole space (xyz).
enum class CoordinatePlane { kXz, kXy, kYz, kXyz };
inline constexpr EnumName<CoordinatePlane> kCoordinatePlaneNames[] = {{CoordinatePlane::kXz, "xz"},
                                                                      {CoordinatePlane::kXy, "xy"},
                                                                      {CoordinatePlane::kYz, "yz"},
                                                                      {CoordinatePlane::kXyz, "xyz"}};
constexpr std::span<const EnumName<CoordinatePlane>> enum_names(CoordinatePlane) {
  return kCoordinatePlaneNames;
}

// p projected onto a coordinate plane: xz zeroes y (KITTI camera-frame ground plane), xy zeroes z, yz zeroes
// x; xyz returns p.
Eigen::Vector3d project_to_plane(const Eigen::Vector3d& p, CoordinatePlane plane);

// v without its component along the unit vector up_w: its projection onto the horizontal plane.
inline Eigen::Vector3d horizontal_part(const Eigen::Vector3d& v, const Eigen::Vector3d& up_w) {
  return v - v.dot(up_w) * up_w;
}

// Unit vector of a world axis name: "x", "y" or "z", optionally preceded by '-'. Throws
// std::invalid_argument for any other name.
Eigen::Vector3d axis_vector(std::string_view name);

// A world axis, in the order of dominant_axis()'s indices.
enum class WorldAxis { kX, kY, kZ };
inline constexpr EnumName<WorldAxis> kWorldAxisNames[] = {
    {WorldAxis::kX, "x"}, {WorldAxis::kY, "y"}, {WorldAxis::kZ, "z"}};
constexpr std::span<const EnumName<WorldAxis>> enum_names(WorldAxis) {
  return kWorldAxisNames;
}
Eigen::Vector3d axis_vector(WorldAxis axis);

// Index (0 = x, 1 = y, 2 = z) of the world axis nearest the direction of v: its largest |component|,
// the first one on ties.
int dominant_axis(const Eigen::Vector3d& v);

// The signed world axis nearest the direction of v: +-unit vector of dominant_axis(v), '-' when that
// component is not positive.
Eigen::Vector3d nearest_signed_axis(const Eigen::Vector3d& v);

}  // namespace loopgate
