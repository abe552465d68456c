// The methods `compare` runs, by name: detector, mode and the DIRD DP's descriptor standardisation
// (standardize.mode; dird-seqslam takes its own descriptors from section dird_seqslam). Everything else is
// the shared configuration. One table: a new method is one line here. `aggregate` names every run by it.
#pragma once

#include <string_view>

#include "pipeline/pipeline_config.hpp"

namespace loopgate::app {

struct CompareMethod {
  const char* name;
  Detector detector;
  RunMode mode;
  const char* standardize;  // standardize.mode
  const char* what;
};
inline constexpr CompareMethod kCompareMethods[] = {
    {"full", Detector::kDird, RunMode::kFull, "off", "DIRD on every frame (the paper's baseline)"},
    {"gated", Detector::kDird, RunMode::kGated, "off", "DIRD in the pose gate's candidate areas (the paper)"},
    {"seqslam", Detector::kSeqSlam, RunMode::kFull, "off", "SeqSLAM on every frame"},
    {"seqslam-gated", Detector::kSeqSlam, RunMode::kGated, "off", "SeqSLAM in the candidate areas"},
    {"std-full", Detector::kDird, RunMode::kFull, "causal", "standardised DIRD on every frame"},
    {"std-gated", Detector::kDird, RunMode::kGated, "causal", "standardised DIRD in the candidate areas"},
    {"dird-seqslam", Detector::kDirdSeqSlam, RunMode::kFull, "off",
     "DIRD + contrast-enhanced sequence search (robust to day/night, seasons), every frame"},
    {"dird-seqslam-gated", Detector::kDirdSeqSlam, RunMode::kGated, "off",
     "DIRD + contrast-enhanced sequence search, in the candidate areas (recommended)"},
};

// The compare name of a run from its summary's words: "method" (dird, seqslam, dird-seqslam), "mode" (full,
// gated; a two-sequence run counts as full) and config.standardize.mode. dird-seqslam's standardisation is
// its own section's, so standardize.mode tells only DIRD's entries apart. nullptr when no entry matches
// (e.g. run.mode odometry).
inline const CompareMethod* find_compare_method(std::string_view method, std::string_view mode,
                                                std::string_view standardize) {
  if (mode == "two-sequence") mode = "full";
  const CompareMethod* loose = nullptr;
  for (const CompareMethod& m : kCompareMethods) {
    if (enum_name(m.detector) != method || enum_name(m.mode) != mode) continue;
    if (standardize == m.standardize) return &m;
    if (m.detector != Detector::kDird && loose == nullptr) loose = &m;
  }
  return loose;
}

}  // namespace loopgate::app
