// summary.json of a single-sequence run, and its "evaluation" block: the detections against the dataset's
// ground truth (eval/run_evaluation.hpp), writing ground_truth.tum and truth_loops.csv for the plots.
#pragma once

#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>

#include "pipeline/detection_method.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline/run_counters.hpp"
#include "pipeline/time_accounting.hpp"

namespace loopgate {

class Dataset;
class ImageSource;
class ImuSynchronizer;
class LoopsWriter;
class LoopCloser;
class RunOutputs;

struct RunParts {
  const PipelineConfig& config;
  const Dataset& dataset;
  std::size_t first_frame = 0, last_frame = 0;
  const DetectionMethod& method;
  const RunOutputs& outputs;
  const LoopsWriter& loops;
  const ImageSource& images;
  const ImuSynchronizer* synchronizer = nullptr;
  const SeqIndex& seqs;
  double end_of_stream_ms = 0;
  // The evaluation's frames are [first_frame, evaluated_end_frame): those the run got to (an interrupted
  // run's are fewer than [first_frame, last_frame)); nullopt = last_frame.
  std::optional<std::size_t> evaluated_end_frame;
  const LoopCloser* closer = nullptr;
  EndOfStreamTime end_of_stream_time;  // the end of the stream's CPU time (time accounting)
};

// Evaluation block (evaluation.md): {"available": false} without ground truth or for a method that does not
// detect loops; else positives from positions (r_true, gap, plane), the loops and the ranked detections
// scored within r_accept, the PR curve, and for gated methods the gate coverage. Writes ground_truth.tum and
// truth_loops.csv into `out_dir`. Only frames the run processed take part.
nlohmann::json evaluate_run(const RunParts& parts, const std::filesystem::path& out_dir);

nlohmann::json make_run_summary(const RunParts& parts, const RunResult& result, nlohmann::json evaluation);

}  // namespace loopgate
