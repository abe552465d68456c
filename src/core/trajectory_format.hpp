// The formats of a trajectory file that loopgate reads (odometry.file_format): one name table for the config
// key (stages) and the reader (io/trajectory_file.hpp).
#pragma once

#include <span>

#include "core/enum_names.hpp"

namespace loopgate {

// auto: told from the file's first data line (io/trajectory_file.hpp); tum: "t_s tx ty tz qx qy qz qw";
// kitti: 12 numbers per row (row-major 3x4 pose), or 13 with a time in seconds first; euroc: a
// comma-separated state_groundtruth_estimate0/data.csv (t_ns, p_xyz, q_wxyz, ...; TUM-VI's mocap0/data.csv
// too).
enum class TrajectoryFormat { kAuto, kTum, kKitti, kEuroc };
inline constexpr EnumName<TrajectoryFormat> kTrajectoryFormatNames[] = {{TrajectoryFormat::kAuto, "auto"},
                                                                        {TrajectoryFormat::kTum, "tum"},
                                                                        {TrajectoryFormat::kKitti, "kitti"},
                                                                        {TrajectoryFormat::kEuroc, "euroc"}};
constexpr std::span<const EnumName<TrajectoryFormat>> enum_names(TrajectoryFormat) {
  return kTrajectoryFormatNames;
}

}  // namespace loopgate
