// A trajectory file in any of the formats loopgate reads (odometry.file, odometry.file_format):
//   tum:   "t_s tx ty tz qx qy qz qw" per line (whitespace);
//   kitti: 12 numbers per line (row-major 3x4 pose): line k is the pose at the sequence's frame k, timed by
//          `row_times` (Dataset::source_times(), e.g. the rows of KITTI times.txt); or 13 numbers, a time in
//          seconds first, timed by itself;
//   euroc: comma-separated t_ns, p_xyz, q_wxyz (+ velocity and biases), as
//   state_groundtruth_estimate0/data.csv
//          or TUM-VI's mocap0/data.csv.
// auto tells them apart by the first data line ('#' comments skipped): commas -> euroc; else 8 fields -> tum,
// 12 or 13 -> kitti. Every error is a DataError naming the file and, where there is one, the line.
#pragma once

#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/trajectory_format.hpp"
#include "core/types.hpp"

namespace loopgate {

struct TrajectoryFile {
  TrajectoryFormat format = TrajectoryFormat::kAuto;  // the format read (auto resolved)
  std::string description;                            // e.g. "kitti, 12 columns timed by the dataset"
  std::vector<StampedPose> poses;                     // strictly increasing times
};

// The format of `file` from its first data line; DataError naming the file and line when it fits none.
TrajectoryFormat detect_trajectory_format(const std::filesystem::path& file);

// Reads `file` in `format` (auto: detected). `row_times[k]`: the time of line k of a 12-column KITTI file
// (nullopt: that frame has no time, its pose is skipped); a 12-column file with more lines than row_times is
// an error.
TrajectoryFile read_trajectory_file(const std::filesystem::path& file, TrajectoryFormat format,
                                    std::span<const std::optional<Timestamp>> row_times);

}  // namespace loopgate
