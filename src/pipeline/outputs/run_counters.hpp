// Counts of a run, kept by the sink (and read after the drain): frames by status, decoded images, odometry
// losses, IMU anomalies, the frames with problems (listed in summary.json), detection outcomes.
#pragma once

#include <array>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>

#include "core/types.hpp"
#include "pipeline/frame/frame_record.hpp"

namespace loopgate {

struct RunCounters {
  std::size_t processed = 0, frames_ok = 0, frames_warning = 0, frames_error = 0;
  std::size_t deadline_misses = 0, decoded = 0, odometry_lost = 0, image_errors = 0;
  std::size_t imu_gaps = 0, imu_out_of_order = 0, imu_duplicates = 0, imu_missing_frames = 0;
  // For the run's checks (run_checks.hpp): frames with an estimated pose, frames whose pixels the decode
  // stage needed, and the first frame's odometry and image problems ("frame N: ...").
  std::size_t frames_with_pose = 0, frames_needing_image = 0;
  std::string first_odometry_problem, first_image_error;
  bool have_first_t = false;
  Timestamp first_t_ns = 0, last_t_ns = 0;
  nlohmann::json problem_frames = nlohmann::json::array();  // the first kMaxListedProblems
  std::size_t problem_frame_count = 0;
  std::array<std::size_t, kFrameOutcomeCount> outcomes{};

  static constexpr std::size_t kMaxListedProblems = 200;

  // One frame through the sink with its status ("ok" | "warning" | "error") and reason.
  void count(const FrameRecord& r, const std::string& status, const std::string& reason);
  void count(FrameOutcome outcome) { ++outcomes[static_cast<std::size_t>(outcome)]; }
  double data_s() const { return have_first_t ? ns_to_s(last_t_ns - first_t_ns) : 0.0; }
  // summary.json "detection" counts: no_candidate, below_threshold, suppressed, loop.
  nlohmann::json outcomes_json() const;
};

}  // namespace loopgate
