// Sequence matching (online DP) and delayed non-maximum suppression over the sparse similarity matrix
// S(j, i) of DIRD (docs/detection.md § The paper's matcher).
//
// DP (§3): for each stored entry S(j, i), the best path of L cells ending at (j, i) that goes back one
// frame in i per step and 0..max_step frames in j (staying >= 0), missing entries counting 0:
//   H1 = S;  Hk(r, c) = S(r, c) + max_{s in 0..max_step, r-s >= 0} H(k-1)(r - s, c - 1);  DP = H_L,
// evaluated at the stored entries of S and kept when DP > tau3 * L. Because j never increases while i
// goes back, a revisit driven in the opposite direction (j decreasing as i increases) is not found.
//
// NMS (§4): on a copy M of DP, the kept entries are visited in ascending order of the current frame i
// (then j; column-major over DP(j, i), the order MATLAB's find() gives). For entry (j, i) the window is
// the 2W+1 cells M(j - k, i + k), k = -W..W (W = nms_half_window, missing = 0), tau = the second largest
// of these values (counting ties), and every non-zero value in the window below tau is set to 0. Every
// kept entry is visited, also one already set to 0. Each window lies on one anti-diagonal j + i, so
// only the order along i matters. Survivors are the loop closures; score = their DP value.
//
// Streaming delay: the visit of column c reads columns up to c + W, and column c can still be zeroed by
// the visits of columns up to c + W. A column is therefore final (and reported) once column c + 2W has
// been pushed: emission_delay() = 2 W frames (118 for W = 59). This gives exactly the batch result
// (tests/match_sequence_matcher_test.cpp checks it on random matrices). flush() ends the stream.
//
// Memory: the matcher keeps the last L-1 sparse DP columns and the last ~3W+1 columns of kept DP
// entries, nothing per frame beyond that.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <span>
#include <utility>
#include <vector>

#include "core/types.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/match_config.hpp"

namespace loopgate {

// A detected loop closure: current frame i (query in two-sequence mode), earlier frame j (reference),
// and its confidence, the DP value (what precision-recall sweeps threshold).
struct LoopClosure {
  std::int64_t i = 0;
  std::int64_t j = 0;
  double score = 0.0;
  bool operator==(const LoopClosure&) const = default;
};

struct FrameMatchStatus {
  std::int64_t i = 0;
  FrameOutcome outcome = FrameOutcome::kNoCandidate;
  std::size_t candidates = 0;       // stored similarity entries S(., i)
  double best_similarity = 0.0;     // max S(., i), 0 if none
  double best_score = 0.0;          // max DP(., i) over the stored entries, 0 if none
  std::int64_t best_j = -1;         // row j of best_score (the smallest j on ties), -1 if none
  std::size_t above_threshold = 0;  // DP entries > tau3 * L
  std::size_t loops = 0;            // NMS survivors (emitted loop closures)
};

// What one push()/flush() finalised: the loop closures (ascending i, then j) and the status of every
// frame whose NMS window closed (ascending i).
struct MatchOutput {
  std::vector<LoopClosure> loops;
  std::vector<FrameMatchStatus> frames;
};

class SequenceMatcher {
 public:
  enum class Mode {
    kSingleSequence,  // j earlier frame of the same sequence; requires i - j >= margin
    kTwoSequence,     // j reference frame, i query frame; no margin (docs/detection.md § Two sequences)
  };

  explicit SequenceMatcher(const MatchConfig& config = {}, Mode mode = Mode::kSingleSequence,
                           std::int64_t first_frame = 0);

  // Feeds the stored entries S(., i) of current frame i, which must equal next_frame() (frames are
  // consecutive; a frame without candidates is pushed with no entries). Entries: any order, distinct
  // j >= 0, similarity finite and >= 0; in single-sequence mode j <= i - margin. Throws
  // std::invalid_argument otherwise. Appends what became final to `out`.
  void push(std::int64_t i, std::span<const SimilarityEntry> entries, MatchOutput& out);
  MatchOutput push(std::int64_t i, std::span<const SimilarityEntry> entries);

  // End of stream: the remaining frames are finalised (no later columns: missing = 0).
  void flush(MatchOutput& out);
  MatchOutput flush();

  std::int64_t next_frame() const { return next_frame_; }
  // Frames pushed but not yet reported.
  std::size_t pending_frames() const { return columns_.size(); }
  std::int64_t emission_delay() const { return 2 * static_cast<std::int64_t>(config_.nms_half_window); }
  const MatchConfig& config() const { return config_; }

 private:
  using SparseColumn = std::vector<std::pair<std::int64_t, double>>;  // (row j, value), ascending j
  struct DpEntry {
    std::int64_t j = 0;
    double score = 0.0;    // DP value
    double current = 0.0;  // value in the NMS copy M
  };
  struct Column {
    std::int64_t i = 0;
    std::vector<DpEntry> entries;  // ascending j, DP > threshold only
    FrameMatchStatus status;
  };

  void visit_column(std::size_t index);
  double* find_current(std::int64_t i, std::int64_t j);
  void finalise_front(MatchOutput& out);

  MatchConfig config_;
  Mode mode_;
  std::int64_t next_frame_;
  std::int64_t next_visit_;           // next column whose entries NMS visits
  std::vector<SparseColumn> h_prev_;  // h_prev_[k - 1] = H_k of the previous column, k = 1..L-1
  std::vector<SparseColumn> h_next_;
  SparseColumn s_column_;
  std::deque<Column> columns_;  // not yet final; columns_.front().i is the oldest
  std::vector<double*> window_scratch_;
};

// Reference (batch) implementation, written for clarity: dense DP columns over all rows, then NMS with the
// whole DP matrix known. `columns[i]` holds S(., i) (entries with distinct j >= 0, any order). Returns the
// DP entries above tau3 * L in ascending (i, j).
std::vector<LoopClosure> sequence_dp_batch(std::span<const std::vector<SimilarityEntry>> columns,
                                           const MatchConfig& config);
// NMS of docs/detection.md § The paper's matcher on DP entries (distinct (i, j)); returns the survivors in
// ascending (i, j).
std::vector<LoopClosure> nms_batch(std::span<const LoopClosure> dp, int nms_half_window);
// sequence_dp_batch + nms_batch.
std::vector<LoopClosure> match_batch(std::span<const std::vector<SimilarityEntry>> columns,
                                     const MatchConfig& config);

// Two-sequence mode (docs/detection.md § Two sequences): S for every (reference r, query q) pair, no safety
// margin, then the streaming DP and NMS with i = query index and j = reference index. `statuses` (optional)
// receives the status of every query frame.
std::vector<LoopClosure> match_two_sequences(std::span<const Descriptor> reference,
                                             std::span<const Descriptor> query,
                                             const DirdSimilarity& similarity, const MatchConfig& config,
                                             std::vector<FrameMatchStatus>* statuses = nullptr);

}  // namespace loopgate
