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

// Time order: the rows kept are the longest run whose times strictly increase (a single outlier is the row
// dropped, judged against the rows on both sides of it); every other row is reported and skipped (lenient)
// or is the error (strict). A file with more than half of its rows bad is an error in lenient mode too.
std::vector<StampedPose> read_tum(const std::filesystem::path& file, IssueLog& log);
std::vector<GroundTruthState> read_euroc_groundtruth(const std::filesystem::path& csv_file, IssueLog& log);
// TUM-VI mav0/mocap0/data.csv: "t_ns, p_RS_R xyz [m], q_RS wxyz", exactly these 8 columns.
std::vector<GroundTruthState> read_mocap_groundtruth(const std::filesystem::path& csv_file, IssueLog& log);
std::vector<EurocImageEntry> read_euroc_camera_csv(const std::filesystem::path& csv_file, IssueLog& log);
// Out-of-order or duplicated samples are reported and dropped like the rows of the other tables: kept in file
// order, one outlier (a typo) made every later sample look out of order and left the frames without IMU.
std::vector<ImuSample> read_euroc_imu(const std::filesystem::path& csv_file, IssueLog& log);

// T_BS of an EuRoC sensor.yaml (e.g. state_groundtruth_estimate0/sensor.yaml, which has nothing else).
Eigen::Isometry3d read_yaml_T_BS(const std::filesystem::path& yaml_file);

// KITTI files are indexed by row (row i belongs to image i), so bad rows are kept as nullopt (lenient)
// instead of being removed. Times: the rows outside the longest strictly increasing run are bad.
std::vector<std::optional<Timestamp>> read_kitti_time_rows(const std::filesystem::path& times_file,
                                                           IssueLog& log);
// A KITTI pose row: 12 numbers (row-major 3x4 T_w_cam0), or 13 with a time in seconds first.
struct KittiPoseRow {
  std::optional<Timestamp> t_ns;  // 13-column files only
  Eigen::Isometry3d T_w_cam0 = Eigen::Isometry3d::Identity();
};
// The first good row fixes the column count (12 or 13; any other count is that line's error, and so is a
// later row of the other count). In a 13-column file the rows outside the longest run of strictly increasing
// times are bad too.
std::vector<std::optional<KittiPoseRow>> read_kitti_pose_rows(const std::filesystem::path& poses_file,
                                                              IssueLog& log);

}  // namespace loopgate::io_detail
