// Streaming clustering of gated frames into candidate areas: holes, inconsistent j, margins, clamping,
// newly covered cells and the lazy descriptor requests (each frame at most once).
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "stages/gate/candidate_areas.hpp"

namespace loopgate {
namespace {

GateDecision gated(std::int64_t i, std::int64_t j) {
  GateDecision d;
  d.frame = i;
  d.has_nearest = true;
  d.nearest_frame = j;
  d.distance_m = 1.0;
  d.threshold_m = 2.0;
  d.gated = true;
  return d;
}

GateDecision not_gated(std::int64_t i) {
  GateDecision d;
  d.frame = i;
  d.has_nearest = i > 40;
  d.nearest_frame = d.has_nearest ? 0 : -1;
  d.distance_m = 9.0;
  d.threshold_m = 2.0;
  return d;
}

GateConfig small_config() {
  GateConfig c;
  c.area_max_hole_frames = 2;
  c.area_j_tolerance_frames = 5;
  c.area_margin_query_frames = 4;
  c.area_margin_reference_frames = 3;
  return c;
}

using Cell = std::pair<std::int64_t, std::int64_t>;

std::set<Cell> cells_of(const std::vector<CellSpan>& spans) {
  std::set<Cell> out;
  for (const CellSpan& s : spans)
    for (std::int64_t j = s.j0; j <= s.j1; ++j) EXPECT_TRUE(out.insert({s.i, j}).second);
  return out;
}

TEST(CandidateAreas, OneClusterGrowsWithMargins) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  for (std::int64_t i = 0; i < 100; ++i) {
    const AreaUpdate u = tracker.update(not_gated(i));
    EXPECT_EQ(u.joined_area, -1);
    EXPECT_TRUE(u.new_cells.empty());
  }
  const AreaUpdate first = tracker.update(gated(100, 20));
  EXPECT_TRUE(first.opened);
  EXPECT_EQ(first.joined_area, 0);
  // Rows [96, 100] x columns [17, 23], each row all of it (i - 10 >= 23).
  EXPECT_EQ(first.new_cells.size(), 5u);
  EXPECT_EQ(cells_of(first.new_cells).size(), 5u * 7u);
  for (std::int64_t i = 101; i <= 104; ++i) {
    const AreaUpdate u = tracker.update(gated(i, 20 + (i - 100)));
    EXPECT_FALSE(u.opened);
    EXPECT_EQ(u.joined_area, 0);
  }
  ASSERT_EQ(tracker.areas().size(), 1u);
  const CandidateArea& a = tracker.areas()[0];
  EXPECT_EQ(a.i_first, 100);
  EXPECT_EQ(a.i_last, 104);
  EXPECT_EQ(a.j_min, 20);
  EXPECT_EQ(a.j_max, 24);
  EXPECT_EQ(a.gated_frames, 5);
  EXPECT_EQ(a.row_begin, 96);
  EXPECT_EQ(a.row_end, 104);
  EXPECT_EQ(a.col_begin, 17);
  EXPECT_EQ(a.col_end, 27);
  EXPECT_TRUE(a.open);
  const auto row = tracker.columns_for_row(97);
  ASSERT_EQ(row.size(), 1u);
  EXPECT_EQ(row[0].area_id, 0);
  EXPECT_EQ(row[0].j0, 17);
  EXPECT_EQ(row[0].j1, 27);
  EXPECT_TRUE(tracker.columns_for_row(95).empty());
  EXPECT_TRUE(tracker.columns_for_row(105).empty());
  EXPECT_TRUE(tracker.covers(96, 27));
  EXPECT_FALSE(tracker.covers(96, 28));
  EXPECT_FALSE(tracker.covers(95, 20));
}

TEST(CandidateAreas, GrowingColumnsAddCellsToEarlierRows) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  tracker.update(gated(100, 20));                       // rows [96, 100] x [17, 23]
  const AreaUpdate u = tracker.update(gated(101, 22));  // columns -> [17, 25]: rows 96..100 gain 24, 25
  const std::set<Cell> cells = cells_of(u.new_cells);
  std::set<Cell> expected;
  for (std::int64_t i = 96; i <= 100; ++i) expected.insert({i, 24}), expected.insert({i, 25});
  for (std::int64_t j = 17; j <= 25; ++j) expected.insert({101, j});
  EXPECT_EQ(cells, expected);
  // Only row 101 is a new frame; columns 24, 25 and row 101 need descriptors.
  EXPECT_EQ(u.new_descriptor_frames, (std::vector<std::int64_t>{24, 25, 101}));
}

