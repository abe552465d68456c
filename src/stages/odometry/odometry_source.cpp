#include "stages/odometry/odometry_source.hpp"

#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "stages/odometry/drift_odometry.hpp"
#include "stages/odometry/file_odometry.hpp"

namespace loopgate {

namespace {
void require_non_negative(const std::string& key, double value) {
  require(value >= 0, "odometry." + key, ">= 0", std::to_string(value));
}
}  // namespace

void OdometryConfig::validate() const {
  require_one_of("odometry.source", source, {"drift", "file"});
  require_one_of("odometry.heading_axis", heading_axis, {"auto", "x", "y", "z"});
  require_non_negative("drift_position_sigma_m_per_sqrt_m", drift_position_sigma_m_per_sqrt_m);
  require_non_negative("drift_heading_sigma_rad_per_sqrt_m", drift_heading_sigma_rad_per_sqrt_m);
  require_non_negative("drift_scale_sigma_per_sqrt_m", drift_scale_sigma_per_sqrt_m);
  require_non_negative("initial_sigma_m", initial_sigma_m);
  require_non_negative("initial_sigma_rad", initial_sigma_rad);
  require_non_negative("file_sigma2_a_m2", file_sigma2_a_m2);
  require_non_negative("file_sigma2_b_m2_per_m", file_sigma2_b_m2_per_m);
  require_non_negative("file_rot_sigma2_a_rad2", file_rot_sigma2_a_rad2);
  require_non_negative("file_rot_sigma2_b_rad2_per_m", file_rot_sigma2_b_rad2_per_m);
  require(file_max_gap_s > 0, "odometry.file_max_gap_s", "> 0", std::to_string(file_max_gap_s));
  if (source == "file")
    require(!file.empty(), "odometry.file", "a TUM trajectory path when source is file", "''");
}

std::unique_ptr<OdometrySource> make_odometry_source(const OdometryConfig& config, const Dataset& dataset) {
  config.validate();
  if (config.source == "file") {
    auto poses = read_tum(config.file);
    if (poses.empty()) throw DataError(config.file, "no poses in the trajectory file");
    spdlog::info("odometry: file source, {} poses from {}", poses.size(), config.file);
    return std::make_unique<FileOdometry>(config, std::move(poses));
  }
  if (!dataset.has_ground_truth()) {
    throw ConfigError("odometry.source: 'drift' needs ground truth, and dataset " + dataset.root().string() +
                      " has none (use source: file)");
  }
  Eigen::Vector3d axis_w = Eigen::Vector3d::UnitZ();
  if (config.heading_axis == "x") axis_w = Eigen::Vector3d::UnitX();
  if (config.heading_axis == "y") axis_w = Eigen::Vector3d::UnitY();
  if (config.heading_axis == "auto") {
    std::vector<Eigen::Vector3d> positions;
    for (std::size_t i = 0; i < dataset.frame_count(); ++i) {
      if (auto T_w_b = dataset.ground_truth_T_w_b(i)) positions.push_back(T_w_b->translation());
    }
    if (positions.size() >= 3) axis_w = plane_normal(positions);
  }
  spdlog::info("odometry: drift source, seed {}, heading axis [{:.3f} {:.3f} {:.3f}]", config.seed,
               axis_w.x(), axis_w.y(), axis_w.z());
  return std::make_unique<DriftOdometry>(config, axis_w);
}

}  // namespace loopgate
