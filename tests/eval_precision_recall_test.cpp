// Scoring: best detection per query, PR sweep, average precision, recall at a precision.
#include <gtest/gtest.h>

#include "core/error.hpp"
#include "eval/precision_recall.hpp"

namespace loopgate {
namespace {

// 10 frames; positive queries 5..8 with true references 0..3.
LoopGroundTruth small_truth() {
  return LoopGroundTruth::from_pairs(10, {{5, 0}, {6, 1}, {7, 2}, {8, 3}});
}

// Lower is better. Best per query (worse duplicates ignored even when they would be right):
//   0.1 q5 TP, 0.2 q6 FP, 0.3 q7 TP, 0.4 q9 FP (not a positive query), 0.5 q8 TP.
std::vector<Detection> small_detections() {
  return {{5, 0, 0.1}, {6, 9, 0.2}, {6, 1, 0.25}, {7, 2, 0.3}, {7, 0, 0.35}, {9, 4, 0.4}, {8, 3, 0.5}};
}

TEST(EvalPrecisionRecall, BestDetectionPerQuery) {
  const auto best = best_detection_per_query(small_detections(), true);
  ASSERT_EQ(best.size(), 5u);
  EXPECT_EQ(best[1].query, 6u);
  EXPECT_EQ(best[1].reference, 9u);
  const auto highest = best_detection_per_query(small_detections(), false);
  EXPECT_EQ(highest[1].reference, 1u);  // 0.25 > 0.2
}

TEST(EvalPrecisionRecall, HandComputedCurve) {
  const PrResult pr = evaluate_precision_recall(small_detections(), small_truth());
  EXPECT_EQ(pr.positives, 4u);
  EXPECT_EQ(pr.queries_with_detection, 5u);
  ASSERT_EQ(pr.curve.size(), 5u);
  const double precision[] = {1.0, 0.5, 2.0 / 3.0, 0.5, 0.6};
  const double recall[] = {0.25, 0.25, 0.5, 0.5, 0.75};
  const double threshold[] = {0.1, 0.2, 0.3, 0.4, 0.5};
  for (std::size_t k = 0; k < 5; ++k) {
    EXPECT_DOUBLE_EQ(pr.curve[k].precision, precision[k]) << k;
    EXPECT_DOUBLE_EQ(pr.curve[k].recall, recall[k]) << k;
    EXPECT_EQ(pr.curve[k].threshold, threshold[k]) << k;
    EXPECT_EQ(pr.curve[k].detections, k + 1);
  }
  // AP = 0.25 * 1 + 0.25 * 2/3 + 0.25 * 0.6
  EXPECT_NEAR(pr.average_precision, 0.25 + 0.25 * 2.0 / 3.0 + 0.15, 1e-12);
  EXPECT_DOUBLE_EQ(pr.recall_at_100, 0.25);
  EXPECT_DOUBLE_EQ(pr.recall_at_99, 0.25);
  EXPECT_DOUBLE_EQ(pr.recall_at_95, 0.25);
  EXPECT_DOUBLE_EQ(recall_at_precision(pr.curve, 0.6), 0.75);
  EXPECT_DOUBLE_EQ(recall_at_precision(pr.curve, 0.65), 0.5);
}

TEST(EvalPrecisionRecall, HigherIsBetterAndTiesAcceptedTogether) {
  PrConfig config;
  config.score_order = ScoreOrder::kHigherIsBetter;
  // Similarities: q5 TP 0.9, q6 FP 0.9 (tie), q7 TP 0.8, q8 TP 0.7.
  const std::vector<Detection> d{{5, 0, 0.9}, {6, 8, 0.9}, {7, 2, 0.8}, {8, 3, 0.7}};
  const PrResult pr = evaluate_precision_recall(d, small_truth(), config);
  ASSERT_EQ(pr.curve.size(), 3u);
  EXPECT_EQ(pr.curve[0].detections, 2u);  // both 0.9 detections at once
  EXPECT_DOUBLE_EQ(pr.curve[0].precision, 0.5);
  EXPECT_DOUBLE_EQ(pr.curve[0].recall, 0.25);
  EXPECT_DOUBLE_EQ(pr.curve[2].precision, 0.75);
  EXPECT_DOUBLE_EQ(pr.curve[2].recall, 0.75);
  EXPECT_DOUBLE_EQ(pr.recall_at_100, 0.0);  // never at precision 1
  EXPECT_NEAR(pr.average_precision, 0.25 * 0.5 + 0.25 * 2.0 / 3.0 + 0.25 * 0.75, 1e-12);
  // The words summary.json writes for the two orders.
  EXPECT_EQ(enum_name(ScoreOrder::kHigherIsBetter), "higher_is_better");
  EXPECT_EQ(enum_name(ScoreOrder::kLowerIsBetter), "lower_is_better");
}

TEST(EvalPrecisionRecall, PerfectDetectorAndEmptyInput) {
  const std::vector<Detection> perfect{{5, 0, 1.0}, {6, 1, 2.0}, {7, 2, 3.0}, {8, 3, 4.0}};
  const PrResult pr = evaluate_precision_recall(perfect, small_truth());
  EXPECT_DOUBLE_EQ(pr.average_precision, 1.0);
  EXPECT_DOUBLE_EQ(pr.recall_at_100, 1.0);
  const PrResult none = evaluate_precision_recall({}, small_truth());
  EXPECT_TRUE(none.curve.empty());
  EXPECT_EQ(none.average_precision, 0.0);
  EXPECT_EQ(none.recall_at_100, 0.0);
}

TEST(EvalPrecisionRecall, PositionTruthCountsFutureMatchesForPrecisionOnly) {
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < 10; ++i) p.emplace_back(i, 0, 0);
  for (int k = 0; k < 10; ++k) p.emplace_back(9 - k, 0, 0);
  GroundTruthConfig config;
  config.radius_m = 0.5;
  config.gap_frames = 3;
  const auto gt = LoopGroundTruth::from_positions(p, config);  // positives 11..19
  // q3 -> 16 is the same place (a match to a later frame): TP for precision, no recall (q3 is not positive).
  const std::vector<Detection> d{{3, 16, 0.1}, {12, 7, 0.2}};
  const PrResult pr = evaluate_precision_recall(d, gt);
  ASSERT_EQ(pr.curve.size(), 2u);
  EXPECT_DOUBLE_EQ(pr.curve[0].precision, 1.0);
  EXPECT_DOUBLE_EQ(pr.curve[0].recall, 0.0);
  EXPECT_DOUBLE_EQ(pr.curve[1].recall, 1.0 / 9.0);
  EXPECT_EQ(pr.curve[1].true_positives, 2u);
  EXPECT_EQ(pr.curve[1].recalled, 1u);
}

// eval.min_travel_m: a detection at the right place but without travel in between (a drone hovering) is
// neither a true nor a false loop. It is dropped before the best-per-query choice, counted in not_judged, and
// the query's next detection is judged instead.
TEST(EvalPrecisionRecall, SamePlaceWithoutTravelIsNotJudged) {
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < 10; ++i) p.emplace_back(i, 0, 0);      // out along x: frames 0..9
  for (int k = 0; k < 10; ++k) p.emplace_back(9.0, 0, 0);    // hovering at x = 9: frames 10..19
  for (int k = 0; k < 10; ++k) p.emplace_back(9 - k, 0, 0);  // back: frames 20..29
  GroundTruthConfig config;
  config.radius_m = 0.5;
  config.gap_frames = 3;
  config.plane = CoordinatePlane::kXy;
  config.revisit.min_travel_m = 2.0;
  const auto gt = LoopGroundTruth::from_positions(p, config);
  // q15 -> 9 and q18 -> 11: the hover (x = 9, 0 m of path): not judged; q18's next detection, -> 2, is 7 m
  // away: false; q25 -> 4: x = 4 both, 10 m of path: true; q26 -> 0: false.
  const std::vector<Detection> d{{18, 11, 0.1}, {18, 2, 0.15}, {25, 4, 0.2}, {26, 0, 0.3}, {15, 9, 0.05}};
  const PrResult pr = evaluate_precision_recall(d, gt);
  EXPECT_EQ(pr.not_judged, 2u);
  EXPECT_EQ(pr.queries_with_detection, 3u);  // 18 (judged on its next detection), 25, 26
  ASSERT_EQ(pr.curve.size(), 3u);
  EXPECT_EQ(pr.curve[0].true_positives, 0u);  // q18 -> 2 at 0.15
  EXPECT_EQ(pr.curve[1].true_positives, 1u);  // q25 -> 4
  EXPECT_EQ(pr.curve[2].detections, 3u);
  // Without the travel rule the hovering pairs are true matches and judged.
  config.revisit.min_travel_m = 0.0;
  const PrResult without_rule = evaluate_precision_recall(d, LoopGroundTruth::from_positions(p, config));
  EXPECT_EQ(without_rule.not_judged, 0u);
  EXPECT_EQ(without_rule.queries_with_detection, 4u);
  EXPECT_EQ(without_rule.curve[0].true_positives, 1u);  // q15 -> 9
}

}  // namespace
}  // namespace loopgate
