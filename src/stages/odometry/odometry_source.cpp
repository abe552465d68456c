#include "stages/odometry/odometry_source.hpp"

#include <string>

#include "core/validate.hpp"

namespace loopgate {

namespace {
// Sigmas and variances: >= 0 and finite, at most `hi` (beyond it the gate would pass every frame).
void require_non_negative(const std::string& key, double value, double hi = 1e3) {
  require_in("odometry." + key, value, 0.0, hi);
}
}  // namespace

void OdometryConfig::validate() const {
  require_non_negative("drift_position_sigma_m_per_sqrt_m", drift_position_sigma_m_per_sqrt_m);
  require_non_negative("drift_heading_sigma_rad_per_sqrt_m", drift_heading_sigma_rad_per_sqrt_m);
  require_non_negative("drift_scale_sigma_per_sqrt_m", drift_scale_sigma_per_sqrt_m);
  require_non_negative("initial_sigma_m", initial_sigma_m);
  require_non_negative("initial_sigma_rad", initial_sigma_rad);
  require_non_negative("file_sigma2_a_m2", file_sigma2_a_m2);
  require_non_negative("file_sigma2_b_m2_per_m", file_sigma2_b_m2_per_m);
  require_non_negative("file_rot_sigma2_a_rad2", file_rot_sigma2_a_rad2);
  require_non_negative("file_rot_sigma2_b_rad2_per_m", file_rot_sigma2_b_rad2_per_m);
  require(file_max_gap_s > 0 && file_max_gap_s <= 3600, "odometry.file_max_gap_s", "in (0, 3600] s",
          std::to_string(file_max_gap_s));
  if (source == OdometrySourceKind::kFile)
    require(!file.empty(), "odometry.file", "a trajectory path (TUM, KITTI or EuRoC) when source is file",
            "''");
}

}  // namespace loopgate
