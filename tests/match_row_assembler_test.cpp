// RowAssembler: rows open for the horizon, released in order (empty rows too), cells for a released row
// rejected, and the matcher's result equal to the batch matcher on the assembled rows.
#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <vector>

#include "stages/match/row_assembler.hpp"

namespace loopgate {
namespace {

MatchConfig small_config() {
  MatchConfig config;
  config.margin = 5;
  config.sequence_length = 3;
  config.tau3 = 0.0;
  config.max_step = 2;
  config.nms_half_window = 2;
  return config;
}

TEST(RowAssembler, ReleasesRowsOnceTheyAreOlderThanTheHorizon) {
  SequenceMatcher matcher(small_config());
  RowAssembler rows(4);
  MatchOutput out;
  rows.advance(0, matcher, out);
  rows.advance(2, matcher, out);
  EXPECT_EQ(rows.next_row(), 0);  // frame 2: rows <= 2 - 4 are final: none
  rows.advance(3, matcher, out);
  EXPECT_EQ(rows.next_row(), 0);  // rows <= -1
  rows.advance(4, matcher, out);
  EXPECT_EQ(rows.next_row(), 1);  // row 0 went to the matcher
  EXPECT_EQ(matcher.next_frame(), 1);
  rows.advance(10, matcher, out);
  EXPECT_EQ(rows.next_row(), 7);
  EXPECT_EQ(matcher.next_frame(), 7);
}

TEST(RowAssembler, CellsForAReleasedRowAreALogicError) {
  SequenceMatcher matcher(small_config());
  RowAssembler rows(2);
  MatchOutput out;
  rows.row(5).push_back({0, 0.5});
  rows.advance(5, matcher, out);  // rows <= 3 released
  EXPECT_THROW(rows.row(3), std::logic_error);
  EXPECT_NO_THROW(rows.row(4));
  EXPECT_EQ(rows.open_rows(), 2u);  // rows 4 and 5
  rows.advance(7, matcher, out);    // rows 4 and 5 go out, row 5 with its cell
  EXPECT_EQ(rows.open_rows(), 0u);
  EXPECT_EQ(matcher.next_frame(), 6);
}

TEST(RowAssembler, RejectsAHorizonBelowOne) {
  EXPECT_THROW(RowAssembler(0), std::invalid_argument);
}

// Cells arriving late (up to the horizon after their row) give the same loops as the batch matcher on the
// complete rows.
TEST(RowAssembler, LateCellsGiveTheBatchResult) {
  const MatchConfig config = small_config();
  const std::int64_t n = 120, horizon = 6;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> value(0.05, 1.0);
  std::uniform_int_distribution<int> delay(0, static_cast<int>(horizon) - 1);
  std::vector<std::vector<SimilarityEntry>> columns(static_cast<std::size_t>(n));
  // arrivals[t]: (row, entry) delivered at frame t
  std::vector<std::vector<std::pair<std::int64_t, SimilarityEntry>>> arrivals(static_cast<std::size_t>(n));
  for (std::int64_t i = config.margin; i < n; ++i) {
    for (std::int64_t j = 0; j <= i - config.margin; j += 3) {
      if (value(rng) < 0.6) continue;
      const SimilarityEntry e{j, value(rng)};
      columns[static_cast<std::size_t>(i)].push_back(e);
      const std::int64_t t = std::min(n - 1, i + delay(rng));
      arrivals[static_cast<std::size_t>(t)].push_back({i, e});
    }
  }
  SequenceMatcher matcher(config);
  RowAssembler rows(horizon);
  MatchOutput out;
  for (std::int64_t t = 0; t < n; ++t) {
    for (const auto& [i, e] : arrivals[static_cast<std::size_t>(t)]) rows.row(i).push_back(e);
    rows.advance(t, matcher, out);
  }
  rows.finish(n, matcher, out);
  matcher.flush(out);
  EXPECT_EQ(out.loops, match_batch(columns, config));
  EXPECT_EQ(out.frames.size(), static_cast<std::size_t>(n));
}

}  // namespace
}  // namespace loopgate
