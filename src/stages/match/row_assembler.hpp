// Streaming assembly of sparse rows for the gated run (docs/gating.md § Candidate areas): a candidate area
// adds cells (query row i, reference columns j) to rows behind the current frame, so a row stays open for
// `horizon_frames` frames after it arrived and only then goes, complete, to the matcher (which needs its
// rows in order). Rows without cells go to the matcher empty.
//
// At frame `current`, rows <= current - horizon_frames are final: advance(current) releases them. A cell
// for a released row is a logic error (the candidate-area tracker never reports one: its own horizon is the
// same). finish(end) releases every row < end at the end of the stream.
//
// BasicRowAssembler<Entry> holds rows of any entry (DIRD similarities, distances) and hands each final row
// to a callable push(i, const std::vector<Entry>&); RowAssembler is the one of DIRD's SequenceMatcher.
#pragma once

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

template <class Entry>
class BasicRowAssembler {
 public:
  // horizon_frames >= 1 (gate.row_horizon_frames).
  explicit BasicRowAssembler(std::int64_t horizon_frames) : horizon_frames_(horizon_frames) {
    if (horizon_frames < 1) {
      throw std::invalid_argument("RowAssembler: horizon_frames must be >= 1, got " +
                                  std::to_string(horizon_frames));
    }
  }

  // The open row i, to append its new cells to. Throws std::logic_error when row i was already released.
  std::vector<Entry>& row(std::int64_t i) {
    if (i < next_row_) {
      throw std::logic_error("RowAssembler: cells for row " + std::to_string(i) +
                             " after it went to the matcher (next row " + std::to_string(next_row_) + ")");
    }
    return rows_[i];
  }
  // Frame `current` is complete: rows [next_row(), current - horizon_frames] go to push(i, row) in order.
  template <class Push>
  void advance(std::int64_t current, Push&& push) {
    if (current >= horizon_frames_ - 1) finish(current - horizon_frames_ + 1, push);
  }
  // End of stream: rows [next_row(), end) go to push(i, row) in order.
  template <class Push>
  void finish(std::int64_t end, Push&& push) {
    static const std::vector<Entry> kEmpty;
    for (; next_row_ < end; ++next_row_) {
      const auto it = rows_.find(next_row_);
      if (it == rows_.end()) {
        push(next_row_, kEmpty);
      } else {
        push(next_row_, it->second);
        rows_.erase(it);
      }
    }
  }

  std::int64_t next_row() const { return next_row_; }  // the first row not yet released
  std::size_t open_rows() const { return rows_.size(); }
  std::int64_t horizon_frames() const { return horizon_frames_; }

 private:
  std::int64_t horizon_frames_;
  std::int64_t next_row_ = 0;
  std::map<std::int64_t, std::vector<Entry>> rows_;  // open rows with cells
};

// DIRD's: final rows of similarities go to the SequenceMatcher.
class RowAssembler : public BasicRowAssembler<SimilarityEntry> {
 public:
  using BasicRowAssembler::advance;
  using BasicRowAssembler::BasicRowAssembler;
  using BasicRowAssembler::finish;
  void advance(std::int64_t current, SequenceMatcher& matcher, MatchOutput& out) {
    advance(current, [&](std::int64_t i, const std::vector<SimilarityEntry>& r) { matcher.push(i, r, out); });
  }
  void finish(std::int64_t end, SequenceMatcher& matcher, MatchOutput& out) {
    finish(end, [&](std::int64_t i, const std::vector<SimilarityEntry>& r) { matcher.push(i, r, out); });
  }
};

}  // namespace loopgate
