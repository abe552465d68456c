#include "io/trajectory_file.hpp"

#include <algorithm>
#include <string_view>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/csv_text.hpp"
#include "io/trajectory_io.hpp"

namespace loopgate {

namespace {

namespace fs = std::filesystem;

constexpr std::size_t kTumFields = 8;
constexpr std::size_t kKittiFields = 12;

std::vector<StampedPose> read_kitti_trajectory(const fs::path& file,
                                               std::span<const std::optional<Timestamp>> row_times,
                                               std::string& description) {
  io_detail::IssueLog log(true, nullptr);
  const auto rows = io_detail::read_kitti_pose_rows(file, log);
  std::vector<StampedPose> poses;
  poses.reserve(rows.size());
  if (!rows.empty() && rows.front()->t_ns) {
    for (const auto& row : rows) poses.push_back(StampedPose{*row->t_ns, row->T_w_cam0});
    description = "kitti, 13 columns (a time first)";
    return poses;
  }
  if (rows.size() > row_times.size()) {
    throw DataError(file, std::to_string(rows.size()) +
                              " poses of 12 columns (no times): one per frame of the "
                              "sequence, timed by the dataset, and it has " +
                              std::to_string(row_times.size()) +
                              " frame times (e.g. the rows of KITTI times.txt); use 13 columns with a time "
                              "in seconds first for another trajectory");
  }
  std::size_t untimed = 0;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    if (row_times[k]) {
      poses.push_back(StampedPose{*row_times[k], rows[k]->T_w_cam0});
    } else {
      ++untimed;
    }
  }
  description = "kitti, 12 columns timed by the dataset's frame times";
  if (untimed > 0) description += " (" + std::to_string(untimed) + " lines of frames without a time skipped)";
  return poses;
}

}  // namespace

TrajectoryFormat detect_trajectory_format(const fs::path& file) {
  const io_detail::TextFile text(file);
  const std::string_view all = text.text();
  std::size_t line_no = 0;
  for (std::size_t pos = 0; pos < all.size();) {
    ++line_no;
    const std::size_t end = std::min(all.find('\n', pos), all.size());
    std::string_view line = all.substr(pos, end - pos);
    pos = end + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    const std::size_t first = line.find_first_not_of(" \t");
    if (first == std::string_view::npos || line[first] == '#') continue;
    if (line.find(',') != std::string_view::npos) return TrajectoryFormat::kEuroc;
    std::vector<std::string_view> fields;
    io_detail::split_fields(line, io_detail::Delimiter::kWhitespace, fields);
    if (fields.size() == kTumFields) return TrajectoryFormat::kTum;
    if (fields.size() == kKittiFields || fields.size() == kKittiFields + 1) return TrajectoryFormat::kKitti;
    throw DataError(
        file, line_no,
        "cannot tell the trajectory format from " + std::to_string(fields.size()) +
            " fields: expected 8 (TUM: t_s tx ty tz qx qy qz qw), 12 or 13 (KITTI: row-major 3x4 "
            "pose, with 13 a time in seconds first) or comma-separated EuRoC columns (t_ns, p_xyz, "
            "q_wxyz); or set odometry.file_format");
  }
  throw DataError(file, "no poses: the trajectory file has no data line");
}

TrajectoryFile read_trajectory_file(const fs::path& file, TrajectoryFormat format,
                                    std::span<const std::optional<Timestamp>> row_times) {
  TrajectoryFile out;
  out.format = format == TrajectoryFormat::kAuto ? detect_trajectory_format(file) : format;
  switch (out.format) {
    case TrajectoryFormat::kTum:
      out.poses = read_tum(file);
      out.description = "tum";
      break;
    case TrajectoryFormat::kKitti: out.poses = read_kitti_trajectory(file, row_times, out.description); break;
    case TrajectoryFormat::kEuroc:
      for (const GroundTruthState& s : read_euroc_groundtruth(file)) out.poses.push_back({s.t_ns, s.T_w_b});
      out.description = "euroc";
      break;
    case TrajectoryFormat::kAuto: break;  // resolved above
  }
  if (format == TrajectoryFormat::kAuto) out.description += " (detected)";
  return out;
}

}  // namespace loopgate