TEST(CandidateAreas, HoleJoinsAndLongerGapOpensNewArea) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  tracker.update(gated(100, 20));
  tracker.update(gated(101, 21));
  tracker.update(not_gated(102));
  tracker.update(not_gated(103));
  EXPECT_EQ(tracker.update(gated(104, 24)).joined_area, 0);  // hole of 2 frames
  for (std::int64_t i = 105; i <= 107; ++i) EXPECT_TRUE(tracker.update(not_gated(i)).closed.empty());
  const AreaUpdate u = tracker.update(gated(108, 28));  // hole of 3 > 2
  EXPECT_EQ(u.closed, (std::vector<int>{0}));
  EXPECT_TRUE(u.opened);
  EXPECT_EQ(u.joined_area, 1);
  EXPECT_FALSE(tracker.areas()[0].open);
  EXPECT_EQ(tracker.areas()[0].i_last, 104);
  EXPECT_EQ(tracker.areas()[1].i_first, 108);
  // Row 104 belongs to area 0 (as a gated row) and to area 1 (query margin 108 - 4).
  const auto row = tracker.columns_for_row(104);
  ASSERT_EQ(row.size(), 2u);
  EXPECT_EQ(row[0].area_id, 0);
  EXPECT_EQ(row[1].area_id, 1);
  EXPECT_EQ(tracker.finish(), (std::vector<int>{1}));
  EXPECT_FALSE(tracker.areas()[1].open);
}

TEST(CandidateAreas, InconsistentNearestStartsNewAreaAndClustersInterleave) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  EXPECT_EQ(tracker.update(gated(300, 20)).joined_area, 0);
  EXPECT_EQ(tracker.update(gated(301, 21)).joined_area, 0);
  const AreaUpdate jump = tracker.update(gated(302, 200));
  EXPECT_TRUE(jump.opened);
  EXPECT_EQ(jump.joined_area, 1);
  EXPECT_EQ(tracker.update(gated(303, 23)).joined_area, 0);   // |23 - 21| <= 5 + 2
  EXPECT_EQ(tracker.update(gated(304, 202)).joined_area, 1);  // |202 - 200| <= 5 + 2
  // Tolerance grows with the step: j_last 23 at 303; at 305 |j - 23| <= 5 + 2.
  EXPECT_EQ(tracker.update(gated(305, 30)).joined_area, 0);
  EXPECT_TRUE(tracker.update(gated(306, 38)).opened);  // |38 - 30| = 8 > 5 + 1
  EXPECT_EQ(tracker.areas().size(), 3u);
  EXPECT_EQ(tracker.areas()[0].j_min, 20);
  EXPECT_EQ(tracker.areas()[0].j_max, 30);
  EXPECT_EQ(tracker.areas()[1].j_min, 200);
  EXPECT_EQ(tracker.areas()[1].j_max, 202);
}

TEST(CandidateAreas, ClosestConsistentAreaWinsTiesToSmallestId) {
  GateConfig c = small_config();
  c.area_j_tolerance_frames = 50;
  CandidateAreaTracker tracker(c, 4, 10);
  tracker.update(gated(200, 10));
  tracker.update(gated(201, 100));  // |100 - 10| > 51: new area 1
  EXPECT_EQ(tracker.update(gated(202, 90)).joined_area, 1);
  EXPECT_EQ(tracker.update(gated(203, 50)).joined_area, 0);  // jumps 40 and 40: tie -> smallest id
}

TEST(CandidateAreas, ClampingAtZeroAndAtPairMargin) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  for (std::int64_t i = 0; i < 12; ++i) tracker.update(not_gated(i));
  const AreaUpdate u = tracker.update(gated(12, 1));
  const CandidateArea& a = tracker.areas()[0];
  EXPECT_EQ(a.row_begin, 8);
  EXPECT_EQ(a.col_begin, 0);  // 1 - 3 clamped
  EXPECT_EQ(a.col_end, 4);
  // Row i only reaches j <= i - 10.
  std::set<Cell> expected = {{10, 0}, {11, 0}, {11, 1}, {12, 0}, {12, 1}, {12, 2}};
  EXPECT_EQ(cells_of(u.new_cells), expected);
  EXPECT_TRUE(tracker.columns_for_row(9).empty());
  const auto row = tracker.columns_for_row(11);
  ASSERT_EQ(row.size(), 1u);
  EXPECT_EQ(row[0].j1, 1);
  EXPECT_EQ(u.new_descriptor_frames, (std::vector<std::int64_t>{0, 1, 2, 10, 11, 12}));

  CandidateAreaTracker early(small_config(), 4, 0);
  early.update(gated(2, 0));
  EXPECT_EQ(early.areas()[0].row_begin, 0);  // 2 - 4 clamped
}

TEST(CandidateAreas, HitsCloserThanPairMarginAreIgnored) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  const AreaUpdate u = tracker.update(gated(100, 91));  // 100 - 91 < 10: along-track neighbour
  EXPECT_EQ(u.joined_area, -1);
  EXPECT_TRUE(u.new_cells.empty());
  EXPECT_TRUE(tracker.areas().empty());
  EXPECT_EQ(tracker.update(gated(101, 91)).joined_area, 0);  // 101 - 91 = 10: a loop candidate
}

TEST(CandidateAreas, QueryMarginMustCoverSequenceLength) {
  EXPECT_THROW(CandidateAreaTracker(small_config(), 5, 10), ConfigError);
  EXPECT_NO_THROW(CandidateAreaTracker(small_config(), 4, 10));
  EXPECT_THROW(CandidateAreaTracker(small_config(), 4, -1), ConfigError);
}

