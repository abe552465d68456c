// Streaming assembly of sparse similarity rows for the gated run (pose-gating.md §4-5): a candidate area adds
// cells (query row i, reference columns j) to rows behind the current frame, so a row stays open for
// `horizon_frames` frames after it arrived and only then goes, complete, to the SequenceMatcher (which needs
// its rows in order). Rows without cells go to the matcher empty.
//
// At frame `current`, rows <= current - horizon_frames are final: advance(current) releases them. A cell
// for a released row is a logic error (the candidate-area tracker never reports one: its own horizon is the
// same). finish(end) releases every row < end at the end of the stream.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

class RowAssembler {
 public:
  // horizon_frames >= 1 (gate.row_horizon_frames).
  explicit RowAssembler(std::int64_t horizon_frames);

  // The open row i, to append its new cells' similarities to. Throws std::logic_error when row i was
  // already released to the matcher.
  std::vector<SimilarityEntry>& row(std::int64_t i);
  // Frame `current` is complete: rows [next_row(), current - horizon_frames] go to `matcher` in order.
  void advance(std::int64_t current, SequenceMatcher& matcher, MatchOutput& out);
  // End of stream: rows [next_row(), end) go to `matcher` in order.
  void finish(std::int64_t end, SequenceMatcher& matcher, MatchOutput& out);

  std::int64_t next_row() const { return next_row_; }  // the first row not yet released
  std::size_t open_rows() const { return rows_.size(); }
  std::int64_t horizon_frames() const { return horizon_frames_; }

 private:
  std::int64_t horizon_frames_;
  std::int64_t next_row_ = 0;
  std::map<std::int64_t, std::vector<SimilarityEntry>> rows_;  // open rows with cells
};

}  // namespace loopgate
