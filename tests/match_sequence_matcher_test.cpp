// Sequence DP (dird.md §3), NMS (§4), streaming == batch, two-sequence mode (§5), per-frame outcomes.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <vector>

#include "core/error.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {
namespace {

using Columns = std::vector<std::vector<SimilarityEntry>>;

// Hand-made sparse matrix: cells {j, i, value}.
Columns matrix(std::int64_t n_columns,
               const std::vector<std::tuple<std::int64_t, std::int64_t, double>>& cells) {
  Columns columns(static_cast<std::size_t>(n_columns));
  for (const auto& [j, i, v] : cells) columns[static_cast<std::size_t>(i)].push_back({j, v});
  return columns;
}

MatchConfig dp_config(int length, double tau3 = 0.0) {
  MatchConfig config;
  config.margin = 0;
  config.sequence_length = length;
  config.tau3 = tau3;
  config.max_step = 3;
  config.nms_half_window = 2;
  return config;
}

double dp_at(const std::vector<LoopClosure>& dp, std::int64_t j, std::int64_t i) {
  for (const LoopClosure& e : dp) {
    if (e.i == i && e.j == j) return e.score;
  }
  return -1.0;  // not kept
}

// Streaming run of the whole matrix; checks that each frame is reported once, in order, and not
// earlier than its NMS window closes.
MatchOutput stream(const Columns& columns, const MatchConfig& config,
                   SequenceMatcher::Mode mode = SequenceMatcher::Mode::kSingleSequence) {
  SequenceMatcher matcher(config, mode);
  MatchOutput all;
  std::int64_t reported = 0;
  for (std::size_t i = 0; i < columns.size(); ++i) {
    const MatchOutput out = matcher.push(static_cast<std::int64_t>(i), columns[i]);
    for (const FrameMatchStatus& s : out.frames) {
      EXPECT_EQ(s.i, reported++);
      EXPECT_LE(s.i + matcher.emission_delay(), static_cast<std::int64_t>(i));
    }
    EXPECT_EQ(reported,
              std::max<std::int64_t>(0, static_cast<std::int64_t>(i) - matcher.emission_delay() + 1));
    EXPECT_LE(matcher.pending_frames(), static_cast<std::size_t>(matcher.emission_delay() + 1));
    all.loops.insert(all.loops.end(), out.loops.begin(), out.loops.end());
    all.frames.insert(all.frames.end(), out.frames.begin(), out.frames.end());
  }
  const MatchOutput last = matcher.flush();
  for (const FrameMatchStatus& s : last.frames) EXPECT_EQ(s.i, reported++);
  EXPECT_EQ(reported, static_cast<std::int64_t>(columns.size()));
  EXPECT_EQ(matcher.pending_frames(), 0u);
  all.loops.insert(all.loops.end(), last.loops.begin(), last.loops.end());
  all.frames.insert(all.frames.end(), last.frames.begin(), last.frames.end());
  return all;
}

TEST(SequenceDp, DiagonalPathAndExactLength) {
  const Columns s = matrix(3, {{0, 0, 0.5}, {1, 1, 0.5}, {2, 2, 0.5}});
  const auto dp3 = sequence_dp_batch(s, dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp3, 0, 0), 0.5);  // earlier columns missing count 0
  EXPECT_DOUBLE_EQ(dp_at(dp3, 1, 1), 1.0);
  EXPECT_DOUBLE_EQ(dp_at(dp3, 2, 2), 1.5);
  const auto dp2 = sequence_dp_batch(s, dp_config(2));
  EXPECT_DOUBLE_EQ(dp_at(dp2, 2, 2), 1.0);  // exactly L = 2 cells
  const auto dp1 = sequence_dp_batch(s, dp_config(1));
  EXPECT_DOUBLE_EQ(dp_at(dp1, 2, 2), 0.5);
}

