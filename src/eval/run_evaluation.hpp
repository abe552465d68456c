// The "evaluation" block of a run's summary.json from plain data (docs/evaluation.md): ground-truth loops
// from positions or from aligned sequences, the reported loops and the ranked detections scored against them,
// and the gated run's coverage of the true loops by candidate areas. No files: the caller writes
// truth_loops.csv and ground_truth.tum from what these return.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "eval/ground_truth.hpp"
#include "eval/precision_recall.hpp"

namespace loopgate {

// {"loop_truth": {loops, loops_true, loops_false, loops_without_travel, query_frames_with_loops,
//                 query_best_loop_true, query_best_loop_false},
//  "precision_recall": {score_order, positives, queries_with_detection, not_judged_without_travel,
//                       average_precision, recall_at_100,
//                       recall_at_99, recall_at_95, recall_at_1 (positives whose top-ranked detection is
//                       true), curve: [{threshold, precision, recall, detections, true_positives}, ...]}}
// `loops`: the reported detections (loops.csv); `ranked`: the detections the PR sweep runs over (DIRD: the
// loops; SeqSLAM: every query's match, accepted or not). Indices as `truth` expects them. Detections of the
// same place without travel (LoopGroundTruth::is_same_place_without_travel) are not judged: loops = true +
// false + without_travel, and the PR sweep and R@1 run over the judged ones only.
nlohmann::json loop_evaluation_json(const std::vector<Detection>& loops, const std::vector<Detection>& ranked,
                                    const LoopGroundTruth& truth, ScoreOrder score_order);

// A single-sequence run against ground-truth positions, or against listed (query, reference) pairs. Indices
// are within the run's frame range.
struct SequenceEvaluationInput {
  std::vector<Eigen::Vector3d> p_w;  // ground-truth position per frame; NaN where there is none
  GroundTruthConfig truth;
  // When set, the truth: (query, reference) pairs of run indices in [0, frame_count) (p_w and truth unused).
  std::optional<std::vector<std::pair<std::size_t, std::size_t>>> pairs;
  std::size_t frame_count = 0;   // with pairs: the run's frames
  nlohmann::json pairs_truth;    // with pairs: the "truth" block's description (file, pairs read, pairs used)
  std::vector<Detection> loops;  // reported loop closures
  std::vector<Detection> ranked;  // what the PR sweep runs over
  ScoreOrder score_order = ScoreOrder::kHigherIsBetter;
};

struct SequenceEvaluation {
  // {"available": true, "truth": {radius_m, gap_frames, plane, accept_radius_m, positives}} (pairs: the
  // pairs_truth fields and positives) + the loop_evaluation_json fields.
  nlohmann::json json;
  std::vector<std::pair<std::size_t, std::size_t>> truth_pairs;  // (query, reference), query ascending
  LoopGroundTruth truth;
};
SequenceEvaluation evaluate_sequence(const SequenceEvaluationInput& input);

// Gated runs: of the positive query frames whose true reference lies at least `margin_frames` back (the only
// ones a matcher with that margin can report) and that the run processed, how many have a true pair that a
// candidate area covers. {"gap_frames", "positive_query_frames", "covered_query_frames", "covered_fraction"}.
// `processed(q)`: frame q went through the run; `covers(q, r)`: a candidate-area cell holds (q, r).
nlohmann::json gate_coverage_json(const std::vector<Eigen::Vector3d>& p_w, const GroundTruthConfig& truth,
                                  int margin_frames, const std::function<bool(std::size_t)>& processed,
                                  const std::function<bool(std::size_t, std::size_t)>& covers);
// The same for any truth (positions or pairs): the true references at least `min_gap_frames` back.
nlohmann::json gate_coverage_json(const LoopGroundTruth& truth, int min_gap_frames,
                                  const std::function<bool(std::size_t)>& processed,
                                  const std::function<bool(std::size_t, std::size_t)>& covers);

// Aligned sequences (two-sequence runs, e.g. Nordland): query frame k and reference frame k show the same
// place. The frame ranges of a run (dataset frame indices [first, first + count)) and the tolerance.
struct AlignedSequences {
  std::size_t reference_first = 0, reference_count = 0;
  std::size_t query_first = 0, query_count = 0;
  int tolerance_frames = 0;

  // Query q and reference r (indices within their ranges) are a true match: |frame(q) - frame(r)| <= T.
  bool aligned(std::size_t q, std::size_t r) const;
  // Every true pair (q, r), indices within the ranges, q ascending.
  std::vector<std::pair<std::size_t, std::size_t>> pairs() const;
};

// The evaluation block of a two-sequence run, in the shape of the single-sequence runs:
// {"available": true, "truth": {"aligned_tolerance_frames", "positives"}} + the loop_evaluation_json fields.
nlohmann::json evaluate_aligned(const AlignedSequences& sequences, const std::vector<Detection>& loops,
                                const std::vector<Detection>& ranked, ScoreOrder score_order);

}  // namespace loopgate
