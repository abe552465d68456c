#include "pipeline/outputs/run_counters.hpp"

#include <string_view>

namespace loopgate {

void RunCounters::count(const FrameRecord& r, const std::string& status, const std::string& reason) {
  ++processed;
  (status == "ok" ? frames_ok : status == "warning" ? frames_warning : frames_error)++;
  if (r.decoded) ++decoded;
  if (r.needs_pixels && !r.decoded) ++image_errors;
  if (r.has_pose && r.odometry.pose.status == OdometryStatus::kLost) ++odometry_lost;
  if (r.needs_pixels) ++frames_needing_image;
  const auto first_message = [&r](std::string_view prefix) -> std::string {
    for (const auto* list : {&r.errors, &r.warnings})
      for (const std::string& m : *list)
        if (m.starts_with(prefix)) return "frame " + std::to_string(r.label) + ": " + m;
    return {};
  };
  if (r.usable_pose()) {
    ++frames_with_pose;
  } else if (first_odometry_problem.empty()) {
    first_odometry_problem = first_message("odometry");
  }
  if (r.needs_pixels && !r.decoded && first_image_error.empty()) first_image_error = first_message("image");
  imu_gaps += static_cast<std::size_t>(r.imu.report.gaps);
  imu_out_of_order += static_cast<std::size_t>(r.imu.report.out_of_order);
  imu_duplicates += static_cast<std::size_t>(r.imu.report.duplicates);
  if (r.imu.report.imu_missing) ++imu_missing_frames;
  if (!have_first_t) {
    have_first_t = true;
    first_t_ns = r.t_ns;
  }
  last_t_ns = r.t_ns;
  if (status != "ok") {
    if (problem_frames.size() < kMaxListedProblems) {
      problem_frames.push_back({{"seq", r.seq}, {"frame", r.label}, {"status", status}, {"reason", reason}});
    }
    ++problem_frame_count;
  }
}

nlohmann::json RunCounters::outcomes_json() const {
  const auto n = [this](FrameOutcome o) { return outcomes[static_cast<std::size_t>(o)]; };
  return {{"no_candidate", n(FrameOutcome::kNoCandidate)},
          {"below_threshold", n(FrameOutcome::kBelowThreshold)},
          {"suppressed", n(FrameOutcome::kSuppressed)},
          {"loop", n(FrameOutcome::kLoop)}};
}

}  // namespace loopgate