TEST(SequenceDp, StepsZeroToThreeOnly) {
  // Step 3 in j per step in i is allowed, step 4 is not.
  const auto dp_step3 = sequence_dp_batch(matrix(3, {{0, 0, 0.1}, {3, 1, 0.2}, {6, 2, 0.4}}), dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp_step3, 6, 2), 0.4 + (0.2 + 0.1));
  const auto dp_step4 = sequence_dp_batch(matrix(3, {{0, 0, 0.1}, {4, 1, 0.2}, {8, 2, 0.4}}), dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp_step4, 4, 1), 0.2);
  EXPECT_DOUBLE_EQ(dp_at(dp_step4, 8, 2), 0.4);
  // Step 0: the same earlier frame for consecutive current frames.
  const auto dp_step0 = sequence_dp_batch(matrix(3, {{2, 0, 0.1}, {2, 1, 0.1}, {2, 2, 0.1}}), dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp_step0, 2, 2), 0.1 + (0.1 + 0.1));
  // j never increases going back: from (2, 2) the path cannot use (3, 1).
  const auto dp_back = sequence_dp_batch(matrix(3, {{3, 1, 0.9}, {2, 2, 0.1}}), dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp_back, 2, 2), 0.1);
}

TEST(SequenceDp, MissingCellsCountZeroAndBestPathWins) {
  // (3, 1) is missing, so the path from (5, 2) through it collects only S(3, 0): the DP passes through
  // missing cells with value 0.
  const auto dp =
      sequence_dp_batch(matrix(3, {{3, 0, 0.9}, {2, 1, 0.1}, {5, 2, 0.1}, {2, 2, 0.1}}), dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp, 5, 2), 0.1 + (0.0 + 0.9));
  EXPECT_DOUBLE_EQ(dp_at(dp, 2, 2), 0.1 + 0.1);  // (3, 0) unreachable from row 2
  // Only stored entries get a DP value: (3, 1) has none although its H_L would be 0.9.
  EXPECT_DOUBLE_EQ(dp_at(dp, 3, 1), -1.0);
  // Best of several predecessors: max over s in 0..3.
  const auto best =
      sequence_dp_batch(matrix(2, {{4, 0, 0.2}, {5, 0, 0.7}, {6, 0, 0.3}, {6, 1, 0.1}}), dp_config(2));
  EXPECT_DOUBLE_EQ(dp_at(best, 6, 1), 0.1 + 0.7);
}

TEST(SequenceDp, BoundaryRowZero) {
  // r - s >= 0: at row 0 only s = 0 exists.
  const auto dp =
      sequence_dp_batch(matrix(3, {{0, 0, 0.3}, {0, 1, 0.3}, {0, 2, 0.3}, {1, 2, 0.2}}), dp_config(3));
  EXPECT_DOUBLE_EQ(dp_at(dp, 0, 2), 0.3 + (0.3 + 0.3));
  EXPECT_DOUBLE_EQ(dp_at(dp, 1, 2), 0.2 + (0.3 + 0.3));
}

TEST(SequenceDp, ThresholdIsStrict) {
  const Columns s = matrix(3, {{0, 0, 0.5}, {1, 1, 0.5}, {2, 2, 0.5}});
  const auto dp = sequence_dp_batch(s, dp_config(2, 0.5));  // keep DP > 1.0
  EXPECT_DOUBLE_EQ(dp_at(dp, 2, 2), -1.0);                  // DP = 1.0 exactly: not kept
  const auto dp_low = sequence_dp_batch(s, dp_config(2, 0.49));
  EXPECT_DOUBLE_EQ(dp_at(dp_low, 2, 2), 1.0);
}

TEST(Nms, SecondLargestRuleInsideWindow) {
  // One anti-diagonal j + i = 30, W = 2.
  const std::vector<LoopClosure> dp = {{20, 10, 5.0}, {21, 9, 3.0}, {22, 8, 4.0}};
  const auto kept = nms_batch(dp, 2);
  EXPECT_EQ(kept, (std::vector<LoopClosure>{{20, 10, 5.0}, {22, 8, 4.0}}));
}

TEST(Nms, WindowEdgesAndOtherDiagonals) {
  // (23, 7) is 3 cells away from (20, 10): outside its window with W = 2, inside that of (21, 9).
  const std::vector<LoopClosure> dp = {{20, 10, 5.0}, {21, 9, 3.0}, {23, 7, 4.0}, {21, 10, 1.0}};
  const auto kept = nms_batch(dp, 2);
  // (21, 9) is suppressed when (21, 9) itself is visited (tau = 4); (21, 10) is on another diagonal.
  EXPECT_EQ(kept, (std::vector<LoopClosure>{{20, 10, 5.0}, {21, 10, 1.0}, {23, 7, 4.0}}));
  // With W = 1 nothing interacts except neighbours: 5, 3 are a pair (tau = 3), 4 is alone.
  EXPECT_EQ(nms_batch(dp, 1).size(), 4u);
  // With W = 0 the window is the entry itself: nothing is suppressed.
  EXPECT_EQ(nms_batch(dp, 0).size(), 4u);
}

