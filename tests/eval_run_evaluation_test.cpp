// The evaluation block of a run from plain data: truth from positions, loops and ranked detections, gate
// coverage, aligned sequences.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "eval/run_evaluation.hpp"

namespace loopgate {
namespace {

// A straight drive out and back: frame k at x = k for k < 50, then x = 99 - k (frame 99 - k revisits k).
std::vector<Eigen::Vector3d> out_and_back() {
  std::vector<Eigen::Vector3d> p(100);
  for (int k = 0; k < 100; ++k)
    p[static_cast<std::size_t>(k)] = {static_cast<double>(k < 50 ? k : 99 - k), 0.0, 0.0};
  return p;
}

GroundTruthConfig truth_config() {
  GroundTruthConfig c;
  c.radius_m = 0.5;
  c.gap_frames = 20;
  c.plane = CoordinatePlane::kXyz;
  c.accept_radius_m = 1.5;
  return c;
}

TEST(RunEvaluation, SequenceTruthLoopsAndPrecisionRecall) {
  SequenceEvaluationInput input;
  input.p_w = out_and_back();
  input.truth = truth_config();
  input.loops = {{80, 19, 5.0}, {81, 18, 4.0}, {90, 40, 3.0}};  // two true, one false (50 m off)
  input.ranked = input.loops;
  input.score_order = ScoreOrder::kHigherIsBetter;
  const SequenceEvaluation e = evaluate_sequence(input);
  // frames 60..99 revisit 39..0 (gap >= 20: frame 60 vs 39 is 21 apart)
  EXPECT_EQ(e.json["truth"]["positives"], 40);
  EXPECT_EQ(e.json["truth"]["accept_radius_m"], 1.5);
  EXPECT_EQ(e.json["loop_truth"]["loops_true"], 2);
  EXPECT_EQ(e.json["loop_truth"]["loops_false"], 1);
  EXPECT_EQ(e.json["precision_recall"]["recall_at_100"], 2.0 / 40.0);
  EXPECT_EQ(e.truth_pairs.size(), 40u);
  EXPECT_EQ(e.truth_pairs.front(), (std::pair<std::size_t, std::size_t>{60, 39}));
}

TEST(RunEvaluation, FramesWithoutTruthAreNeverPositive) {
  SequenceEvaluationInput input;
  input.p_w = out_and_back();
  for (std::size_t k = 90; k < 100; ++k) input.p_w[k].setConstant(std::numeric_limits<double>::quiet_NaN());
  input.truth = truth_config();
  input.score_order = ScoreOrder::kHigherIsBetter;
  EXPECT_EQ(evaluate_sequence(input).json["truth"]["positives"], 30);
}

TEST(RunEvaluation, GateCoverageCountsReachablePositivesInsideAreas) {
  const auto p = out_and_back();
  // margin 30: only queries whose true reference is >= 30 back: 65..99 (65 vs 34 is 31 back)
  const auto covers = [](std::size_t q, std::size_t) { return q >= 80; };
  const auto all = [](std::size_t) { return true; };
  nlohmann::json c = gate_coverage_json(p, truth_config(), 30, all, covers);
  EXPECT_EQ(c["gap_frames"], 30);
  EXPECT_EQ(c["positive_query_frames"], 35);
  EXPECT_EQ(c["covered_query_frames"], 20);  // 80..99
  // frames the run did not process take no part
  c = gate_coverage_json(
      p, truth_config(), 30, [](std::size_t q) { return q < 90; }, covers);
  EXPECT_EQ(c["positive_query_frames"], 25);
  EXPECT_EQ(c["covered_query_frames"], 10);  // 80..89
}

// eval.truth_pairs_file: the listed pairs are the truth, with or without positions; a detection is true only
// when its pair is listed (not by distance), and gate coverage counts the listed references beyond the
// margin.
TEST(RunEvaluation, PairsAreTheTruthWhenGiven) {
  SequenceEvaluationInput input;
  input.p_w = out_and_back();  // ignored: the pairs decide
  input.truth = truth_config();
  input.pairs = std::vector<std::pair<std::size_t, std::size_t>>{{80, 19}, {81, 18}, {82, 17}, {85, 70}};
  input.frame_count = 100;
  input.pairs_truth = {{"pairs_file", "gt.csv"}, {"pairs", 4}};
  input.loops = {{80, 19, 5.0}, {81, 17, 4.0}, {85, 70, 3.0}};  // (81, 17) is 1 m off but not listed
  input.ranked = input.loops;
  input.score_order = ScoreOrder::kHigherIsBetter;
  const SequenceEvaluation e = evaluate_sequence(input);
  EXPECT_EQ(e.json["truth"]["pairs_file"], "gt.csv");
  EXPECT_FALSE(e.json["truth"].contains("radius_m"));
  EXPECT_EQ(e.json["truth"]["positives"], 4);
  EXPECT_EQ(e.json["loop_truth"]["loops_true"], 2);
  EXPECT_EQ(e.json["loop_truth"]["loops_false"], 1);
  EXPECT_EQ(e.truth_pairs.size(), 4u);
  // Coverage: only references at least 20 frames back count ((85, 70) is 15 back).
  const auto all = [](std::size_t) { return true; };
  const nlohmann::json c =
      gate_coverage_json(e.truth, 20, all, [](std::size_t q, std::size_t) { return q == 80; });
  EXPECT_EQ(c["gap_frames"], 20);
  EXPECT_EQ(c["positive_query_frames"], 3);
  EXPECT_EQ(c["covered_query_frames"], 1);
}

TEST(RunEvaluation, AlignedSequences) {
  const AlignedSequences s{10, 100, 0, 50, 2};
  EXPECT_TRUE(s.aligned(20, 8));   // query frame 20, reference frame 18
  EXPECT_FALSE(s.aligned(20, 7));  // reference frame 17
  EXPECT_EQ(s.pairs().front(), (std::pair<std::size_t, std::size_t>{8, 0}));
  const nlohmann::json e = evaluate_aligned(s, {{20, 8, 0.5}}, {{20, 8, 0.5}}, ScoreOrder::kLowerIsBetter);
  EXPECT_EQ(e["truth"]["aligned_tolerance_frames"], 2);
  EXPECT_EQ(e["loop_truth"]["loops_true"], 1);
}

}  // namespace
}  // namespace loopgate
