// SeqSLAM steps 2-5 on hand-made matrices: differences, contrast enhancement, velocity search,
// +infinity rule, second best outside the window, exclusion band, end-to-end loop.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "stages/seqslam/seqslam.hpp"

namespace loopgate {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(SeqSlamDifference, MeanAbsoluteDifferenceAndSadKernel) {
  SeqSlamImages ref(3), query(3);
  ref.add(std::vector<std::uint8_t>{0, 10, 20});
  query.add(std::vector<std::uint8_t>{5, 5, 5});
  query.add(std::vector<std::uint8_t>{0, 10, 20});
  SeqSlamMatrix D(1, 2);
  seqslam_difference_block(ref, query, {}, 0, 1, 0, 2, D);
  EXPECT_DOUBLE_EQ(D.at(0, 0), 25.0 / 3.0);
  EXPECT_DOUBLE_EQ(D.at(0, 1), 0.0);

  // The SIMD kernel equals the scalar definition, including a tail not multiple of 16.
  std::mt19937 rng(7);
  std::vector<std::uint8_t> a(2048 + 5), b(2048 + 5);
  for (auto& x : a) x = static_cast<std::uint8_t>(rng());
  for (auto& x : b) x = static_cast<std::uint8_t>(rng());
  std::uint32_t expected = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    expected += static_cast<std::uint32_t>(std::abs(int{a[i]} - int{b[i]}));
  EXPECT_EQ(seqslam_sad(a.data(), b.data(), a.size()), expected);
  EXPECT_EQ(seqslam_sad(a.data(), b.data(), 7), [&] {
    std::uint32_t s = 0;
    for (int i = 0; i < 7; ++i) s += static_cast<std::uint32_t>(std::abs(int{a[i]} - int{b[i]}));
    return s;
  }());
}

TEST(SeqSlamDifference, BlocksEqualTheWholeMatrixAndExclusionGivesInfinity) {
  std::mt19937 rng(3);
  SeqSlamImages images(64);
  for (int i = 0; i < 37; ++i) {
    std::vector<std::uint8_t> img(64);
    for (auto& x : img) x = static_cast<std::uint8_t>(rng());
    images.add(img);
  }
  const SeqSlamExclusion band(SeqSlamExclusion::Kind::kBand, 3);
  SeqSlamMatrix whole(37, 37), blocks(37, 37);
  seqslam_difference_block(images, images, band, 0, 37, 0, 37, whole);
  for (std::size_t r0 = 0; r0 < 37; r0 += 10)
    for (std::size_t q0 = 0; q0 < 37; q0 += 7)
      seqslam_difference_block(images, images, band, r0, std::min<std::size_t>(37, r0 + 10), q0,
                               std::min<std::size_t>(37, q0 + 7), blocks);
  for (std::size_t r = 0; r < 37; ++r) {
    for (std::size_t q = 0; q < 37; ++q) {
      EXPECT_EQ(whole.at(r, q), blocks.at(r, q));
      const std::size_t d = r > q ? r - q : q - r;
      if (d < 3) {
        EXPECT_EQ(whole.at(r, q), kInf) << r << "," << q;
      } else {
        EXPECT_DOUBLE_EQ(whole.at(r, q), seqslam_sad(images.image(r), images.image(q), 64) / 64.0);
      }
    }
  }
  const SeqSlamExclusion past(SeqSlamExclusion::Kind::kPast, 5);
  EXPECT_TRUE(past.excluded(10, 14));
  EXPECT_FALSE(past.excluded(9, 14));
  EXPECT_TRUE(past.excluded(20, 14));  // the future is excluded in single-sequence mode
}

TEST(SeqSlamContrast, HandComputedColumn) {
  // Column [1 3 2 6], window 2 (rows r-1..r+1):
  //   r0: [1 3] mean 2 sd sqrt(2) -> -0.70711;  r1: [1 3 2] mean 2 sd 1 -> 1;
  //   r2: [3 2 6] mean 11/3 sd sqrt(39/9) -> -0.80064;  r3: [2 6] mean 4 sd sqrt(8) -> 0.70711.
  SeqSlamMatrix M(4, 2);
  const double col[] = {1, 3, 2, 6};
  for (std::size_t r = 0; r < 4; ++r) {
    M.at(r, 0) = col[r];
    M.at(r, 1) = 5.0;  // constant column -> 0
  }
  const double minimum = seqslam_enhance_contrast(M, 2, 0, 2);
  EXPECT_NEAR(M.at(0, 0), -1.0 / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(M.at(1, 0), 1.0, 1e-12);
  EXPECT_NEAR(M.at(2, 0), (2.0 - 11.0 / 3.0) / std::sqrt(39.0 / 9.0), 1e-12);
  EXPECT_NEAR(M.at(3, 0), 2.0 / std::sqrt(8.0), 1e-12);
  for (std::size_t r = 0; r < 4; ++r) EXPECT_EQ(M.at(r, 1), 0.0);
  EXPECT_NEAR(minimum, -0.800640769, 1e-9);
  seqslam_subtract(M, minimum, 0, 2);
  EXPECT_NEAR(M.at(2, 0), 0.0, 1e-15);
  EXPECT_NEAR(M.at(1, 1), -minimum, 1e-15);
}

TEST(SeqSlamContrast, ExcludedEntriesStayInfiniteAndLeaveTheStatistics) {
  // Column [1 inf 3 2]: r0 uses [1] only (one entry -> 0); r2 uses [3 2] (mean 2.5, sd 0.7071);
  // r3 uses [3 2].
  SeqSlamMatrix M(4, 1);
  M.at(0, 0) = 1;
  M.at(1, 0) = kInf;
  M.at(2, 0) = 3;
  M.at(3, 0) = 2;
  seqslam_enhance_contrast(M, 2, 0, 1);
  EXPECT_EQ(M.at(0, 0), 0.0);
  EXPECT_EQ(M.at(1, 0), kInf);
  EXPECT_NEAR(M.at(2, 0), 0.5 / std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(M.at(3, 0), -0.5 / std::sqrt(0.5), 1e-12);
}

// 8 reference rows x 5 query columns of ones with a valley of 0.5 along rows 2, 4, 6 in columns
// 1, 2, 3 (move 4 with ds = 2). Moves 2..4: offsets (0,1,2), (0,1,3), (0,2,4).
// Scores of query 2 by start row: [3, 3, 1.5, 2, 2.5, 3, inf, inf] (s = 3: move 3 -> 1 + .5 + .5;
// s = 4: move 2 -> 1 + 1 + .5, move 4 runs beyond the last row; s >= 6: every move leaves the matrix).
SeqSlamMatrix valley_matrix() {
  SeqSlamMatrix E(8, 5, 1.0);
  E.at(2, 1) = 0.5;
  E.at(4, 2) = 0.5;
  E.at(6, 3) = 0.5;
  return E;
}

SeqSlamConfig small_config() {
  SeqSlamConfig c;
  c.sequence_length_frames = 2;
  c.velocity_min = 1.0;
  c.velocity_max = 2.0;
  c.second_best_window_rows = 2;
  c.ratio_threshold = 0.7;
  c.validate();
  return c;
}

TEST(SeqSlamSearch, VelocitySearchAndInfinityBeyondTheLastRow) {
  const SeqSlamConfig config = small_config();
  EXPECT_EQ(config.moves(), (std::vector<int>{2, 3, 4}));
  const auto scores = seqslam_sequence_scores(valley_matrix(), 2, config);
  const std::vector<double> expected{3, 3, 1.5, 2, 2.5, 3, kInf, kInf};
  ASSERT_EQ(scores.size(), expected.size());
  for (std::size_t s = 0; s < expected.size(); ++s) EXPECT_EQ(scores[s], expected[s]) << "start " << s;
}

TEST(SeqSlamSearch, BestSecondOutsideWindowAndRatio) {
  SeqSlamConfig config = small_config();
  const SeqSlamMatch m = seqslam_match_query(valley_matrix(), 2, config);
  ASSERT_TRUE(m.has_match);
  EXPECT_EQ(m.reference, 3u);  // best start 2 + ds/2
  EXPECT_EQ(m.best_score, 1.5);
  EXPECT_EQ(m.second_score, 2.5);  // rows 1..3 excluded around the best
  EXPECT_DOUBLE_EQ(m.ratio, 0.6);
  EXPECT_TRUE(m.accepted);
  config.second_best_window_rows = 4;  // rows 0..4 excluded: second = 3
  const SeqSlamMatch wide = seqslam_match_query(valley_matrix(), 2, config);
  EXPECT_EQ(wide.second_score, 3.0);
  EXPECT_DOUBLE_EQ(wide.ratio, 0.5);
  config.ratio_threshold = 0.4;
  EXPECT_FALSE(seqslam_match_query(valley_matrix(), 2, config).accepted);
}

TEST(SeqSlamSearch, EndQueriesHaveNoMatchAndTiesTakeTheFirst) {
  const SeqSlamConfig config = small_config();
  const SeqSlamMatrix E(8, 5, 1.0);  // all equal: every finite start scores 3
  EXPECT_FALSE(seqslam_match_query(E, 0, config).has_match);
  EXPECT_FALSE(seqslam_match_query(E, 4, config).has_match);
  const SeqSlamMatch m = seqslam_match_query(E, 1, config);
  ASSERT_TRUE(m.has_match);
  EXPECT_EQ(m.reference, 1u);  // start 0
  EXPECT_DOUBLE_EQ(m.ratio, 1.0);
  EXPECT_FALSE(m.accepted);
}

TEST(SeqSlamSearch, ASequenceTouchingAnExcludedEntryCannotWin) {
  const SeqSlamConfig config = small_config();
  SeqSlamMatrix E = valley_matrix();
  E.at(4, 2) = kInf;  // the middle of the valley is excluded
  const auto scores = seqslam_sequence_scores(E, 2, config);
  // Start 2: the valley (move 4, rows 2,4,6) touches the excluded entry; moves 2 and 3 give 2.5.
  EXPECT_EQ(scores[2], 2.5);
  // Start 3: moves 2 and 3 cross row 4 of column 2; move 4 (rows 3,5,7) gives 3.
  EXPECT_EQ(scores[3], 3.0);
  const SeqSlamMatch m = seqslam_match_query(E, 2, config);
  ASSERT_TRUE(m.has_match);
  EXPECT_EQ(m.best_score, 2.5);
  EXPECT_DOUBLE_EQ(m.ratio, 1.0);  // start 4 scores 2.5 too
  EXPECT_FALSE(m.accepted);
  // Everything excluded: no match.
  const SeqSlamMatrix all(8, 5, kInf);
  EXPECT_FALSE(seqslam_match_query(all, 2, config).has_match);
  // A single finite sequence: no finite second best -> ratio +inf, not accepted.
  SeqSlamMatrix one(3, 3, kInf);
  one.at(0, 0) = one.at(1, 1) = one.at(2, 2) = 0.0;
  SeqSlamConfig c1 = config;
  c1.velocity_min = c1.velocity_max = 1.0;  // move 2 only: rows s, s+1, s+2
  const SeqSlamMatch lone = seqslam_match_query(one, 1, c1);
  ASSERT_TRUE(lone.has_match);
  EXPECT_EQ(lone.reference, 1u);
  EXPECT_EQ(lone.ratio, kInf);
  EXPECT_FALSE(lone.accepted);
}

// A run that revisits its start: frames 60..79 show the places of frames 10..29 (with noise).
SeqSlamImages looping_run() {
  std::mt19937 rng(11);
  std::vector<std::vector<std::uint8_t>> places(60, std::vector<std::uint8_t>(2048));
  for (auto& p : places)
    for (auto& x : p) x = static_cast<std::uint8_t>(rng() % 136);
  SeqSlamImages run(2048);
  std::uniform_int_distribution<int> noise(-6, 6);
  for (int i = 0; i < 90; ++i) {
    const auto& place = places[static_cast<std::size_t>(i >= 60 && i < 80 ? i - 50 : (i >= 80 ? i - 30 : i))];
    std::vector<std::uint8_t> img(2048);
    for (std::size_t k = 0; k < img.size(); ++k)
      img[k] = static_cast<std::uint8_t>(std::clamp(place[k] + noise(rng), 0, 255));
    run.add(img);
  }
  return run;
}

TEST(SeqSlamRun, SingleSequenceFindsTheLoopOnlyWithTheExclusion) {
  const SeqSlamImages run = looping_run();
  SeqSlamConfig config;
  config.exclusion = SeqSlamExclusionKind::kNone;
  const auto self = SeqSlam(config).run(run);
  EXPECT_EQ(self[70].reference, 70u);  // without exclusion every frame matches itself

  config.exclusion = SeqSlamExclusionKind::kPast;
  config.exclusion_margin_frames = 20;
  const auto matches = SeqSlam(config).run(run);
  ASSERT_EQ(matches.size(), 90u);
  for (std::size_t q = 65; q <= 74; ++q) {
    ASSERT_TRUE(matches[q].has_match) << q;
    EXPECT_EQ(matches[q].reference, q - 50) << q;
    EXPECT_TRUE(matches[q].accepted) << q << " ratio " << matches[q].ratio;
  }
  for (std::size_t q = 0; q < 90; ++q) {
    if (matches[q].has_match) {
      EXPECT_LE(matches[q].reference + 20, q) << q;
    }
  }

  config.exclusion = SeqSlamExclusionKind::kBand;
  const auto band = SeqSlam(config).run(run);
  EXPECT_EQ(band[70].reference, 20u);
  EXPECT_EQ(band[20].reference, 70u);  // the band allows the future too
}

// The block functions, run column block by column block (as a parallel caller would), give
// bit-identical matches to SeqSlam::run.
TEST(SeqSlamRun, ColumnBlocksEqualTheWholeRun) {
  const SeqSlamImages run = looping_run();
  SeqSlamConfig config;
  config.exclusion = SeqSlamExclusionKind::kPast;
  config.exclusion_margin_frames = 20;
  const auto whole = SeqSlam(config).run(run);
  const std::size_t n = run.size();
  SeqSlamMatrix M(n, n);
  double minimum = kInf;
  for (std::size_t b = 0; b < n; b += 17) {
    const std::size_t e = std::min(n, b + 17);
    seqslam_difference_block(run, run, SeqSlamExclusion::from_config(config), 0, n, b, e, M);
    minimum = std::min(minimum, seqslam_enhance_contrast(M, config.contrast_window_rows, b, e));
  }
  for (std::size_t b = 0; b < n; b += 23) seqslam_subtract(M, minimum, b, std::min(n, b + 23));
  for (std::size_t q = 0; q < n; ++q) {
    const SeqSlamMatch m = seqslam_match_query(M, q, config);
    EXPECT_EQ(m.has_match, whole[q].has_match);
    EXPECT_EQ(m.reference, whole[q].reference);
    if (m.has_match) {
      EXPECT_EQ(m.ratio, whole[q].ratio) << q;
    }
  }
}

TEST(SeqSlamRun, TwoSequenceMode) {
  const SeqSlamImages run = looping_run();
  SeqSlamImages reference(2048), query(2048);
  for (std::size_t i = 0; i < 60; ++i)
    reference.add(std::vector<std::uint8_t>(run.image(i), run.image(i) + 2048));
  for (std::size_t i = 60; i < 80; ++i)
    query.add(std::vector<std::uint8_t>(run.image(i), run.image(i) + 2048));
  const auto matches = SeqSlam(SeqSlamConfig{}).run(reference, query);
  ASSERT_EQ(matches.size(), 20u);
  for (std::size_t q = 0; q < 20; ++q) {
    if (q < 5 || q >= 15) {
      EXPECT_FALSE(matches[q].has_match) << q;
    } else {
      EXPECT_EQ(matches[q].reference, q + 10) << q;
    }
  }
}

}  // namespace
}  // namespace loopgate