TEST(Nms, Ties) {
  EXPECT_EQ(nms_batch(std::vector<LoopClosure>{{20, 10, 5.0}, {21, 9, 5.0}, {22, 8, 5.0}}, 2).size(), 3u);
  EXPECT_EQ(nms_batch(std::vector<LoopClosure>{{20, 10, 5.0}, {21, 9, 5.0}, {22, 8, 3.0}}, 2),
            (std::vector<LoopClosure>{{20, 10, 5.0}, {21, 9, 5.0}}));
  // Second largest counts ties: {5, 3, 3} -> tau 3, nothing below it.
  EXPECT_EQ(nms_batch(std::vector<LoopClosure>{{20, 10, 5.0}, {21, 9, 3.0}, {22, 8, 3.0}}, 2).size(), 3u);
}

TEST(Nms, VisitOrderIsAscendingCurrentFrame) {
  // Along one anti-diagonal with W = 1: 10, 9, 8, 7 at i = 10..13. Ascending i: visiting i = 11 zeroes
  // 8 (tau 9); then i = 12 sees {9, 0, 7} (tau 7) and i = 13 sees {0, 7}: 7 survives. (The opposite
  // order would also remove 7.) Zeroed entries are still visited.
  const std::vector<LoopClosure> dp = {{10, 10, 10.0}, {11, 9, 9.0}, {12, 8, 8.0}, {13, 7, 7.0}};
  EXPECT_EQ(nms_batch(dp, 1), (std::vector<LoopClosure>{{10, 10, 10.0}, {11, 9, 9.0}, {13, 7, 7.0}}));
}

TEST(SequenceMatcher, StreamingNmsMatchesHandCases) {
  // L = 1, tau3 = 0: DP = S, so the streaming matcher runs the NMS of the hand cases above.
  MatchConfig config = dp_config(1);
  const Columns s = matrix(24, {{10, 20, 0.5}, {9, 21, 0.3}, {8, 22, 0.4}, {3, 5, 0.2}});
  const MatchOutput out = stream(s, config);
  EXPECT_EQ(out.loops, (std::vector<LoopClosure>{{5, 3, 0.2}, {20, 10, 0.5}, {22, 8, 0.4}}));
  ASSERT_EQ(out.frames.size(), 24u);
  EXPECT_EQ(out.frames[0].outcome, FrameOutcome::kNoCandidate);
  EXPECT_EQ(out.frames[5].outcome, FrameOutcome::kLoop);
  EXPECT_EQ(out.frames[20].outcome, FrameOutcome::kLoop);
  EXPECT_EQ(out.frames[21].outcome, FrameOutcome::kSuppressed);
  EXPECT_EQ(out.frames[21].above_threshold, 1u);
  EXPECT_EQ(out.frames[21].loops, 0u);
  EXPECT_EQ(out.frames[22].loops, 1u);
  EXPECT_STREQ(to_string(out.frames[21].outcome), "suppressed");
  EXPECT_STREQ(to_string(out.frames[0].outcome), "no candidate");
  EXPECT_STREQ(to_string(FrameOutcome::kBelowThreshold), "below threshold");
  EXPECT_STREQ(to_string(FrameOutcome::kLoop), "loop");
}

TEST(SequenceMatcher, BelowThresholdOutcome) {
  MatchConfig config = dp_config(2, 0.5);  // DP > 1.0
  const Columns s = matrix(4, {{0, 2, 0.4}, {1, 3, 0.4}, {0, 3, 0.9}});
  const MatchOutput out = stream(s, config);
  ASSERT_EQ(out.frames.size(), 4u);
  EXPECT_EQ(out.frames[2].outcome, FrameOutcome::kBelowThreshold);
  EXPECT_EQ(out.frames[2].candidates, 1u);
  EXPECT_DOUBLE_EQ(out.frames[2].best_similarity, 0.4);
  EXPECT_DOUBLE_EQ(out.frames[2].best_score, 0.4);
  EXPECT_EQ(out.frames[3].outcome, FrameOutcome::kLoop);  // (0, 3): 0.9 + 0.4 = 1.3
  EXPECT_EQ(out.loops, (std::vector<LoopClosure>{{3, 0, 0.9 + 0.4}}));
  EXPECT_DOUBLE_EQ(out.frames[3].best_score, 1.3);
}

