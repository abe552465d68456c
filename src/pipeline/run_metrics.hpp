// Accuracy figures of a run for summary.json: the trajectory (the odometry poses reported as tracking,
// against the dataset's ground truth interpolated to the same times, with the ATE of src/eval) and the loop
// detections (scored against ground-truth loops, with the PR evaluation of src/eval).
#pragma once

#include <nlohmann/json.hpp>
#include <vector>

#include "core/types.hpp"
#include "eval/ground_truth.hpp"
#include "eval/precision_recall.hpp"

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

// {"loop_truth": {loops, loops_true, loops_false, query_frames_with_loops, query_best_loop_true,
//                 query_best_loop_false},
//  "precision_recall": {score_order, positives, queries_with_detection, average_precision, recall_at_100,
//                       recall_at_99, recall_at_95, curve: [{threshold, precision, recall, detections,
//                       true_positives}, ...]}}
// `loops`: the reported detections (loops.csv); `ranked`: the detections the PR sweep runs over (DIRD: the
// loops; SeqSLAM: every query's match, accepted or not). Indices as `truth` expects them.
nlohmann::json loop_evaluation_json(const std::vector<Detection>& loops, const std::vector<Detection>& ranked,
                                    const LoopGroundTruth& truth, const std::string& score_order);

}  // namespace loopgate
