// Gated SeqSLAM (stages/seqslam/seqslam_gated.hpp) against the full computation restricted to the covered
// cells, on generated images: the enhanced differences it computes are the full run's bit for bit, and every
// query's scores and match are full SeqSLAM's step 4 on E - m with the start rows restricted to those whose
// match is a covered cell (the header's invariant); the frames it reads are the ones frames_for_cells()
// asked for while the cells came in.
#include "stages/seqslam/seqslam_gated.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "stages/seqslam/seqslam.hpp"

namespace loopgate {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr std::size_t kFrames = 230;
constexpr std::size_t kPlaces = 100;  // frame k shows place k % kPlaces: frame k revisits k - 100
constexpr std::size_t kPixels = 64;

SeqSlamConfig past_config() {
  SeqSlamConfig config;  // OpenSeqSLAM defaults: ds 10, R 10, moves 8..12, Rwindow 10
  config.exclusion = SeqSlamExclusionKind::kPast;
  config.exclusion_margin_frames = 30;
  config.validate();
  return config;
}

SeqSlamImages revisit_images() {
  std::mt19937 rng(11);
  std::vector<std::vector<std::uint8_t>> places(kPlaces, std::vector<std::uint8_t>(kPixels));
  for (auto& place : places)
    for (auto& x : place) x = static_cast<std::uint8_t>(rng() % 200);
  SeqSlamImages images(kPixels);
  std::uniform_int_distribution<int> noise(-20, 20);
  for (std::size_t k = 0; k < kFrames; ++k) {
    std::vector<std::uint8_t> image(kPixels);
    for (std::size_t p = 0; p < kPixels; ++p)
      image[p] = static_cast<std::uint8_t>(std::clamp(places[k % kPlaces][p] + noise(rng), 0, 255));
    images.add(image);
  }
  return images;
}

struct Span {
  std::size_t i, j0, j1;
};

// Candidate-area-like coverage: a band along the revisit diagonal (with its margins), a rectangle, rows
// whose only cells are at j < ds/2 (no start row), an area reaching the last frames (no match near the end),
// cut into overlapping pieces and shuffled.
std::vector<Span> coverage(std::size_t margin) {
  std::vector<Span> spans;
  const auto add = [&](std::size_t i, std::size_t j0, std::size_t j1) {
    j1 = std::min(j1, i - margin);
    if (j0 > j1) return;
    const std::size_t mid = (j0 + j1) / 2;
    spans.push_back({i, j0, std::min(j1, mid + 2)});  // overlapping halves
    spans.push_back({i, mid, j1});
  };
  for (std::size_t i = 90; i <= 170; ++i) add(i, i >= 112 ? i - 112 : 0, i - 88);
  for (std::size_t i = 150; i < kFrames; ++i) add(i, 30, 95);
  add(40, 0, 3);
  add(41, 0, 6);
  std::mt19937 rng(5);
  std::shuffle(spans.begin(), spans.end(), rng);
  return spans;
}

std::set<std::pair<std::size_t, std::size_t>> cell_set(const std::vector<Span>& spans) {
  std::set<std::pair<std::size_t, std::size_t>> cells;
  for (const Span& s : spans)
    for (std::size_t j = s.j0; j <= s.j1; ++j) cells.insert({s.i, j});
  return cells;
}

void expect_same_double(double a, double b, const std::string& what) {
  if (std::isnan(a) || std::isnan(b)) {
    EXPECT_TRUE(std::isnan(a) && std::isnan(b)) << what << ": " << a << " vs " << b;
  } else {
    EXPECT_EQ(a, b) << what;
  }
}

TEST(SeqSlamGated, EqualsFullSeqSlamRestrictedToTheCoveredCells) {
  const SeqSlamConfig config = past_config();
  const SeqSlamImages images = revisit_images();
  const SeqSlamFrames frames{images.image(0), kPixels};
  const auto h = static_cast<std::size_t>(config.sequence_length_frames / 2);
  const std::vector<Span> spans = coverage(static_cast<std::size_t>(config.exclusion_margin_frames));
  const auto cells = cell_set(spans);

  SeqSlamGatedSearch gated(config);
  std::set<std::size_t> requested;  // what a streaming caller would have preprocessed
  for (const Span& s : spans) {
    gated.add_cells(s.i, s.j0, s.j1);
    std::vector<std::size_t> frames_needed;
    gated.frames_for_cells(s.i, s.j0, s.j1, frames_needed);
    requested.insert(frames_needed.begin(), frames_needed.end());
  }
  gated.plan(kFrames);
  for (const std::size_t k : gated.frames_read()) EXPECT_TRUE(requested.count(k)) << "frame " << k;
  double minimum = kInf;
  for (const std::size_t q : gated.columns()) minimum = std::min(minimum, gated.compute_column(q, frames));

  // The full run: D over the whole matrix, step 3, before its minimum is subtracted.
  SeqSlamMatrix E(kFrames, kFrames);
  const std::size_t full_differences = seqslam_difference_block(
      images, images, SeqSlamExclusion::from_config(config), 0, kFrames, 0, kFrames, E);
  const double full_minimum = seqslam_enhance_contrast(E, config.contrast_window_rows, 0, kFrames);

  // (1) every E cell computed is the full run's, bit for bit; the gated minimum is theirs.
  std::size_t compared = 0;
  double gated_cells_minimum = kInf;
  for (std::size_t q = 0; q < kFrames; ++q) {
    for (std::size_t r = 0; r < kFrames; ++r) {
      const auto value = gated.entry(r, q);
      if (!value) continue;
      ++compared;
      EXPECT_EQ(*value, E.at(r, q)) << "E(" << r << ", " << q << ")";
      if (std::isfinite(*value)) gated_cells_minimum = std::min(gated_cells_minimum, *value);
    }
  }
  EXPECT_EQ(compared, gated.enhanced_entries());
  EXPECT_GT(compared, cells.size());  // the paths and windows reach beyond the covered cells
  EXPECT_EQ(minimum, gated_cells_minimum);
  EXPECT_GE(minimum, full_minimum);
  EXPECT_GT(gated.difference_entries(), 0u);
  EXPECT_LT(gated.difference_entries(), full_differences / 2);

  gated.subtract(minimum);
  SeqSlamMatrix shifted = E;
  seqslam_subtract(shifted, minimum, 0, kFrames);
  seqslam_subtract(E, full_minimum, 0, kFrames);

  // (2) and (3): scores and match of every query.
  std::size_t matches = 0, accepted = 0, start_rows_checked = 0;
  for (std::size_t query = 0; query < kFrames; ++query) {
    std::vector<double> restricted = seqslam_sequence_scores(shifted, query, config);
    for (std::size_t s = 0; s < restricted.size(); ++s) {
      if (!cells.count({query, s + h})) restricted[s] = kInf;
    }
    std::size_t first = 0;
    const std::vector<double> scores = gated.sequence_scores(query, &first);
    for (std::size_t k = 0; k < scores.size(); ++k) {
      EXPECT_EQ(scores[k], restricted[first + k]) << "query " << query << " start " << first + k;
      start_rows_checked += cells.count({query, first + k + h});
    }
    const SeqSlamMatch expected =
        seqslam_match_from_scores(query, restricted.data(), restricted.size(), 0, config);
    const SeqSlamMatch m = gated.match_query(query);
    const std::string where = "query " + std::to_string(query);
    EXPECT_EQ(m.query, query);
    ASSERT_EQ(m.has_match, expected.has_match) << where;
    if (!m.has_match) continue;
    ++matches;
    accepted += m.accepted ? 1 : 0;
    EXPECT_EQ(m.reference, expected.reference) << where;
    expect_same_double(m.best_score, expected.best_score, where + " best");
    expect_same_double(m.second_score, expected.second_score, where + " second");
    expect_same_double(m.ratio, expected.ratio, where + " ratio");
    EXPECT_EQ(m.accepted, expected.accepted) << where;
    // The full run's own minimum shifts every score alike: the same best start row.
    std::vector<double> full_scores = seqslam_sequence_scores(E, query, config);
    for (std::size_t s = 0; s < full_scores.size(); ++s) {
      if (!cells.count({query, s + h})) full_scores[s] = kInf;
    }
    EXPECT_EQ(seqslam_match_from_scores(query, full_scores.data(), full_scores.size(), 0, config).reference,
              m.reference)
        << where;
  }
  EXPECT_GT(start_rows_checked, cells.size() / 2);
  EXPECT_GT(matches, 100u);
  EXPECT_GT(accepted, 20u);
  // Queries outside the coverage, within ds/2 of an end, or whose cells are all at j < ds/2: no match.
  EXPECT_FALSE(gated.match_query(60).has_match);
  EXPECT_FALSE(gated.match_query(40).has_match);
  EXPECT_FALSE(gated.match_query(kFrames - 3).has_match);
  // Query 41's only start rows are 0 and 1: a best sequence, no second one outside best +- 5.
  const SeqSlamMatch lone = gated.match_query(41);
  EXPECT_TRUE(lone.has_match);
  EXPECT_EQ(lone.ratio, kInf);
  EXPECT_FALSE(lone.accepted);
}

TEST(SeqSlamGated, RunDoesTheStepsInOrderAndNoCoverageComputesNothing) {
  const SeqSlamConfig config = past_config();
  const SeqSlamImages images = revisit_images();
  const SeqSlamFrames frames{images.image(0), kPixels};
  SeqSlamGatedSearch by_steps(config), by_run(config);
  for (const Span& s : coverage(30)) {
    by_steps.add_cells(s.i, s.j0, s.j1);
    by_run.add_cells(s.i, s.j0, s.j1);
  }
  const std::vector<SeqSlamMatch> matches = by_run.run(kFrames, frames);
  ASSERT_EQ(matches.size(), kFrames);
  by_steps.plan(kFrames);
  double minimum = kInf;
  for (const std::size_t q : by_steps.columns())
    minimum = std::min(minimum, by_steps.compute_column(q, frames));
  by_steps.subtract(minimum);
  EXPECT_EQ(by_run.minimum(), minimum);
  for (std::size_t q = 0; q < kFrames; ++q) {
    const SeqSlamMatch m = by_steps.match_query(q);
    EXPECT_EQ(matches[q].query, q);
    EXPECT_EQ(matches[q].has_match, m.has_match) << q;
    EXPECT_EQ(matches[q].reference, m.reference) << q;
  }

  SeqSlamGatedSearch empty(config);
  const std::vector<SeqSlamMatch> none = empty.run(kFrames, frames);
  EXPECT_TRUE(empty.columns().empty());
  EXPECT_TRUE(empty.frames_read().empty());
  EXPECT_EQ(empty.difference_entries(), 0u);
  for (const SeqSlamMatch& m : none) EXPECT_FALSE(m.has_match);
  EXPECT_THROW(empty.add_cells(100, 0, 10), std::logic_error);
}

TEST(SeqSlamGated, FramesForCellsAreTheSequenceAndContrastNeighbours) {
  const SeqSlamGatedSearch gated(past_config());  // ds 10, R 10, moves 8..12, past 30
  std::vector<std::size_t> frames;
  // Query frames 95..105; starts 35..55, so rows 35..67 for the sequences and 30..72 with the windows.
  gated.frames_for_cells(100, 40, 60, frames);
  std::vector<std::size_t> expected;
  for (std::size_t k = 30; k <= 72; ++k) expected.push_back(k);
  for (std::size_t k = 95; k <= 105; ++k) expected.push_back(k);
  EXPECT_EQ(frames, expected);
  // Rows beyond 105 - 30 = 75 are excluded against every query 95..105: not listed.
  frames.clear();
  gated.frames_for_cells(100, 70, 70, frames);
  expected.clear();
  for (std::size_t k = 60; k <= 75; ++k) expected.push_back(k);
  for (std::size_t k = 95; k <= 105; ++k) expected.push_back(k);
  EXPECT_EQ(frames, expected);
  // Near the start: no frame below 0; cells at j < ds/2 need only the query frames.
  frames.clear();
  gated.frames_for_cells(3, 0, 2, frames);
  EXPECT_EQ(frames, (std::vector<std::size_t>{0, 1, 2, 3, 4, 5, 6, 7, 8}));
}

}  // namespace
}  // namespace loopgate