TEST(SequenceMatcher, InputChecks) {
  MatchConfig config = dp_config(3);
  config.margin = 5;
  SequenceMatcher matcher(config);
  const std::vector<SimilarityEntry> none;
  EXPECT_THROW(matcher.push(1, none), std::invalid_argument);  // frames start at 0
  matcher.push(0, none);
  const std::vector<SimilarityEntry> inside_margin = {{3, 0.5}};
  EXPECT_THROW(matcher.push(1, inside_margin), std::invalid_argument);
  for (std::int64_t i = 1; i < 10; ++i) matcher.push(i, none);
  const std::vector<SimilarityEntry> duplicate = {{1, 0.5}, {1, 0.6}};
  EXPECT_THROW(matcher.push(10, duplicate), std::invalid_argument);
  const std::vector<SimilarityEntry> negative = {{-1, 0.5}};
  EXPECT_THROW(matcher.push(10, negative), std::invalid_argument);
  const std::vector<SimilarityEntry> ok = {{5, 0.5}, {0, 0.6}};  // unsorted is fine
  EXPECT_NO_THROW(matcher.push(10, ok));
  // Two-sequence mode has no margin: any reference index is fine.
  SequenceMatcher two(config, SequenceMatcher::Mode::kTwoSequence);
  const std::vector<SimilarityEntry> ahead = {{50, 0.5}};
  EXPECT_NO_THROW(two.push(0, ahead));
}

TEST(SequenceMatcher, StreamingEqualsBatchOnRandomMatrices) {
  std::mt19937 rng(2024);
  for (int trial = 0; trial < 24; ++trial) {
    MatchConfig config;
    config.margin = std::uniform_int_distribution<int>(0, 12)(rng);
    config.sequence_length = std::uniform_int_distribution<int>(1, 8)(rng);
    config.max_step = std::uniform_int_distribution<int>(0, 4)(rng);
    config.nms_half_window = std::uniform_int_distribution<int>(0, 9)(rng);
    config.tau3 = std::uniform_real_distribution<double>(0.0, 0.3)(rng);
    const int n = std::uniform_int_distribution<int>(30, 260)(rng);
    const double density = std::uniform_real_distribution<double>(0.01, 0.3)(rng);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    Columns columns(static_cast<std::size_t>(n));
    // Random noise plus a few diagonal "revisit" runs so that NMS windows have chains.
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j <= i - config.margin; ++j) {
        if (unit(rng) < density) columns[static_cast<std::size_t>(i)].push_back({j, unit(rng)});
      }
    }
    for (int run = 0; run < 3; ++run) {
      const int start_i = std::uniform_int_distribution<int>(config.margin, n - 1)(rng);
      int j = std::uniform_int_distribution<int>(0, std::max(0, start_i - config.margin))(rng);
      for (int i = start_i; i < n && j <= i - config.margin;
           ++i, j += std::uniform_int_distribution<int>(0, 2)(rng)) {
        auto& column = columns[static_cast<std::size_t>(i)];
        bool present = false;
        for (auto& e : column) {
          if (e.j == j) {
            e.similarity = 0.9;
            present = true;
          }
        }
        if (!present) column.push_back({j, 0.9});
      }
    }
    for (auto& column : columns) std::shuffle(column.begin(), column.end(), rng);

    const std::vector<LoopClosure> dp = sequence_dp_batch(columns, config);
    const std::vector<LoopClosure> batch = nms_batch(dp, config.nms_half_window);
    const MatchOutput streamed = stream(columns, config);
    ASSERT_EQ(streamed.loops, batch) << "trial " << trial;
    EXPECT_LT(batch.size(), dp.size() + 1);
    // Per-frame outcomes agree with the batch quantities.
    std::map<std::int64_t, std::size_t> dp_per_frame, loops_per_frame;
    for (const LoopClosure& e : dp) ++dp_per_frame[e.i];
    for (const LoopClosure& e : batch) ++loops_per_frame[e.i];
    for (const FrameMatchStatus& f : streamed.frames) {
      const auto& column = columns[static_cast<std::size_t>(f.i)];
      EXPECT_EQ(f.candidates, column.size());
      EXPECT_EQ(f.above_threshold, dp_per_frame[f.i]);
      EXPECT_EQ(f.loops, loops_per_frame[f.i]);
      const FrameOutcome expected = column.empty()              ? FrameOutcome::kNoCandidate
                                    : dp_per_frame[f.i] == 0    ? FrameOutcome::kBelowThreshold
                                    : loops_per_frame[f.i] == 0 ? FrameOutcome::kSuppressed
                                                                : FrameOutcome::kLoop;
      EXPECT_EQ(f.outcome, expected);
    }
  }
}

