// Accuracy of a run's trajectory for summary.json: the odometry poses reported as tracking, against the
// dataset's ground truth interpolated to the same times, with the ATE of src/eval.
#pragma once

#include <nlohmann/json.hpp>
#include <vector>

#include "core/types.hpp"

namespace loopgate {

class Dataset;

// JSON object "trajectory_accuracy": {"available": false, "why": ...} without ground truth or with
// fewer than 3 poses inside its time span, else
//   alignment "posyaw" (translation + yaw about the gravity axis up_axis: from the IMU and the ground
//   truth when there is an IMU, else the world axis nearest the normal of the ground-truth plane; z for
//   EuRoC, y for KITTI camera frames),
//   pairs, rmse_m, mean_m, max_m, path_length_m, final_error_m, drift_per_100m (end-point error after
//   that alignment / ground-truth path length * 100), and se3_rmse_m (rotation+translation alignment).
// `tracked_poses` must be sorted by time.
nlohmann::json trajectory_accuracy_json(const std::vector<StampedPose>& tracked_poses,
                                        const Dataset& dataset);

}  // namespace loopgate
