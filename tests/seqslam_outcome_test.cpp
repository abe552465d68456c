// SeqSLAM's per-query result in the outputs' words, single- and two-sequence.
#include "stages/seqslam/seqslam_outcome.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace loopgate {
namespace {

SeqSlamConfig config() {
  SeqSlamConfig c;
  c.sequence_length_frames = 10;
  c.ratio_threshold = 0.9;
  c.second_best_window_rows = 10;
  c.exclusion = SeqSlamExclusionKind::kPast;
  c.exclusion_margin_frames = 200;
  return c;
}

SeqSlamMatch match(std::size_t query, bool has_match, std::size_t reference, double ratio) {
  SeqSlamMatch m;
  m.query = query;
  m.has_match = has_match;
  m.reference = reference;
  m.ratio = ratio;
  m.accepted = has_match && ratio <= 0.9;
  return m;
}

TEST(SeqSlamOutcome, SingleSequence) {
  SeqSlamOutcomeContext c;
  c.query_count = 1000;
  FrameDetection d = seqslam_detection(match(2, false, 0, 0), config(), c);
  EXPECT_EQ(d.label, "no match");
  EXPECT_EQ(d.outcome, FrameOutcome::kNoCandidate);
  EXPECT_EQ(d.reason, "within ds/2 = 5 frames of an end of the run");
  EXPECT_EQ(d.match, -1);
  d = seqslam_detection(match(500, false, 0, 0), config(), c);
  EXPECT_EQ(d.reason, "every sequence touches the exclusion (past 200 frames)");
  d = seqslam_detection(match(500, true, 120, 0.95), config(), c);
  EXPECT_EQ(d.label, "rejected");
  EXPECT_EQ(d.outcome, FrameOutcome::kBelowThreshold);
  EXPECT_EQ(d.reason, "ratio 0.9500 > 0.9000");
  EXPECT_EQ(d.match, 120);
  d = seqslam_detection(match(500, true, 120, 0.5), config(), c);
  EXPECT_EQ(d.label, "loop");
  EXPECT_EQ(d.outcome, FrameOutcome::kLoop);
  EXPECT_EQ(d.reason, "ratio 0.5000 <= 0.9000");
  EXPECT_DOUBLE_EQ(d.score, 0.5);
}

TEST(SeqSlamOutcome, GatedSingleSequence) {
  SeqSlamOutcomeContext c;
  c.query_count = 1000;
  c.gated = true;
  EXPECT_EQ(seqslam_detection(match(500, false, 0, 0), config(), c).reason,
            "every sequence matching a candidate-area cell touches the exclusion (past 200 frames)");
  c.outside_areas = true;
  const FrameDetection outside = seqslam_detection(match(2, false, 0, 0), config(), c);
  EXPECT_EQ(outside.label, "no match");
  EXPECT_EQ(outside.outcome, FrameOutcome::kNoCandidate);
  EXPECT_EQ(outside.reason, "outside every candidate area");
  c.outside_areas = false;
  EXPECT_EQ(seqslam_detection(match(500, true, 120, 0.5), config(), c).reason, "ratio 0.5000 <= 0.9000");
}

TEST(SeqSlamOutcome, TwoSequences) {
  SeqSlamOutcomeContext c;
  c.two_sequence = true;
  c.query_count = 1000;
  c.reference_count = 800;
  c.reference_first = 10;
  EXPECT_EQ(seqslam_detection(match(999, false, 0, 0), config(), c).reason,
            "within ds/2 = 5 frames of an end of the query sequence");
  const FrameDetection beyond = seqslam_detection(match(500, true, 805, 0.5), config(), c);
  EXPECT_EQ(beyond.label, "no match");
  EXPECT_EQ(beyond.reason, "best sequence centred on reference 815 beyond the last reference frame");
  EXPECT_EQ(seqslam_detection(match(500, false, 0, 0), config(), c).reason,
            "no sequence with a finite score");
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(seqslam_detection(match(500, true, 100, inf), config(), c).reason,
            "no sequence outside best +- 5 rows: no second best, no support");
}

}  // namespace
}  // namespace loopgate
