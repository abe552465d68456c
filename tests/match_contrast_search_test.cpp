// ContrastSequenceSearch (stages/match/contrast_search.hpp): the contrast of a row against a hand
// computation, the streaming search against the batch reference on random sparse rows, what it is for (a
// revisit whose distances are all larger than everything else's: an illumination change), the cover of a
// revisit's first frames, and the input and configuration it refuses.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>

#include "core/error.hpp"
#include "stages/match/contrast_search.hpp"

namespace loopgate {
namespace {

using Mode = ContrastSequenceSearch::Mode;

ContrastOutput run_streaming(const std::vector<std::vector<DistanceEntry>>& rows,
                             const ContrastSearchConfig& c, int length, Mode mode, int margin) {
  ContrastSequenceSearch search(c, length, mode, margin, 0);
  ContrastOutput out;
  for (std::size_t i = 0; i < rows.size(); ++i) search.push(static_cast<std::int64_t>(i), rows[i], out);
  search.flush(out);
  return out;
}

void expect_same(const ContrastOutput& a, const ContrastOutput& b) {
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (std::size_t k = 0; k < a.frames.size(); ++k) {
    const ContrastVerdict &x = a.frames[k], &y = b.frames[k];
    EXPECT_EQ(x.i, y.i);
    EXPECT_EQ(x.outcome, y.outcome) << "query " << x.i;
    EXPECT_EQ(x.best_j, y.best_j) << "query " << x.i;
    EXPECT_EQ(x.score, y.score) << "query " << x.i;  // same arithmetic, same order: bit-identical
    EXPECT_EQ(x.velocity, y.velocity) << "query " << x.i;
    EXPECT_EQ(x.line_end, y.line_end) << "query " << x.i;
    EXPECT_EQ(x.cells, y.cells) << "query " << x.i;
    EXPECT_EQ(x.defined, y.defined) << "query " << x.i;
  }
  ASSERT_EQ(a.loops.size(), b.loops.size());
  for (std::size_t k = 0; k < a.loops.size(); ++k) EXPECT_EQ(a.loops[k], b.loops[k]);
}

TEST(ContrastSearch, ContrastOfARowIsTheHandComputation) {
  // Distances at references 0, 1, 2, 4 (3 missing), window w = 1, at least 2 distances.
  const std::vector<DistanceEntry> row = {{0, 10.0}, {1, 4.0}, {2, 10.0}, {4, 7.0}};
  const std::vector<float> z = contrast_enhance_row(row, 1, 2);
  ASSERT_EQ(z.size(), 4u);
  // j = 0: window {0, 1}: mean 7, population stddev 3 -> (7 - 10) / 3 = -1.
  EXPECT_NEAR(z[0], -1.0, 1e-6);
  // j = 1: window {0, 1, 2}: mean 8, stddev sqrt(8) -> (8 - 4) / sqrt(8).
  EXPECT_NEAR(z[1], 4.0 / std::sqrt(8.0), 1e-6);
  // j = 2: window {1, 2} (3 missing): mean 7, stddev 3 -> -1.
  EXPECT_NEAR(z[2], -1.0, 1e-6);
  // j = 4: window {4} alone (3 missing, 5 beyond the row): fewer than 2 -> undefined.
  EXPECT_TRUE(std::isnan(z[3]));
  // Equal distances have no contrast.
  const std::vector<DistanceEntry> flat = {{0, 5.0}, {1, 5.0}, {2, 5.0}};
  for (const float v : contrast_enhance_row(flat, 1, 2)) EXPECT_TRUE(std::isnan(v));
}

TEST(ContrastSearch, StreamingEqualsTheBatchReferenceOnRandomSparseRows) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    ContrastSearchConfig c;
    c.contrast_half_window_frames = 1 + trial % 6;
    c.contrast_min_cells = 2 + trial % 3;
    c.velocity_min = 0.7 + 0.05 * (trial % 3);
    c.velocity_max = c.velocity_min + 0.6;
    c.velocity_steps = 2 + trial % 5;
    c.min_score = 0.3 + 0.1 * (trial % 4);
    const int length = 1 + trial % 9;
    const Mode mode = trial % 2 ? Mode::kTwoSequence : Mode::kSingleSequence;
    const int margin = mode == Mode::kSingleSequence ? 5 + trial % 7 : 0;
    const std::size_t n = 60 + static_cast<std::size_t>(trial) * 3;
    std::uniform_real_distribution<double> distance(100.0, 200.0);
    std::uniform_int_distribution<int> coin(0, 9);
    std::vector<std::vector<DistanceEntry>> rows(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::int64_t j_max = mode == Mode::kSingleSequence ? static_cast<std::int64_t>(i) - margin : 80;
      for (std::int64_t j = 0; j <= j_max; ++j) {
        if (coin(rng) < 3) continue;  // sparse, with holes
        double d = distance(rng);
        if (j == static_cast<std::int64_t>(i) / 2) d -= 60.0;  // a faint diagonal
        rows[i].push_back({j, d});
      }
      std::shuffle(rows[i].begin(), rows[i].end(), rng);  // any order
    }
    SCOPED_TRACE(trial);
    expect_same(run_streaming(rows, c, length, mode, margin),
                contrast_search_batch(rows, c, length, mode, margin));
  }
}