TEST(CandidateAreas, NonIncreasingFramesAreDataError) {
  CandidateAreaTracker tracker(small_config(), 4, 10);
  tracker.update(not_gated(5));
  EXPECT_THROW(tracker.update(not_gated(5)), DataError);
  EXPECT_THROW(tracker.update(not_gated(3)), DataError);
}

// Random streams: the new cells of all updates are disjoint; descriptors are requested once each, exactly
// for the frames those cells touch. Without a horizon (row_horizon_frames beyond the stream) the cells'
// union is exactly the union of the final rectangles (clamped per row); with a horizon H it is the subset
// whose cells arrived while their row was at most H frames old, and no row older than that gets a cell.
void check_random_stream(std::uint64_t seed, bool with_horizon) {
  std::mt19937_64 rng(seed);
  GateConfig c;
  c.area_max_hole_frames = static_cast<int>(rng() % 4);
  c.area_j_tolerance_frames = static_cast<int>(rng() % 10);
  c.area_margin_query_frames = 3 + static_cast<int>(rng() % 10);
  c.area_margin_reference_frames = static_cast<int>(rng() % 8);
  c.row_horizon_frames = with_horizon ? std::max(c.area_margin_query_frames, c.area_max_hole_frames + 1) +
                                            static_cast<int>(rng() % 20)
                                      : 100000;
  const int pair_margin = static_cast<int>(rng() % 30);
  CandidateAreaTracker tracker(c, 3, pair_margin);
  std::set<Cell> reported;
  std::set<std::int64_t> requested;
  std::int64_t j = 0;
  for (std::int64_t i = 0; i < 600; ++i) {
    GateDecision d = not_gated(i);
    if (i > 50 && rng() % 3 != 0) {
      j = (rng() % 10 == 0) ? static_cast<std::int64_t>(rng() % static_cast<std::uint64_t>(i - 40))
                            : std::min<std::int64_t>(
                                  i - 40, std::max<std::int64_t>(0, j + 1 + static_cast<int>(rng() % 3) - 1));
      d = gated(i, j);
    }
    const AreaUpdate u = tracker.update(d);
    for (const CellSpan& s : u.new_cells) {
      ASSERT_LE(s.j0, s.j1);
      ASSERT_LE(s.j1, s.i - pair_margin);
      ASSERT_GE(s.j0, 0);
      ASSERT_LE(s.i, i);
      ASSERT_GE(s.i, i - c.row_horizon_frames) << "cell in a final row";
      for (std::int64_t jj = s.j0; jj <= s.j1; ++jj)
        ASSERT_TRUE(reported.insert({s.i, jj}).second) << "cell twice";
    }
    for (const std::int64_t f : u.new_descriptor_frames)
      ASSERT_TRUE(requested.insert(f).second) << "frame twice";
  }
  std::set<Cell> expected;
  for (const CandidateArea& a : tracker.areas()) {
    for (std::int64_t i = a.row_begin; i <= a.row_end; ++i) {
      for (std::int64_t jj = a.col_begin; jj <= std::min(a.col_end, i - pair_margin); ++jj)
        expected.insert({i, jj});
    }
  }
  std::set<std::int64_t> touched;
  for (const auto& [i, jj] : reported) {
    touched.insert(i);
    touched.insert(jj);
    EXPECT_TRUE(expected.count({i, jj})) << "cell outside every rectangle";
  }
  for (const auto& [i, jj] : expected) EXPECT_EQ(tracker.covers(i, jj), reported.count({i, jj}) == 1);
  if (with_horizon) {
    EXPECT_LE(reported.size(), expected.size()) << "seed " << seed;
  } else {
    EXPECT_EQ(reported, expected) << "seed " << seed;
  }
  EXPECT_EQ(requested, touched) << "seed " << seed;
  EXPECT_EQ(tracker.descriptor_requests().count(), touched.size());
  EXPECT_GT(tracker.areas().size(), 1u);
}

TEST(CandidateAreas, NewCellsAndDescriptorRequestsOnRandomStreams) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) check_random_stream(seed, false);
}

TEST(CandidateAreas, RowHorizonFreezesOldRows) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) check_random_stream(seed, true);
  GateConfig c = small_config();
  c.row_horizon_frames = 3;  // < area_margin_query_frames = 4
  EXPECT_THROW(CandidateAreaTracker(c, 4, 10), ConfigError);
  c.row_horizon_frames = 4;
  c.area_max_hole_frames = 4;  // the horizon must exceed the hole
  EXPECT_THROW(CandidateAreaTracker(c, 4, 10), ConfigError);
}

TEST(DescriptorRequests, AtMostOnce) {
  DescriptorRequests r;
  EXPECT_TRUE(r.request(5));
  EXPECT_FALSE(r.request(5));
  EXPECT_TRUE(r.request(1000));
  EXPECT_TRUE(r.requested(5));
  EXPECT_FALSE(r.requested(6));
  EXPECT_FALSE(r.requested(-1));
  EXPECT_EQ(r.count(), 2u);
}

}  // namespace
}  // namespace loopgate
