// Sequence search on locally contrast-enhanced distances: SeqSLAM's matching back end (docs/detection.md §
// SeqSLAM steps 3-4) on any image distance, streaming, for DIRD descriptors in particular (run.method
// dird-seqslam, docs/illumination.md).
//
// Why: across day and night (or seasons) every distance of a query grows, so an absolute scale (DIRD's
// logistic with mu/sigma) rejects the true match with everything else. What survives the change of
// condition is the ranking of a query's distances among neighbouring references, and the continuity of
// that ranking along the route. So:
//
// 1. Contrast enhancement, per query row i (the row's computed distances only, e.g. a gated run's cells):
//    z(i, j) = (mean - d(i, j)) / stddev over the row's distances d(i, j') with |j' - j| <= w
//    (w = contrast_half_window_frames; population stddev; undefined when fewer than contrast_min_cells
//    distances lie in the window or they are all equal). Positive z: closer than the references around it.
// 2. Lines: for each velocity v of a geometric grid from velocity_min to velocity_max (velocity_steps
//    values), the line of L = match.sequence_length cells ending at (i, j) reads z(i - k, j - round(v k)),
//    k = 0..L-1 (an undefined or missing cell reads 0). Its score is the mean of the L values. A line must
//    end at a defined cell. Per row i and velocity the best line (highest score, then smallest j) is kept.
// 3. Cover: a line asserts that every query it crosses matches the reference it crosses. Each kept line
//    of row i offers query q = i - k the reference j - round(v k) with the line's score (only where z of
//    that cell is defined); a query keeps the best offer (ties: the earlier one). So the first L - 1
//    frames of a revisit are matched too, by the lines that end later in it (a line ending at a query only
//    would lose them: measured on the demo's night revisit, 30% of its queries).
// 4. A query is final when row q + L - 1 has been pushed (no later line crosses it); it is a loop closure
//    when its best score >= min_score (one loop per query, no NMS).
//
// The score is in units of the local spread of distances, so one threshold serves every descriptor,
// resolution and condition (docs/illumination.md gives the measured distribution of chance lines). Loops
// driven in the opposite direction are not found (velocities are positive), as with DIRD's DP and SeqSLAM.
//
// Everything depends only on rows already pushed: the streaming result equals contrast_search_batch() on
// the same rows, and a gated run's result equals it on the full distances restricted to the gated cells.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <span>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

struct ContrastSearchConfig {
  int contrast_half_window_frames = 10;  // w: the contrast window is 2 w + 1 references
  int contrast_min_cells = 5;            // fewer distances in the window: z undefined
  // Reference frames per query frame along a line: a geometric grid of velocity_steps values from
  // velocity_min to velocity_max (1 value if min == max); the default, 2/3 .. 3/2 in 7 steps, holds 1 and
  // allows either traversal to be 1.5 times as fast as the other.
  double velocity_min = 2.0 / 3.0;
  double velocity_max = 1.5;
  int velocity_steps = 7;
  double min_score = 1.0;  // a loop closure: best line's mean z >= min_score (docs/illumination.md)

  // The keys, in order, for loading, printing and the JSON echo (section dird_seqslam).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("contrast_half_window_frames", self.contrast_half_window_frames);
    v("contrast_min_cells", self.contrast_min_cells);
    v("velocity_min", self.velocity_min);
    v("velocity_max", self.velocity_max);
    v("velocity_steps", self.velocity_steps);
    v("min_score", self.min_score);
  }
  // Throws ConfigError naming "dird_seqslam.<key>": contrast_half_window_frames in [1, 1000],
  // contrast_min_cells in [2, 2 w + 1], 0 < velocity_min <= velocity_max <= 10, velocity_steps in [1, 64]
  // (1 only when min == max), min_score in [-100, 100]; each message states the bound.
  void validate() const;

  // The velocities, ascending.
  std::vector<double> velocities() const;
};

// One computed distance of a query row: reference j and its distance (>= 0, any scale).
struct DistanceEntry {
  std::int64_t j = 0;
  double distance = 0.0;
};

