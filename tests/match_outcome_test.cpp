// The matcher's per-frame status in the outputs' words (frames.csv detection, match, score, reason).
#include "stages/match/match_outcome.hpp"

#include <gtest/gtest.h>

namespace loopgate {
namespace {

FrameMatchStatus status(FrameOutcome outcome) {
  FrameMatchStatus s;
  s.i = 300;
  s.outcome = outcome;
  s.candidates = 12;
  s.best_similarity = 0.25;
  s.best_score = 0.75;
  s.best_j = 40;
  s.above_threshold = 3;
  s.loops = 1;
  return s;
}

MatchOutcomeContext single() {
  MatchOutcomeContext c;
  c.margin_frames = 200;
  c.tau1 = 0.05;
  c.dp_threshold = 1.0;
  return c;
}

TEST(MatchOutcome, NoCandidateSaysWhyInOrder) {
  FrameMatchStatus s = status(FrameOutcome::kNoCandidate);
  s.best_j = -1;
  MatchOutcomeContext c = single();
  EXPECT_EQ(match_detection(s, c).reason, "no similarity above tau1 = 0.05");
  c.before_margin = true;
  EXPECT_EQ(match_detection(s, c).reason, "no earlier frame beyond the margin of 200");
  c.described = false;
  EXPECT_EQ(match_detection(s, c).reason, "no descriptor (image not decoded)");
  c.outside_areas = true;
  const FrameDetection d = match_detection(s, c);
  EXPECT_EQ(d.reason, "outside every candidate area");
  EXPECT_EQ(d.label, "no candidate");
  EXPECT_EQ(d.outcome, FrameOutcome::kNoCandidate);
  EXPECT_EQ(d.match, -1);
}

TEST(MatchOutcome, SingleSequenceReasons) {
  const MatchOutcomeContext c = single();
  const FrameDetection below = match_detection(status(FrameOutcome::kBelowThreshold), c);
  EXPECT_EQ(below.label, "below threshold");
  EXPECT_EQ(below.reason, "12 candidates, best similarity 0.2500; best DP 0.7500 <= 1.0000");
  EXPECT_EQ(below.match, 40);
  EXPECT_DOUBLE_EQ(below.score, 0.75);
  EXPECT_EQ(match_detection(status(FrameOutcome::kSuppressed), c).reason,
            "3 DP values above 1.0000, all suppressed by NMS");
  const FrameDetection loop = match_detection(status(FrameOutcome::kLoop), c);
  EXPECT_EQ(loop.label, "loop");
  EXPECT_EQ(loop.reason, "1 loop closure(s) of 3 DP values above 1.0000");
}

TEST(MatchOutcome, TwoSequenceReasonsAreShorter) {
  MatchOutcomeContext c = single();
  c.two_sequence = true;
  EXPECT_EQ(match_detection(status(FrameOutcome::kBelowThreshold), c).reason, "best DP 0.7500 <= 1.0000");
  EXPECT_EQ(match_detection(status(FrameOutcome::kLoop), c).reason, "1 loop closure(s)");
}

}  // namespace
}  // namespace loopgate
