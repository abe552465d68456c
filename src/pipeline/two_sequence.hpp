// Two-sequence mode (docs/detection.md § Two sequences): a reference sequence against a query sequence
// (e.g. Nordland summer vs winter), appearance only. Every image of both is described (in parallel,
// `run.threads` workers) by the two-sequence form of run.method (methods/two_sequence/two_sequence_method.hpp: dird,
// dird-seqslam, seqslam), which then matches every query frame against the whole reference with no safety
// margin, using the stage objects of its single-sequence run (i = query frame, j = reference frame).
//
// Outputs in `out_dir` (outputs/two_sequence_outputs.hpp):
//   frames.csv  one row per query frame: its best reference match and score, accepted or not, and the
//               detection status and reason;
//   loops.csv   i,j,t_i,t_j,score (i query frame, j reference frame);
//   summary.json configuration echo, counts, stage times, peak RSS, and with eval.aligned_tolerance_frames
//               >= 0 the share of loops / best matches within that many frames of the same index.
// run.frames (A:B) selects the same index range of both sequences. Images that fail to decode are
// recorded (frame status "error") and take part in no pair (SeqSLAM: they take part as all-zero images).
//
// SeqSLAM (docs/detection.md § SeqSLAM) uses exclusion "none" whatever seqslam.exclusion says (logged).
// summary.json has "mode": "two-sequence", "method", "score_order" (DIRD and dird-seqslam higher_is_better,
// SeqSLAM lower_is_better) and "evaluation" (evaluate_aligned; {"available": false} when
// eval.aligned_tolerance_frames < 0; AlignedSequences and evaluate_aligned are in eval/run_evaluation.hpp);
// with a tolerance, truth_loops.csv lists the aligned pairs (i query, j reference frame).
#pragma once

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "eval/run_evaluation.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

class Dataset;

struct TwoSequenceResult {
  std::size_t reference_frames = 0, query_frames = 0;
  std::size_t loops = 0;
  double wall_s = 0;
  bool interrupted = false;  // a stop request: the outputs cover the query frames described before it
  nlohmann::json summary;
};

// `config` must be valid (load_config / apply_config validate it; run.mode is not used). Throws
// ConfigError/DataError for bad input found before the run (no frames, no images, an empty frame range).
// `stop` (may be null): once set, no further frame is described; the query frames described so
// far (a prefix of the range) are matched and every output is written for them, with "interrupted" in
// summary.json (none when the stop came while the reference was described). A second stop signal
// (core/stop_request.hpp) aborts the remaining work at once.
TwoSequenceResult run_two_sequences(const PipelineConfig& config, const Dataset& reference,
                                    const Dataset& query, const std::filesystem::path& out_dir,
                                    const std::atomic<bool>* stop = nullptr);

}  // namespace loopgate
