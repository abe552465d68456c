// Private: the file-format readers of trajectory_io.hpp in a form that reports through an IssueLog,
// so the dataset readers can open damaged files leniently. The public functions call these with a
// strict log.
#pragma once

#include <filesystem>
#include <optional>
#include <vector>

#include "core/types.hpp"
#include "io/csv_text.hpp"
#include "io/trajectory_io.hpp"

namespace loopgate::io_detail {

// Rows with a time that does not strictly increase are reported and skipped (lenient).
std::vector<StampedPose> read_tum(const std::filesystem::path& file, IssueLog& log);
std::vector<GroundTruthState> read_euroc_groundtruth(const std::filesystem::path& csv_file, IssueLog& log);
std::vector<EurocImageEntry> read_euroc_camera_csv(const std::filesystem::path& csv_file, IssueLog& log);
// Out-of-order or duplicated samples are reported and KEPT in file order (lenient).
std::vector<ImuSample> read_euroc_imu(const std::filesystem::path& csv_file, IssueLog& log);

// T_BS of an EuRoC sensor.yaml (e.g. state_groundtruth_estimate0/sensor.yaml, which has nothing else).
Eigen::Isometry3d read_yaml_T_BS(const std::filesystem::path& yaml_file);

// KITTI files are indexed by row (row i belongs to image i), so bad rows are kept as nullopt (lenient)
// instead of being removed. A time that does not strictly increase over the last good one is bad.
std::vector<std::optional<Timestamp>> read_kitti_time_rows(const std::filesystem::path& times_file,
                                                           IssueLog& log);
std::vector<std::optional<Eigen::Isometry3d>> read_kitti_pose_rows(const std::filesystem::path& poses_file,
                                                                   IssueLog& log);

}  // namespace loopgate::io_detail
