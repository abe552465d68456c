#include "stages/match/row_assembler.hpp"

#include <stdexcept>
#include <string>

namespace loopgate {

RowAssembler::RowAssembler(std::int64_t horizon_frames) : horizon_frames_(horizon_frames) {
  if (horizon_frames < 1) {
    throw std::invalid_argument("RowAssembler: horizon_frames must be >= 1, got " +
                                std::to_string(horizon_frames));
  }
}

std::vector<SimilarityEntry>& RowAssembler::row(std::int64_t i) {
  if (i < next_row_) {
    throw std::logic_error("RowAssembler: cells for row " + std::to_string(i) +
                           " after it went to the matcher (next row " + std::to_string(next_row_) + ")");
  }
  return rows_[i];
}

void RowAssembler::advance(std::int64_t current, SequenceMatcher& matcher, MatchOutput& out) {
  if (current >= horizon_frames_ - 1) finish(current - horizon_frames_ + 1, matcher, out);
}

void RowAssembler::finish(std::int64_t end, SequenceMatcher& matcher, MatchOutput& out) {
  for (; next_row_ < end; ++next_row_) {
    const auto it = rows_.find(next_row_);
    if (it == rows_.end()) {
      matcher.push(next_row_, {}, out);
    } else {
      matcher.push(next_row_, it->second, out);
      rows_.erase(it);
    }
  }
}

}  // namespace loopgate