TEST(SequenceMatcher, LongRunStaysBounded) {
  // 6 000 frames with a revisit band: pending frames never exceed the emission delay + 1.
  MatchConfig config;  // KITTI reference values
  SequenceMatcher matcher(config);
  std::size_t loops = 0;
  std::vector<SimilarityEntry> entries;
  for (std::int64_t i = 0; i < 6000; ++i) {
    entries.clear();
    if (i >= 1000) entries.push_back({i - 1000, 0.8});
    if (i >= 300) entries.push_back({(i * 7919) % (i - 299), 0.06});
    loops += matcher.push(i, entries).loops.size();
    ASSERT_LE(matcher.pending_frames(), 119u);
  }
  loops += matcher.flush().loops.size();
  EXPECT_GT(loops, 100u);
}

TEST(TwoSequences, QueryFindsItsReferenceSegment) {
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<Descriptor> reference(120);
  for (auto& d : reference) {
    for (auto& b : d) b = static_cast<std::uint8_t>(byte(rng));
  }
  std::vector<Descriptor> query;
  std::uniform_int_distribution<int> noise(-3, 3);
  for (std::size_t q = 0; q < 50; ++q) {
    Descriptor d = reference[q + 30];
    for (auto& b : d) b = static_cast<std::uint8_t>(std::clamp(static_cast<int>(b) + noise(rng), 0, 255));
    query.push_back(d);
  }
  DirdConfig dird;
  dird.mu = 20000.0;  // noisy copies are ~5 000 apart, random descriptors ~290 000
  dird.sigma = 2000.0;
  MatchConfig config;
  config.sequence_length = 5;
  config.nms_half_window = 3;
  config.margin = 200;  // ignored in two-sequence mode
  std::vector<FrameMatchStatus> statuses;
  const std::vector<LoopClosure> loops =
      match_two_sequences(reference, query, DirdSimilarity(dird), config, &statuses);
  ASSERT_EQ(loops.size(), 50u);
  for (std::size_t q = 0; q < loops.size(); ++q) {
    EXPECT_EQ(loops[q].i, static_cast<std::int64_t>(q));
    EXPECT_EQ(loops[q].j, static_cast<std::int64_t>(q) + 30);
    EXPECT_NEAR(loops[q].score, static_cast<double>(std::min<std::size_t>(q + 1, 5)), 0.01);
  }
  ASSERT_EQ(statuses.size(), 50u);
  EXPECT_EQ(statuses[10].outcome, FrameOutcome::kLoop);
}

TEST(MatchConfig, ValidateNamesKeys) {
  MatchConfig config;
  EXPECT_NO_THROW(config.validate());
  EXPECT_DOUBLE_EQ(config.dp_threshold(), 1.0);
  config.sequence_length = 0;
  try {
    config.validate();
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("match.sequence_length"), std::string::npos);
  }
  config = MatchConfig{};
  config.margin = -1;
  EXPECT_THROW(config.validate(), ConfigError);
  config = MatchConfig{};
  config.nms_half_window = -1;
  EXPECT_THROW(config.validate(), ConfigError);
  config = MatchConfig{};
  config.max_step = -1;
  EXPECT_THROW(config.validate(), ConfigError);
  std::vector<std::string> keys;
  MatchConfig::fields(config, [&](const char* key, auto&) { keys.emplace_back(key); });
  EXPECT_EQ(keys,
            (std::vector<std::string>{"margin", "sequence_length", "tau3", "max_step", "nms_half_window"}));
}

}  // namespace
}  // namespace loopgate
