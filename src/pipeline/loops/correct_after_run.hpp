// compare's loop correction of a finished run, outside the loop closer's class: the run's odometry and
// loops fed to a LoopCloser after the run (loop_closer.hpp).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

namespace loopgate {

class Dataset;
struct PipelineConfig;
struct RunTrack;

// compare's loop correction: a finished run's loops verified and its pose graph solved after the run, outside
// its timing (the same LoopCloser, fed the run's poses and loops in order, so the files are those a run with
// verify.enabled writes). Writes loop_edges.csv and trajectory_corrected.tum into run_dir and returns
// summary_fields() plus "ms" (the wall time of the correction). The policy LoopCorrection::kAfterRun
// (loop_correction_policy.hpp): the loops are verified whatever `config.verify.enabled` says, with its verify
// and posegraph sections.
nlohmann::json correct_after_run(const PipelineConfig& config, const Dataset& dataset, const RunTrack& track,
                                 const std::filesystem::path& run_dir);

}  // namespace loopgate
