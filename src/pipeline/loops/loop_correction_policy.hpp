// How a run's loops correct its trajectory: a value the caller of a run chooses and hands to it, instead of
// switching verify.enabled off and on around the run.
#pragma once

#include <span>

#include "core/enum_names.hpp"

namespace loopgate {

enum class LoopCorrection {
  kOff,        // no verification, no pose graph (verify.enabled false)
  kStreaming,  // `run` with verify.enabled: the loop closer verifies the loops while the stream runs
  // compare: the stream runs without verification, so that every method's column times the same
  // loop-detection work; the run keeps its odometry's step covariances, and its loops are verified and its
  // pose graph solved after it (correct_after_run).
  kAfterRun,
};

inline constexpr EnumName<LoopCorrection> kLoopCorrectionNames[] = {
    {LoopCorrection::kOff, "off"},
    {LoopCorrection::kStreaming, "streaming"},
    {LoopCorrection::kAfterRun, "after_run"},
};
constexpr std::span<const EnumName<LoopCorrection>> enum_names(LoopCorrection) {
  return kLoopCorrectionNames;
}

// compare's policy: its runs are corrected after they end when the configuration verifies loops.
constexpr LoopCorrection compare_loop_correction(bool verify_enabled) {
  return verify_enabled ? LoopCorrection::kAfterRun : LoopCorrection::kOff;
}
// Whether the stream itself verifies loops (the streamed run's verify.enabled).
constexpr bool verifies_while_streaming(LoopCorrection correction) {
  return correction == LoopCorrection::kStreaming;
}
// Whether the run keeps its odometry's step covariances for a correction after it (run_pipeline's
// keep_step_cov).
constexpr bool corrects_after_run(LoopCorrection correction) {
  return correction == LoopCorrection::kAfterRun;
}

}  // namespace loopgate