// A revisit at "night": from query 300 on, every distance is 10x larger and noisier than by day, the revisit
// (query i matches reference i - 250) only 8% closer than the other references of its row. An absolute scale
// fitted to the day rejects all of it; the contrast search finds every query of the revisit.
TEST(ContrastSearch, FindsARevisitWhoseDistancesAreAllLargerThanTheDays) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 1.0);
  const int margin = 50, n = 400;
  std::vector<std::vector<DistanceEntry>> rows(n);
  for (int i = 0; i < n; ++i) {
    const bool night = i >= 300;
    for (int j = 0; j <= i - margin; ++j) {
      const double base = night ? 1000.0 : 100.0, spread = night ? 20.0 : 2.0;
      double d = base + spread * noise(rng);
      if (night && j == i - 250) d = 0.92 * base + spread * noise(rng);
      rows[static_cast<std::size_t>(i)].push_back({j, d});
    }
  }
  ContrastSearchConfig c;
  const ContrastOutput out = run_streaming(rows, c, 20, Mode::kSingleSequence, margin);
  ASSERT_EQ(out.frames.size(), static_cast<std::size_t>(n));
  int found = 0;
  for (int i = 300; i < n; ++i) {
    const ContrastVerdict& v = out.frames[static_cast<std::size_t>(i)];
    if (v.outcome == FrameOutcome::kLoop && std::abs(v.best_j - (i - 250)) <= 1) ++found;
  }
  EXPECT_EQ(found, 100);  // the first frames of the revisit too (cover)
  // By day (no revisit) nothing reaches the threshold.
  for (int i = 0; i < 280; ++i)
    EXPECT_NE(out.frames[static_cast<std::size_t>(i)].outcome, FrameOutcome::kLoop) << i;
}

TEST(ContrastSearch, TheFirstFramesOfARevisitAreMatchedByTheLinesThatEndLater) {
  // Two-sequence rows: query q matches reference q + 100 from query 40 on; before, no match anywhere.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> distance(50.0, 60.0);
  const int n = 100, refs = 300, length = 10;
  std::vector<std::vector<DistanceEntry>> rows(n);
  for (int q = 0; q < n; ++q) {
    for (int r = 0; r < refs; ++r) {
      const double d = q >= 40 && r == q + 100 ? 20.0 : distance(rng);
      rows[static_cast<std::size_t>(q)].push_back({r, d});
    }
  }
  ContrastSearchConfig c;
  c.velocity_min = c.velocity_max = 1.0;
  c.velocity_steps = 1;
  const ContrastOutput out = run_streaming(rows, c, length, Mode::kTwoSequence, 0);
  for (int q = 40; q < 40 + length; ++q) {  // the lines ending at q only partly cross the revisit
    const ContrastVerdict& v = out.frames[static_cast<std::size_t>(q)];
    EXPECT_EQ(v.best_j, q + 100) << q;
    EXPECT_GE(v.line_end, 40 + length - 1) << q;  // matched by a line lying wholly in the revisit
    EXPECT_EQ(v.outcome, FrameOutcome::kLoop) << q;
  }
}

TEST(ContrastSearch, RefusesRowsOutOfOrderOrWithBadEntries) {
  ContrastSearchConfig c;
  ContrastOutput out;
  {
    ContrastSequenceSearch s(c, 5, Mode::kSingleSequence, 10);
    EXPECT_THROW(s.push(1, {}, out), std::invalid_argument);  // expected row 0
    s.push(0, {}, out);
    const std::vector<DistanceEntry> within = {{5, 1.0}};  // 11 - 5 < margin 10
    for (int i = 1; i < 11; ++i) s.push(i, {}, out);
    EXPECT_THROW(s.push(11, within, out), std::invalid_argument);
  }
  ContrastSequenceSearch s(c, 5, Mode::kTwoSequence, 0);
  const std::vector<DistanceEntry> twice = {{3, 1.0}, {3, 2.0}};
  EXPECT_THROW(s.push(0, twice, out), std::invalid_argument);
  const std::vector<DistanceEntry> nan = {{3, std::nan("")}};
  EXPECT_THROW(s.push(0, nan, out), std::invalid_argument);
  const std::vector<DistanceEntry> negative = {{-1, 1.0}};
  EXPECT_THROW(s.push(0, negative, out), std::invalid_argument);
}

TEST(ContrastSearch, ConfigErrorsNameTheKey) {
  const auto expect_key = [](ContrastSearchConfig c, const char* key) {
    try {
      c.validate();
      FAIL() << key << " accepted";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  };
  ContrastSearchConfig c;
  c.contrast_half_window_frames = 0;
  expect_key(c, "dird_seqslam.contrast_half_window_frames");
  c = {};
  c.contrast_min_cells = 100;
  expect_key(c, "dird_seqslam.contrast_min_cells");
  c = {};
  c.velocity_min = 0;
  expect_key(c, "dird_seqslam.velocity_min");
  c = {};
  c.velocity_max = 0.5;
  expect_key(c, "dird_seqslam.velocity_max");
  c = {};
  c.velocity_steps = 1;
  expect_key(c, "dird_seqslam.velocity_steps");
  c = {};
  c.min_score = std::nan("");
  expect_key(c, "dird_seqslam.min_score");
  // The velocity grid: geometric, both ends exact, 1.0 in the middle of 2/3 .. 3/2.
  const std::vector<double> v = ContrastSearchConfig{}.velocities();
  ASSERT_EQ(v.size(), 7u);
  EXPECT_EQ(v.front(), 2.0 / 3.0);
  EXPECT_EQ(v.back(), 1.5);
  EXPECT_NEAR(v[3], 1.0, 1e-12);
}

}  // namespace
}  // namespace loopgate
