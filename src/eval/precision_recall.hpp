// Scoring loop detections against a ground truth: PR curve, average precision, recall at a
// precision (docs/evaluation.md).
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "eval/ground_truth.hpp"

namespace loopgate {

// Which way a detection's score is better: lower (SeqSLAM ratio, descriptor distance) or higher (similarity).
enum class ScoreOrder { kLowerIsBetter, kHigherIsBetter };
inline constexpr EnumName<ScoreOrder> kScoreOrderNames[] = {
    {ScoreOrder::kLowerIsBetter, "lower_is_better"}, {ScoreOrder::kHigherIsBetter, "higher_is_better"}};
constexpr std::span<const EnumName<ScoreOrder>> enum_names(ScoreOrder) {
  return kScoreOrderNames;
}

// A loop detection: query (current) frame matched to reference (earlier) frame with a score.
struct Detection {
  std::size_t query = 0;
  std::size_t reference = 0;
  double score = 0.0;
};

struct PrConfig {
  ScoreOrder score_order = ScoreOrder::kLowerIsBetter;

  // The keys, in order, for loading, printing and the JSON echo (Self is PrConfig or const PrConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("score_order", self.score_order);
  }
  bool lower_is_better() const { return score_order == ScoreOrder::kLowerIsBetter; }
};

// One operating point: every query whose best detection scores at least as well as `threshold`
// is accepted.
struct PrPoint {
  double threshold = 0.0;
  std::size_t detections = 0;      // accepted queries
  std::size_t true_positives = 0;  // accepted queries whose detection is a true match
  std::size_t recalled = 0;        // accepted positive queries whose detection is a true match
  double precision = 1.0;          // true_positives / detections
  double recall = 0.0;             // recalled / positive queries
};

struct PrResult {
  std::vector<PrPoint> curve;  // one point per distinct best-detection score, most confident first
  std::size_t positives = 0;   // positive query frames of the ground truth
  std::size_t queries_with_detection = 0;
  std::size_t not_judged = 0;  // detections dropped as the same place without travel (not true, not false)
  double average_precision = 0.0;
  double recall_at_100 = 0.0;  // highest recall with precision = 1
  double recall_at_99 = 0.0;
  double recall_at_95 = 0.0;
};

// Keeps each query's best-scoring detection (the first one on ties), in query order.
std::vector<Detection> best_detection_per_query(const std::vector<Detection>& detections,
                                                bool lower_is_better);

// The detections a ground truth judges: those that are not the same place without travel
// (LoopGroundTruth::is_same_place_without_travel), in their order.
std::vector<Detection> judged_detections(const std::vector<Detection>& detections,
                                         const LoopGroundTruth& ground_truth);

// Sweeps the score threshold over the best judged detection per query (detections of the same place
// without travel are dropped first and counted in not_judged). A detection is a true positive
// when ground_truth.is_true_match(query, reference). Precision = TP / accepted; recall = accepted
// positive queries with a TP / positive queries (a TP of a non-positive query, e.g. a match to a
// later frame, counts for precision but not for recall, so recall stays <= 1).
PrResult evaluate_precision_recall(const std::vector<Detection>& detections,
                                   const LoopGroundTruth& ground_truth, const PrConfig& config = {});

// Area under the step PR curve: sum over points of (recall_k - recall_{k-1}) * precision_k, with
// recall_0 = 0 (the interpolation-free definition of scikit-learn's average_precision_score).
double average_precision(const std::vector<PrPoint>& curve);
// Highest recall among points with precision >= min_precision; 0 when there is none.
double recall_at_precision(const std::vector<PrPoint>& curve, double min_precision);

}  // namespace loopgate
