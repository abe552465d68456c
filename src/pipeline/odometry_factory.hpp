// Odometry sources built from a Dataset (docs/ekf.md). The sources of
// src/stages/odometry take plain data (a trajectory, ground-truth states, calibrations, an axis); this is
// the composition root's half: it reads those out of the dataset and the trajectory file, resolves
// `odometry.source: auto` and says what is missing.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>

#include "pipeline/pipeline_config.hpp"
#include "stages/ekf/ekf_config.hpp"
#include "stages/odometry/odometry_source.hpp"

namespace loopgate {

class Dataset;

// Builds the configured source. `dataset` supplies ground truth (drift: required, and the heading axis
// when "auto"; ekf: the initial state with ekf.init_mode ground_truth) and the camera and IMU calibration
// (ekf); `ekf` configures the ekf source. Throws ConfigError / DataError naming what is missing.
std::unique_ptr<OdometrySource> make_odometry_source(const OdometryConfig& config, const EkfConfig& ekf,
                                                     const Dataset& dataset);
// Same with the default EkfConfig.
std::unique_ptr<OdometrySource> make_odometry_source(const OdometryConfig& config, const Dataset& dataset);

// The world axis (+-x, +-y or +-z) nearest the up direction: the mean specific force of the IMU over the
// sequence, rotated into the world by the ground truth. nullopt without IMU or ground truth.
std::optional<Eigen::Vector3d> world_up_axis_from_imu(const Dataset& dataset);

// What the configured source needs from `dataset` and its inputs, naming the file (odometry.file, the
// dataset) and the times they cover: the run's checks say it when no frame got a pose.
std::string odometry_expectation(const OdometryConfig& config, const EkfConfig& ekf, const Dataset& dataset);

// ConfigError when the run needs poses (run.mode gated: the pose gate; run.mode odometry; verify.enabled) and
// the source resolves to none for `dataset`, saying why and what to use instead.
void require_poses_if_needed(const PipelineConfig& config, const Dataset& dataset);

// The source `config.source` resolves to for `dataset`: auto becomes ekf, drift or none (see
// stages/odometry/odometry_source.hpp).
OdometrySourceKind resolve_odometry_source(const OdometryConfig& config, const EkfConfig& ekf,
                                           const Dataset& dataset);

}  // namespace loopgate
