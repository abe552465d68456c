// Trajectory accuracy: absolute trajectory error (ATE) after alignment, and drift per 100 m.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/enum_names.hpp"
#include "core/geometry.hpp"
#include "core/types.hpp"

namespace loopgate {

// How an estimated trajectory is aligned to the ground truth before the error is taken:
// se3: rotation + translation minimising the squared error (Umeyama, no scale);
// posyaw: translation + rotation about the gravity axis only (VIO: roll and pitch are observable);
// none: compared as given.
enum class AteAlignment { kSe3, kPosyaw, kNone };
inline constexpr EnumName<AteAlignment> kAteAlignmentNames[] = {
    {AteAlignment::kSe3, "se3"}, {AteAlignment::kPosyaw, "posyaw"}, {AteAlignment::kNone, "none"}};
constexpr std::span<const EnumName<AteAlignment>> enum_names(AteAlignment) {
  return kAteAlignmentNames;
}

struct AteConfig {
  AteAlignment alignment = AteAlignment::kSe3;
  WorldAxis up_axis = WorldAxis::kZ;    // gravity axis for posyaw: x, y (KITTI camera frame) or z (EuRoC)
  std::int64_t max_dt_ns = 10'000'000;  // timestamp association tolerance (associate_by_time)

  // The keys, in order, for loading, printing and the JSON echo (Self is AteConfig or const AteConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("alignment", self.alignment);
    v("up_axis", self.up_axis);
    v("max_dt_ns", self.max_dt_ns);
  }
  void validate() const;                                       // throws ConfigError for a negative max_dt_ns
  Eigen::Vector3d up() const { return axis_vector(up_axis); }  // unit vector of up_axis
};

struct AteResult {
  std::size_t count = 0;
  double rmse_m = 0.0;
  double mean_m = 0.0;
  double max_m = 0.0;
  double path_length_m = 0.0;   // of the ground truth
  double final_error_m = 0.0;   // after alignment
  double drift_per_100m = 0.0;  // final_error_m / path_length_m * 100 (metres per 100 m, i.e. %)
  Eigen::Isometry3d T_gt_est = Eigen::Isometry3d::Identity();  // applied to the estimate
};

// T minimising sum |p_gt - T p_est|^2 over rotations and translations (Umeyama 1991, no scale).
// Needs >= 3 non-collinear pairs for a unique rotation; throws std::invalid_argument on size mismatch
// or fewer than 2 pairs (1 pair gives the translation only).
Eigen::Isometry3d align_se3(const std::vector<Eigen::Vector3d>& p_est,
                            const std::vector<Eigen::Vector3d>& p_gt);
// Same with the rotation restricted to a yaw about `up` (unit vector), closed form.
Eigen::Isometry3d align_position_yaw(const std::vector<Eigen::Vector3d>& p_est,
                                     const std::vector<Eigen::Vector3d>& p_gt,
                                     const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

// ATE of positions paired by index (p_est[k] with p_gt[k]), aligned per config. Drift per 100 m is
// the end-point error after that alignment divided by the ground-truth path length.
AteResult compute_ate(const std::vector<Eigen::Vector3d>& p_est, const std::vector<Eigen::Vector3d>& p_gt,
                      const AteConfig& config = {});

// Pairs (estimate index, ground-truth index) with the nearest ground-truth time within max_dt_ns.
// Both inputs must be sorted by time.
std::vector<std::pair<std::size_t, std::size_t>> associate_by_time(
    const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& ground_truth,
    std::int64_t max_dt_ns);

}  // namespace loopgate
