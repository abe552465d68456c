// The loop-detection method of a run, chosen once when the run is built (make_detection_method): none
// (odometry only), DIRD on every frame (full), DIRD inside the pose gate's candidate areas (gated), SeqSLAM
// on every frame (full) or inside the candidate areas (gated).
// The graph calls one hook per node; a method owns all of its state (descriptors, matcher, gate, areas) and
// nothing outside it branches on which method runs. To add a method, implement this interface in a new file
// and add its row to kMethods (method_registry.hpp; docs/architecture.md § Adding a method).
//
// Threading contract (the pipeline guarantees it): gate() and match() are called serially, in sequence
// order; describe() may run for several frames at once; finish() runs once after the graph drained (inside
// the run's task arena, so it may use parallel algorithms); detection() is called by the sink, serially,
// in sequence order; the rest after finish().
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "pipeline/frame/csv_row.hpp"
#include "pipeline/frame/frame_record.hpp"
#include "pipeline/pipeline_config.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

class GateFeedback;
class ImageSource;
class LoopsWriter;

// A frame's final detection row: whether it had a descriptor when the row was written, and the result
// (match in sequence numbers).
struct FrameVerdict {
  bool described = false;
  FrameDetection detection;
};

// What the run's evaluation needs from a method.
struct MethodEvaluation {
  // The detections the PR sweep runs over, dataset frame indices; empty optional: the loops themselves.
  std::optional<std::vector<Detection>> ranked;
  // Gated methods: whether a candidate-area cell holds (query seq, reference seq).
  std::function<bool(std::int64_t, std::int64_t)> covers;
};

// Everything a method may use from the run.
struct MethodContext {
  const PipelineConfig& config;
  const SeqIndex& seqs;
  ImageSource& images;
  LoopsWriter& loops;    // loops.csv (open when the method detects loops)
  std::size_t capacity;  // frames the run may release
  // gate.feedback (gated methods): verified loops into the pose gate; nullptr when off.
  GateFeedback* feedback;
};

class DetectionMethod {
 public:
  virtual ~DetectionMethod() = default;

  // summary.json "method" and "mode", e.g. dird / gated.
  virtual std::string name() const = 0;
  virtual std::string mode() const = 0;
  // False for the odometry-only run: no loops.csv, no detection columns, no evaluation.
  virtual bool detects() const { return true; }
  // describe() needs the pixels of every frame, decoded by the decode node.
  virtual bool needs_every_image() const { return false; }
  // Whether a higher score means a better match (similarities) or a lower one (SeqSLAM's ratio):
  // summary.json "score_order" and the PR sweep's threshold direction.
  virtual ScoreOrder score_order() const { return ScoreOrder::kHigherIsBetter; }

  virtual void gate(FrameRecord& /*r*/) {}
  virtual void describe(FrameRecord& /*r*/) {}
  virtual void match(FrameRecord& /*r*/) {}
  // End of stream: flush the matcher, run batch searches.
  virtual void finish() {}
  // D: frame s's detection() and every loop whose query is s are final once match() of s + D has run
  // (gate.feedback's lag, gate_feedback.hpp); nullopt when they are final only at the end of the stream.
  virtual std::optional<int> verdict_delay_frames() const { return std::nullopt; }

  // Columns of the frame's frames.csv row that the method knows when the frame reaches the sink (the
  // gate's decision); called once with a default record for the header.
  virtual void add_frame_cells(const FrameRecord& /*r*/, CsvRow& /*row*/) const {}
  // The detection row of frame `seq` once it is final (in order; nullopt: not yet).
  virtual std::optional<FrameVerdict> detection(std::size_t /*seq*/) { return std::nullopt; }

  // Files of its own (gated: candidate_areas.csv, candidate_cells.csv, descriptors.csv), after finish().
  virtual void write_files(const std::filesystem::path& /*out_dir*/) const {}
  // Its fields of summary.json: descriptors_computed, similarities_computed, candidate_areas,
  // gate, detection.nms_delay_frames, ... (merged over the run's).
  virtual nlohmann::json summary() const { return nlohmann::json::object(); }
  virtual MethodEvaluation evaluation() const { return {}; }
  // A descriptor for the plots' picture (DIRD: the first loop's query frame, else the middle frame).
  virtual std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const {
    return std::nullopt;
  }
};

// run.method seqslam: run.mode full -> SeqSLAM on every frame, gated -> SeqSLAM inside the candidate areas;
// run.method dird: run.mode full -> DIRD full, gated -> DIRD gated, odometry -> none (seqslam with odometry
// is rejected by the config); DIRD with standardize.mode causal or scale.mode online -> the standardised DIRD
// methods; run.method dird-seqslam: full or gated dird-seqslam (raw or standardised distances). Throws
// DataError when the method needs images and the dataset has none, ConfigError for an option the
// single-sequence run cannot take (standardize.mode batch; scale.mode online with run.mode gated).
std::unique_ptr<DetectionMethod> make_detection_method(const MethodContext& context, bool dataset_has_images,
                                                       const std::filesystem::path& dataset_root);

// run.mode odometry: no detection (detection_method.cpp). The methods' factories are declared by their rows
// of kMethods (method_registry.hpp).
std::unique_ptr<DetectionMethod> make_no_detection(const MethodContext& context);

}  // namespace loopgate