// Step 1 for one row: entries sorted by j (distinct), z per entry in that order (NaN where undefined).
std::vector<float> contrast_enhance_row(std::span<const DistanceEntry> sorted_row, int half_window,
                                        int min_cells);

// The search's verdict on one query frame.
struct ContrastVerdict {
  std::int64_t i = 0;
  FrameOutcome outcome = FrameOutcome::kNoCandidate;  // kNoCandidate: no line crosses a defined cell of i
  std::size_t cells = 0;                              // distances in row i
  std::size_t defined = 0;                            // of them with a defined z
  std::int64_t best_j = -1;                           // reference of the best line crossing i, -1 if none
  double score = 0.0;                                 // its mean z
  double velocity = 0.0;                              // its velocity
  std::int64_t line_end = -1;  // the query frame where it ends (i <= line_end <= i + L - 1)
};

struct ContrastOutput {
  std::vector<LoopClosure> loops;       // ascending i; score = mean z
  std::vector<ContrastVerdict> frames;  // ascending i
};

class ContrastSequenceSearch {
 public:
  enum class Mode {
    kSingleSequence,  // j earlier frame of the same sequence; j <= i - margin
    kTwoSequence,     // j reference frame, i query frame; no margin
  };

  // sequence_length = L >= 1 (match.sequence_length); margin >= 0 (single sequence).
  ContrastSequenceSearch(const ContrastSearchConfig& config, int sequence_length,
                         Mode mode = Mode::kSingleSequence, int margin = 0, std::int64_t first_frame = 0);

  // Row i = next_frame(): the distances computed for query i (any order, distinct j >= 0, finite and >= 0;
  // single sequence: j <= i - margin). A row without distances is pushed empty. Throws
  // std::invalid_argument otherwise. Appends what became final to `out`.
  void push(std::int64_t i, std::span<const DistanceEntry> row, ContrastOutput& out);
  // End of stream: every pending query is final.
  void flush(ContrastOutput& out);

  std::int64_t next_frame() const { return next_frame_; }
  std::int64_t emission_delay() const { return sequence_length_ - 1; }
  int sequence_length() const { return sequence_length_; }
  const ContrastSearchConfig& config() const { return config_; }

 private:
  struct ZRow {  // z of one row, dense over [j_lo, j_lo + z.size())
    std::int64_t i = 0;
    std::int64_t j_lo = 0;
    std::vector<float> z;                   // 0 where undefined or not computed
    std::vector<std::uint8_t> defined;      // 1 where z is defined
    const float* at(std::int64_t j) const;  // nullptr outside the range or undefined
  };

  const ZRow* row_at(std::int64_t i) const;  // nullptr when i is not among the kept rows
  void finalise(std::int64_t last_final, ContrastOutput& out);

  ContrastSearchConfig config_;
  int sequence_length_;
  Mode mode_;
  int margin_;
  std::int64_t next_frame_;
  std::vector<std::vector<std::int64_t>> offsets_;  // per velocity: round(v k), k = 0..L-1
  std::vector<double> velocities_;
  std::deque<ZRow> rows_;                // the last L rows
  std::deque<ContrastVerdict> pending_;  // queries not yet final, ascending i
  std::vector<double> line_sum_;         // scratch
};

// Reference (batch) implementation, written for clarity: every row's z first, then every line.
// rows[k] holds row first_frame + k. Returns the verdict of every row and the loop closures.
ContrastOutput contrast_search_batch(std::span<const std::vector<DistanceEntry>> rows,
                                     const ContrastSearchConfig& config, int sequence_length,
                                     ContrastSequenceSearch::Mode mode, int margin);

// The verdict in the outputs' words (frames.csv): label, reason, match and score.
struct ContrastOutcomeContext {
  bool two_sequence = false;
  bool described = true;       // the frame had a descriptor
  bool outside_areas = false;  // gated: no candidate-area cell in the frame's row
  bool before_margin = false;  // single sequence: no earlier frame beyond match.margin yet
  int margin_frames = 0;
  double min_score = 0.0;
};
FrameDetection contrast_detection(const ContrastVerdict& verdict, const ContrastOutcomeContext& context);

}  // namespace loopgate
