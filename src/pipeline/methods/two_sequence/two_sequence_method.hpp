// The two-sequence (batch) form of a detection method (docs/detection.md § Two sequences): a reference
// sequence against a query sequence, appearance only, no poses, so no gate. The run (two_sequence.cpp) reads
// the images and hands each to describe() on its parallel loop, reference first; then match() compares every
// described query frame with the whole reference, with the same stage objects the single-sequence method
// uses (DIRD: DirdSimilarity and the SequenceMatcher; dird-seqslam: the coded distances and
// ContrastSequenceSearch; SeqSLAM: SeqSlamBatch), and gives one verdict per query frame, the loops and the
// detections the PR sweep ranks. The run writes every output from them (frames.csv, loops.csv,
// summary.json, the evaluation): no method writes a file.
//
// Threading contract (the run guarantees it): describe() runs for several frames at once, each (side, k)
// once; begin() before it and match() after it, on the calling thread, which may use the run's parallel
// loop (TwoSequenceRun::parallel).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "pipeline/frame/csv_row.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

class Dataset;

enum class SequenceSide { kReference, kQuery };

// What the run lends a method while it matches: the run's parallel loop, its clock and its trace.
class TwoSequenceRun {
 public:
  virtual ~TwoSequenceRun() = default;
  // Runs body(k) for k in [0, count) on the run's threads, in blocks (a span each on trace.json when
  // `blocks` names them). Each body writes only its own outputs, so the result does not depend on the
  // thread count. A second stop signal aborts (Interrupted).
  virtual void parallel(std::size_t count, const std::function<void(std::size_t)>& body,
                        const char* blocks = nullptr) = 0;
  // The run clock (ns since the run's start), and a phase from `from_ns` to now on trace.json.
  virtual std::int64_t now_ns() const = 0;
  virtual void phase(const char* name, std::int64_t from_ns) = 0;
};

// One side after describe: frames [0, taken) were read (all of them unless a stop request came); `valid`:
// the frame has a descriptor; `errors`: why not (empty when fine).
struct DescribedFrames {
  std::vector<std::uint8_t> valid;
  std::vector<std::string> errors;
  std::size_t described = 0;
  std::size_t taken = 0;
};

// What match() is given: the frames described (query_count <= the query range: a stop request ends it
// after the frames taken), and the datasets with the first frame of each range (frame numbers for cells).
struct TwoSequenceInput {
  const DescribedFrames& reference;
  const DescribedFrames& query;
  std::size_t reference_count = 0, query_count = 0;
  const Dataset& reference_dataset;
  const Dataset& query_dataset;
  std::size_t reference_first = 0, query_first = 0;
};

// A query frame's verdict: its detection (match: the reference index within the range, -1 none) and the
// method's own cells of its frames.csv row.
struct QueryVerdict {
  std::size_t query = 0;
  FrameDetection detection;
  CsvRow cells;
};

struct TwoSequenceMatches {
  std::vector<std::string> columns;  // the method's frames.csv columns (the names of every verdict's cells)
  std::vector<QueryVerdict> frames;  // one per query frame, in order
  std::vector<Detection> loops;      // accepted, indices within the ranges
  std::vector<Detection> ranked;     // what the PR sweep runs over
  std::size_t similarities = 0;      // pair similarities (distances, difference-matrix entries) computed
  nlohmann::json summary = nlohmann::json::object();  // the method's own fields (stages_s, detection, ...)
};

class TwoSequenceMethod {
 public:
  virtual ~TwoSequenceMethod() = default;

  // summary.json "method" and "score_order", and the effective configuration it echoes.
  virtual const char* name() const = 0;
  virtual ScoreOrder score_order() const = 0;
  virtual nlohmann::json config_json() const = 0;
  // The describe step's word on trace.json and in stages_s: "describe" or "preprocess".
  virtual const char* describe_step() const { return "describe"; }
  // After a frame's error in its frames.csv reason (SeqSLAM: the frame took part as an all-zero image).
  virtual std::string error_note() const { return {}; }

  // Before describe: the frames of each range.
  virtual void begin(std::size_t reference_count, std::size_t query_count) = 0;
  // Frame k of `side` (dataset frame `frame`); `image` null when it did not load (the run recorded why).
  // Returns false, with `error` set, when the method cannot take the image. Parallel for distinct (side, k).
  virtual bool describe(SequenceSide side, std::size_t k, const cv::Mat* image, const Dataset& dataset,
                        std::size_t frame, std::string& error) = 0;
  // Every described query frame against the whole reference. Throws DataError when nothing can be matched.
  virtual TwoSequenceMatches match(TwoSequenceRun& run, const TwoSequenceInput& input) = 0;
};

// The two-sequence form of run.method, from its row of the method registry (method_registry.hpp): dird
// (raw, or standardize.mode batch or causal, scale.mode online), dird-seqslam and seqslam
// (two_sequence_dird.cpp, two_sequence_dird_seqslam.cpp, two_sequence_seqslam.cpp).
std::unique_ptr<TwoSequenceMethod> make_two_sequence_method(const PipelineConfig& config);
std::unique_ptr<TwoSequenceMethod> make_two_sequence_dird(const PipelineConfig& config);
std::unique_ptr<TwoSequenceMethod> make_two_sequence_dird_seqslam(const PipelineConfig& config);
std::unique_ptr<TwoSequenceMethod> make_two_sequence_seqslam(const PipelineConfig& config);

// Seconds between two readings of the run clock (ns).
inline double seconds_between(std::int64_t from_ns, std::int64_t to_ns) {
  return 1e-9 * static_cast<double>(to_ns - from_ns);
}

}  // namespace loopgate
