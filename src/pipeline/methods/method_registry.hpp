// The detection methods, one row each: the single table that `run`, `compare`, `aggregate`, the config's
// validation and `--help` read. A row names a method (`run.method: dird-seqslam-gated`, `compare --methods`)
// and says what it is made of: the detector (run.method's word in the config echo), the mode (gated or
// full), the DIRD DP's descriptor standardisation, and the facts other code asks of a method (whether its
// loops exist while the stream runs, which key holds the margin a loop needs). Adding a method: one class
// and one row here (docs/architecture.md § Adding a method).
#pragma once

#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "io/config.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

// Where a method's minimum frame distance between the two frames of a loop is configured.
enum class MarginKey { kMatchMargin, kSeqSlamExclusion };
inline constexpr EnumName<MarginKey> kMarginKeyNames[] = {
    {MarginKey::kMatchMargin, "match.margin"},
    {MarginKey::kSeqSlamExclusion, "seqslam.exclusion_margin_frames"}};
constexpr std::span<const EnumName<MarginKey>> enum_names(MarginKey) {
  return kMarginKeyNames;
}

// Builds the method's object for one run (detection_method.hpp).
using MethodFactory = std::unique_ptr<DetectionMethod> (*)(const MethodContext&);
// Builds its two-sequence form for one run (methods/two_sequence/two_sequence_method.hpp).
using TwoSequenceFactory = std::unique_ptr<TwoSequenceMethod> (*)(const PipelineConfig&);

struct MethodEntry {
  const char* name;             // run.method / compare --methods name
  Detector detector;            // the detector it runs (run.method in the config echo)
  RunMode mode;                 // gated or full
  StandardizeMode standardize;  // standardize.mode of the DIRD DP; dird-seqslam has its own section
  const char* what;             // one line for --help, compare and the docs
  bool streams_loops;           // loops are decided while the stream runs (gate.feedback can use them)
  MarginKey margin;             // the key of the frames a loop's two frames must be apart
  // Its two-sequence form (--reference --query: no poses, so no gate); nullptr when it has none.
  TwoSequenceFactory two_sequence;
  MethodFactory make;  // the stage objects it composes, as one DetectionMethod
};

// A row's factory: the function `fn` that the method's own file defines, declared by the row itself (a
// block-scope declaration inside a captureless lambda, which converts to a MethodFactory at compile time), so
// a new method needs no declaration in a shared header: one file and one row.
#define LOOPGATE_METHOD_FACTORY(fn)                                      \
  [](const MethodContext& context) -> std::unique_ptr<DetectionMethod> { \
    std::unique_ptr<DetectionMethod> fn(const MethodContext&);           \
    return fn(context);                                                  \
  }

inline constexpr MethodEntry kMethods[] = {
    {"full", Detector::kDird, RunMode::kFull, StandardizeMode::kOff,
     "DIRD on every frame (the paper's baseline)", true, MarginKey::kMatchMargin, make_two_sequence_dird,
     LOOPGATE_METHOD_FACTORY(make_dird_full)},
    {"gated", Detector::kDird, RunMode::kGated, StandardizeMode::kOff,
     "DIRD in the pose gate's candidate areas (the paper)", true, MarginKey::kMatchMargin, nullptr,
     LOOPGATE_METHOD_FACTORY(make_dird_gated)},
    {"seqslam", Detector::kSeqSlam, RunMode::kFull, StandardizeMode::kOff, "SeqSLAM on every frame", false,
     MarginKey::kSeqSlamExclusion, make_two_sequence_seqslam, LOOPGATE_METHOD_FACTORY(make_seqslam)},
    {"seqslam-gated", Detector::kSeqSlam, RunMode::kGated, StandardizeMode::kOff,
     "SeqSLAM in the candidate areas", false, MarginKey::kSeqSlamExclusion, nullptr,
     LOOPGATE_METHOD_FACTORY(make_seqslam_gated)},
    {"std-full", Detector::kDird, RunMode::kFull, StandardizeMode::kCausal,
     "standardised DIRD on every frame", true, MarginKey::kMatchMargin, make_two_sequence_dird,
     LOOPGATE_METHOD_FACTORY(make_standard_dird_full)},
    {"std-gated", Detector::kDird, RunMode::kGated, StandardizeMode::kCausal,
     "standardised DIRD in the candidate areas", true, MarginKey::kMatchMargin, nullptr,
     LOOPGATE_METHOD_FACTORY(make_standard_dird_gated)},
    {"dird-seqslam", Detector::kDirdSeqSlam, RunMode::kFull, StandardizeMode::kOff,
     "DIRD + contrast-enhanced sequence search (robust to day/night, seasons), every frame", true,
     MarginKey::kMatchMargin, make_two_sequence_dird_seqslam,
     LOOPGATE_METHOD_FACTORY(make_dird_seqslam_full)},
    {"dird-seqslam-gated", Detector::kDirdSeqSlam, RunMode::kGated, StandardizeMode::kOff,
     "DIRD + contrast-enhanced sequence search, in the candidate areas (recommended)", true,
     MarginKey::kMatchMargin, nullptr, LOOPGATE_METHOD_FACTORY(make_dird_seqslam_gated)},
};

// The row named `name`, or nullptr.
const MethodEntry* find_method_entry(std::string_view name);

// The row of a run from its words: detector (dird, seqslam, dird-seqslam), mode (full, gated; a
// two-sequence run counts as full) and standardize.mode. dird-seqslam's standardisation is its own
// section's, so standardize.mode tells only DIRD's rows apart. nullptr when no row matches (run.mode
// odometry).
const MethodEntry* find_method_entry(std::string_view detector, std::string_view mode,
                                     std::string_view standardize);

// The row of a configuration: the one run.method named (run.method_row), else the one of its detector, mode
// and standardize.mode; nullptr for run.mode odometry.
const MethodEntry* method_entry(const PipelineConfig& config);

// "full,gated,..." (every row, in table order; only those with a two-sequence form when asked).
std::string method_entry_names(bool two_sequence_only = false);

// run.method may name a row directly (`run.method: dird-seqslam-gated`): the row's detector, mode and
// standardisation are then written into run.method, run.mode and standardize.mode before the config is
// parsed. The detector words (dird, seqslam, dird-seqslam) keep their meaning: the detector, in the mode
// that run.mode says (`--method seqslam --mode gated`). A run.mode set to another mode than the row's is a
// ConfigError naming both. Returns the row named, nullptr for a detector word.
const MethodEntry* expand_method_name(RawConfig& raw);

// The checks of a valid configuration that depend on its method's row (PipelineConfig::validate() knows the
// sections, not the methods): gate.feedback needs a method that streams its loops. Throws ConfigError.
void validate_method(const PipelineConfig& config);

// load_config<PipelineConfig> with run.method expanded as above: `file` (when not empty), the --set
// overrides in order, then the flags; validated once (and validate_method()). run.method_row holds the row
// run.method named.
PipelineConfig load_pipeline_config(const std::filesystem::path& file,
                                    const std::vector<std::string>& overrides,
                                    const std::vector<FlagValue>& flags, ConfigPaths paths);

}  // namespace loopgate
