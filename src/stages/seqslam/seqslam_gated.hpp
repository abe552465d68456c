// Gated SeqSLAM (docs/seqslam-gated.md): SeqSLAM steps 2-4 (docs/detection.md § SeqSLAM) only
// where the pose gate's candidate areas cover cells (query i, reference j). A plain class, no threads: the
// caller (pipeline/seqslam_gated_method.cpp) computes columns and queries in parallel.
//
// What is computed, with h = ds/2, w = R/2 (contrast window), moves v in [vmin ds, vmax ds], n frames:
//   - the start rows of query N: s = r - h for every covered cell (N, r), i.e. the sequences whose match
//     s + h is a covered cell; only for h <= N < n - h (full SeqSLAM gives the others no match either);
//   - E (step 3) on every cell those sequences read, covered or not: column N - h + t, row
//     s + floor(t v / ds), t = 0..ds, every move (rows past the last frame score +infinity, as in full);
//   - D (step 2) on those rows extended by w on both sides (the contrast window of each E cell, clipped
//     to the run), excluded entries (seqslam.exclusion) +infinity and not computed, as in full;
//   - the minimum of the E cells computed is subtracted from them (full: the minimum of the whole matrix);
//   - the frames read: every column with work and every non-excluded D row. frames_for_cells() gives, per
//     covered span, a superset a streaming caller can request as soon as the span is covered.
//
// Invariant (tests/seqslam_gated_test.cpp on random data; tests/pipeline_seqslam_gated_test.cpp and
// tests/e2e_seqslam_gated_test.cpp on runs): let E be full SeqSLAM's matrix after step 3, before its minimum
// is subtracted, C the covered cells and m = minimum() (the minimum of the gated E cells). Then
//   (1) every E cell the gated search computed equals E there, bit for bit;
//   (2) for every query N and every start row s with (N, s + h) in C, the gated score of s equals
//       seqslam_sequence_scores(E - m, N)[s], bit for bit;
//   (3) the gated match of N (has_match, reference, best, second, ratio, accepted) is
//       seqslam_match_from_scores() over those scores with every other start row at +infinity: full
//       SeqSLAM's step 4 on E - m restricted to the start rows whose match is a covered cell.
// Full SeqSLAM subtracts its global minimum m_full <= m instead; every score sums ds + 1 entries, so the
// shift changes every score by the same (ds + 1)(m - m_full): the best and second start rows are the full
// run's restricted ones (up to rounding ties), the ratio is not (gated ratios are lower or equal).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "stages/seqslam/seqslam.hpp"
#include "stages/seqslam/seqslam_config.hpp"

namespace loopgate {

// Inclusive interval of rows (reference frames) or columns.
struct SeqSlamSpan {
  std::size_t first = 0;
  std::size_t last = 0;
};

// Preprocessed images by frame index: frame k at bytes + k * pixel_count.
struct SeqSlamFrames {
  const std::uint8_t* bytes = nullptr;
  std::size_t pixel_count = 0;
  const std::uint8_t* image(std::size_t k) const { return bytes + k * pixel_count; }
};

class SeqSlamGatedSearch {
 public:
  explicit SeqSlamGatedSearch(const SeqSlamConfig& config);  // validates (ConfigError)

  const SeqSlamConfig& config() const { return config_; }

  // The frames the search of the covered cells (query i, references [j0, j1]) may read, ascending: the
  // query frames i - h .. i + h and the reference frames [j0 - h - w, j1 - h + max move + w] (clipped at 0)
  // that are not excluded against at least one of those queries. Frames past the run's end may be listed.
  void frames_for_cells(std::size_t i, std::size_t j0, std::size_t j1, std::vector<std::size_t>& out) const;

  // Covers cells (query i, references [j0, j1]); any order, overlaps allowed. Before plan().
  void add_cells(std::size_t i, std::size_t j0, std::size_t j1);

  // After the last add_cells: the run has `frame_count` frames; plans what every column computes.
  void plan(std::size_t frame_count);
  std::size_t frame_count() const { return frame_count_; }
  // The columns (query frames) with work, ascending: the units of compute_column.
  const std::vector<std::size_t>& columns() const { return work_columns_; }
  // The queries with at least one start row, ascending (every other query has no match).
  const std::vector<std::size_t>& queries() const { return queries_; }
  // Every frame the planned computation reads (columns and non-excluded D rows), ascending.
  std::vector<std::size_t> frames_read() const;

  // Steps 2 and 3 for column q (after plan): returns the minimum finite E of the column (+infinity if
  // none). Distinct columns may be computed concurrently.
  double compute_column(std::size_t q, const SeqSlamFrames& frames);
  // Subtracts `minimum` (the minimum over every column's return value) from every E cell, when finite.
  void subtract(double minimum);
  double minimum() const { return minimum_; }

  // Step 4 for query N (after subtract): its match, with query = N. Concurrent calls are fine.
  SeqSlamMatch match_query(std::size_t query) const;
  // The scores of its start rows [*first_start, *first_start + size()); +infinity for a start row whose
  // match is not covered. Empty when the query has no start row.
  std::vector<double> sequence_scores(std::size_t query, std::size_t* first_start) const;

  // plan, every column, subtract the minimum, every query, on this thread: one match per frame.
  std::vector<SeqSlamMatch> run(std::size_t frame_count, const SeqSlamFrames& frames);

  // E(r, q) as it stands (before or after subtract), nullopt when the search does not compute it.
  std::optional<double> entry(std::size_t r, std::size_t q) const;
  // Whether cell (query i, reference j) was covered (after plan).
  bool covered(std::size_t i, std::size_t j) const;
  std::size_t difference_entries() const;  // D entries computed (excluded ones are not)
  std::size_t enhanced_entries() const;    // E entries held

 private:
  struct Column {
    std::vector<SeqSlamSpan> e_rows;     // rows of E the search reads, merged, ascending
    std::vector<SeqSlamSpan> d_rows;     // e_rows extended by the contrast window, merged
    std::vector<std::vector<double>> e;  // E per e_rows span
    std::size_t differences = 0;
    // E of rows [first, last], inside one span; nullptr when it is not.
    const double* find(std::size_t first, std::size_t last) const;
  };
  // Start rows of query N (covered r >= h shifted by -h), merged, ascending.
  std::vector<SeqSlamSpan> start_rows(std::size_t query) const;

  SeqSlamConfig config_;
  SeqSlamExclusion exclusion_;
  std::size_t half_sequence_ = 0;  // h = ds/2
  std::size_t half_window_ = 0;    // w = R/2
  std::size_t move_min_ = 0, move_max_ = 0;
  bool planned_ = false;
  std::size_t frame_count_ = 0;
  std::vector<std::vector<SeqSlamSpan>> covered_;  // per query row (merged by plan())
  std::vector<Column> columns_;
  std::vector<std::size_t> work_columns_;
  std::vector<std::size_t> queries_;
  double minimum_ = 0.0;
};

}  // namespace loopgate
