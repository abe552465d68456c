#include "pipeline/odometry_factory.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <vector>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_file.hpp"
#include "stages/ekf/vio_ekf.hpp"
#include "stages/odometry/drift_odometry.hpp"
#include "stages/odometry/ekf_odometry.hpp"
#include "stages/odometry/file_odometry.hpp"

namespace loopgate {

std::optional<Eigen::Vector3d> world_up_axis_from_imu(const Dataset& dataset) {
  if (!dataset.has_imu() || !dataset.has_ground_truth()) return std::nullopt;
  const auto imu = dataset.imu_calibration();
  const Eigen::Matrix3d R_b_i = imu ? Eigen::Matrix3d(imu->T_b_i.rotation()) : Eigen::Matrix3d::Identity();
  Eigen::Vector3d sum_w = Eigen::Vector3d::Zero();
  for (const ImuSample& s : dataset.imu_samples()) {
    const auto gt = ground_truth_state_at(dataset.ground_truth(), s.t_ns);
    if (gt && s.accel_mps2.allFinite()) sum_w += gt->T_w_b.rotation() * (R_b_i * s.accel_mps2);
  }
  if (sum_w.isZero(0.0)) return std::nullopt;
  return nearest_signed_axis(sum_w);
}

OdometrySourceKind resolve_odometry_source(const OdometryConfig& config, const EkfConfig& ekf,
                                           const Dataset& dataset) {
  if (config.source != OdometrySourceKind::kAuto) return config.source;
  const bool ekf_inputs = dataset.has_images() && dataset.has_imu() && dataset.camera().has_value() &&
                          dataset.imu_calibration().has_value();
  const bool ekf_init = ekf.init_mode != EkfInitMode::kGroundTruth || dataset.has_ground_truth();
  if (ekf_inputs && ekf_init) return OdometrySourceKind::kEkf;
  return dataset.has_ground_truth() ? OdometrySourceKind::kDrift : OdometrySourceKind::kNone;
}

std::string odometry_expectation(const OdometryConfig& config, const EkfConfig& ekf, const Dataset& dataset) {
  const OdometrySourceKind source = resolve_odometry_source(config, ekf, dataset);
  const auto seconds = [](Timestamp t) { return fmt::format("{:.3f}", ns_to_s(t)); };
  const std::string frames =
      dataset.frame_count() == 0
          ? std::string("no frames")
          : fmt::format("{} frames at t = {} .. {} s", dataset.frame_count(), seconds(dataset.frame_t_ns(0)),
                        seconds(dataset.frame_t_ns(dataset.frame_count() - 1)));
  if (source == OdometrySourceKind::kFile) {
    std::string covers = "no readable poses";
    try {
      const auto poses = read_trajectory_file(config.file, config.file_format, dataset.source_times()).poses;
      if (!poses.empty())
        covers = "poses at t = " + seconds(poses.front().t_ns) + " .. " + seconds(poses.back().t_ns) + " s";
    } catch (const std::exception& e) {
      covers = e.what();
    }
    return fmt::format(
        "poses in {} within odometry.file_max_gap_s = {} s of the frame times; it has {}, the dataset's {}: "
        "no frame within odometry.file_max_gap_s of the trajectory (another sequence, or times in another "
        "unit?)",
        config.file, config.file_max_gap_s, covers, frames);
  }
  if (source == OdometrySourceKind::kEkf) {
    return fmt::format(
        "the ekf to start ({}) within ekf.max_init_s = {} s and track the images and IMU of {} ({})",
        ekf.init_mode == EkfInitMode::kGroundTruth ? "from ground truth at a frame time"
        : ekf.init_mode == EkfInitMode::kStatic    ? "while the platform is still"
        : ekf.init_mode == EkfInitMode::kDynamic   ? "by visual-inertial alignment while moving"
                                                   : "still or moving",
        ekf.max_init_s, dataset.root().string(), frames);
  }
  if (source == OdometrySourceKind::kDrift) {
    std::string truth = "none";
    if (!dataset.ground_truth().empty()) {
      truth = "t = " + seconds(dataset.ground_truth().front().t_ns) + " .. " +
              seconds(dataset.ground_truth().back().t_ns) + " s";
    }
    return fmt::format("ground truth of {} at the frame times (its ground truth covers {}; the dataset's {})",
                       dataset.root().string(), truth, frames);
  }
  if (source == OdometrySourceKind::kNone) return "no poses (odometry.source none: appearance only)";
  return "poses from odometry.source " + std::string(enum_name(source));
}

void require_poses_if_needed(const PipelineConfig& config, const Dataset& dataset) {
  if (resolve_odometry_source(config.odometry, config.ekf, dataset) != OdometrySourceKind::kNone) return;
  const std::string why =
      config.odometry.source == OdometrySourceKind::kNone
          ? std::string("odometry.source is none (appearance only)")
          : "odometry.source auto found no odometry for dataset " + dataset.root().string() +
                " (no ground truth for drift; no IMU, calibration and images for the ekf)";
  if (config.run.mode == RunMode::kGated) {
    throw ConfigError("run.mode: 'gated' needs poses for the pose gate, and " + why +
                      ": use run.mode full (--mode full), or odometry.source file with a trajectory");
  }
  if (config.run.mode == RunMode::kOdometry) {
    throw ConfigError("run.mode: 'odometry' estimates poses only, and " + why + ": nothing to do");
  }
  if (config.verify.enabled) {
    throw ConfigError("verify.enabled: geometric verification triangulates with the odometry poses, and " +
                      why + ": set verify.enabled=false");
  }
}

namespace {
std::unique_ptr<OdometrySource> make_ekf_source(const OdometryConfig& config, const EkfConfig& ekf,
                                                const Dataset& dataset) {
  ekf.validate();
  const auto where = dataset.root();
  if (!dataset.has_images())
    throw DataError(where, "odometry.source ekf needs images, and this dataset has none");
  if (!dataset.has_imu())
    throw DataError(where, "odometry.source ekf needs IMU data, and this dataset has none");
  const auto camera = dataset.camera();
  if (!camera) {
    throw DataError(where,
                    "odometry.source ekf needs the camera calibration (cam sensor.yaml), and this "
                    "dataset has none");
  }
  const auto imu = dataset.imu_calibration();
  if (!imu) {
    throw DataError(where,
                    "odometry.source ekf needs the IMU calibration (imu0 sensor.yaml), and this "
                    "dataset has none");
  }
  const bool from_truth = ekf.init_mode == EkfInitMode::kGroundTruth;
  if (from_truth && !dataset.has_ground_truth()) {
    throw ConfigError("ekf.init_mode: 'ground_truth' needs ground truth, and dataset " + where.string() +
                      " has none (use ekf.init_mode=auto, the default, to start from the sensors)");
  }
  // Started from the sensors, the filter's world is its own (gravity-aligned, +z up, yaw 0 at the start):
  // only a start from ground truth takes the ground truth's world, and so its up axis.
  Eigen::Vector3d up_w = Eigen::Vector3d::UnitZ();
  if (config.ekf_up_axis != UpAxis::kAuto) {
    up_w = axis_vector(enum_name(config.ekf_up_axis));
  } else if (from_truth) {
    up_w = world_up_axis_from_imu(dataset).value_or(Eigen::Vector3d::UnitZ());
  }
  spdlog::info("odometry: ekf source (MSCKF, window {}, {} features), init_mode {}, world up [{} {} {}]",
               ekf.window_size, ekf.max_features, enum_name(ekf.init_mode), up_w.x(), up_w.y(), up_w.z());
  return std::make_unique<EkfOdometry>(
      ekf, *camera, *imu, from_truth ? dataset.ground_truth() : std::vector<GroundTruthState>{}, up_w);
}
}  // namespace

std::unique_ptr<OdometrySource> make_odometry_source(const OdometryConfig& config, const Dataset& dataset) {
  return make_odometry_source(config, EkfConfig{}, dataset);
}

std::unique_ptr<OdometrySource> make_odometry_source(const OdometryConfig& config, const EkfConfig& ekf,
                                                     const Dataset& dataset) {
  config.validate();
  const OdometrySourceKind source = resolve_odometry_source(config, ekf, dataset);
  if (config.source == OdometrySourceKind::kAuto)
    spdlog::info("odometry: source auto -> {}", enum_name(source));
  if (source == OdometrySourceKind::kEkf) return make_ekf_source(config, ekf, dataset);
  if (source == OdometrySourceKind::kNone) {
    spdlog::info("odometry: none (appearance only): frames carry no pose");
    return std::make_unique<NoOdometry>();
  }
  if (source == OdometrySourceKind::kFile) {
    TrajectoryFile trajectory = read_trajectory_file(config.file, config.file_format, dataset.source_times());
    std::vector<StampedPose>& poses = trajectory.poses;
    if (poses.empty()) throw DataError(config.file, "no poses in the trajectory file");
    // A trajectory that does not overlap the dataset would make every frame "odometry lost".
    const auto gap_ns = static_cast<Timestamp>(config.file_max_gap_s * 1e9);
    std::size_t covered = 0;
    for (std::size_t i = 0; i < dataset.frame_count(); ++i) {
      const Timestamp t = dataset.frame_t_ns(i);
      if (t >= poses.front().t_ns - gap_ns && t <= poses.back().t_ns + gap_ns) ++covered;
    }
    if (covered == 0) {
      // Said now, and again when the run ends (it exits non-zero, run_checks.hpp); the run still goes
      // through the frames so that its outputs show it frame by frame.
      spdlog::error("odometry: {}: every frame will be 'odometry lost'",
                    odometry_expectation(config, ekf, dataset));
    } else if (covered < dataset.frame_count()) {
      spdlog::warn("odometry: {} covers {} of the dataset's {} frames; the others are 'odometry lost'",
                   config.file, covered, dataset.frame_count());
    }
    spdlog::info("odometry: file source, {} poses from {} ({})", poses.size(), config.file,
                 trajectory.description);
    return std::make_unique<FileOdometry>(config, std::move(poses));
  }
  if (!dataset.has_ground_truth()) {
    throw ConfigError(
        "odometry.source: 'drift' needs ground truth, and dataset " + dataset.root().string() +
        " has none (use source: file with a trajectory, or none for an appearance-only run.mode full)");
  }
  Eigen::Vector3d axis_w = Eigen::Vector3d::UnitZ();
  if (config.heading_axis != HeadingAxis::kAuto) axis_w = axis_vector(enum_name(config.heading_axis));
  if (config.heading_axis == HeadingAxis::kAuto) {
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
