#include "pipeline/loops/correct_after_run.hpp"

#include <chrono>

#include "core/error.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loop_timing.hpp"
#include "pipeline/outputs/run_result.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

using loop_internal::ms_since;

nlohmann::json correct_after_run(const PipelineConfig& config, const Dataset& dataset, const RunTrack& track,
                                 const std::filesystem::path& run_dir) {
  const auto start = std::chrono::steady_clock::now();
  // LoopCorrection::kAfterRun: the run streamed without verification; its loops are verified here, with the
  // verify and posegraph sections of `config`.
  PipelineConfig verifying = config;
  verifying.verify.enabled = true;
  LoopCloser closer(verifying, dataset, track.first_frame, track.last_frame, true);
  for (std::size_t k = 0; k < track.tracked_frames.size(); ++k)
    closer.record_pose(track.tracked_frames[k], track.tracked_poses[k].T_w_b, track.tracked_sigma_m[k],
                       k < track.tracked_step_cov.size() ? track.tracked_step_cov[k] : std::nullopt);
  for (const Detection& loop : track.loops) closer.submit(loop);
  closer.finish();
  closer.write_edges(run_dir);
  if (!closer.solve_failure().empty())
    throw DataError(run_dir, "the final pose-graph solve failed (no trajectory_corrected.tum): " +
                                 closer.solve_failure());
  closer.write_graph(run_dir);
  closer.write_corrected(run_dir, track.tracked_poses);
  nlohmann::json fields = closer.summary_fields(track.tracked_poses);
  fields["ms"] = ms_since(start);
  return fields;
}

}  // namespace loopgate
