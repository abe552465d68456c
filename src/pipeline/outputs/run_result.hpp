// What a finished run hands back to its caller: the counts, the failure, the summary and the track (odometry
// and loops) for correcting the trajectory after the run.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/pose_covariance.hpp"
#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

// A finished run's odometry and loops, for correcting its trajectory after the run (compare's loop
// correction, correct_after_run in loops/correct_after_run.hpp).
struct RunTrack {
  std::size_t first_frame = 0, last_frame = 0;  // the run's frame range [first, last)
  std::vector<std::size_t> tracked_frames;      // the frame of each tracked pose
  std::vector<StampedPose> tracked_poses;       // the odometry's estimates (status tracking; the ATE's poses)
  std::vector<double> tracked_sigma_m;          // their position sigma (PoseEstimate::position_sigma_m)
  // Their step covariances (OdometryOutput::step_cov) when the pose graph uses them (posegraph.odometry_cov
  // odometry) and loop closure is on (verify.enabled, or run_pipeline's keep_step_cov); else empty.
  std::vector<std::optional<PoseCov>> tracked_step_cov;
  std::vector<Detection> loops;  // as loops.csv, dataset frames
};

struct RunResult {
  std::size_t frames_in = 0;         // presented by the source: processed + dropped (+ lost on failure)
  std::size_t frames_processed = 0;  // through the sink
  std::size_t frames_dropped = 0;    // real-time overload drops (rate mode)
  std::size_t deadline_misses = 0;   // rate mode: sink exit later than release + deadline
  std::size_t frames_ok = 0, frames_warning = 0, frames_error = 0;
  double wall_s = 0, data_s = 0, realtime_factor = 0, cpu_s = 0, peak_rss_mb = 0;
  bool interrupted = false;
  bool failed = false;
  std::string error;  // the failure, naming stage, seq and frame
  // Outputs that could not be written (a full disk): each file is whole or absent; these are absent. A run
  // with a missing output is `failed`.
  std::vector<std::string> missing_outputs;
  std::vector<std::string> output_errors;  // why, naming the files
  std::string profile_table;               // the profiler table (also in summary.json as numbers)
  nlohmann::json summary;                  // what summary.json holds
  // A descriptor for the plots' picture (DIRD methods: the first loop's query frame, else the middle
  // frame), with its dataset frame index.
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor;
  RunTrack track;
};

}  // namespace loopgate
