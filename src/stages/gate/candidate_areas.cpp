#include "stages/gate/candidate_areas.hpp"

#include <algorithm>
#include <cstdlib>
#include <string>

#include "core/error.hpp"

namespace loopgate {

CandidateAreaTracker::CandidateAreaTracker(const GateConfig& config, int sequence_length,
                                           int pair_margin_frames)
    : config_(config), pair_margin_frames_(pair_margin_frames) {
  config_.validate();
  config_.validate_for_sequence_length(sequence_length);
  if (pair_margin_frames < 0) throw ConfigError("match.margin: must be >= 0 frames");
}

void CandidateAreaTracker::set_rectangle(CandidateArea& area) const {
  area.row_begin = std::max<std::int64_t>(0, area.i_first - config_.area_margin_query_frames);
  area.row_end = area.i_last;
  area.col_begin = std::max<std::int64_t>(0, area.j_min - config_.area_margin_reference_frames);
  area.col_end = area.j_max + config_.area_margin_reference_frames;
}

void CandidateAreaTracker::cover_row(std::int64_t i, std::int64_t lo, std::int64_t hi, AreaUpdate& out) {
  if (i < last_frame_ - static_cast<std::int64_t>(config_.row_horizon_frames)) return;  // final row
  hi = std::min(hi, i - static_cast<std::int64_t>(pair_margin_frames_));
  lo = std::max<std::int64_t>(lo, 0);
  if (hi < lo) return;
  std::vector<Interval>& row = covered_[i];
  // Parts of [lo, hi] not yet covered, walking the disjoint ascending intervals of the row.
  std::int64_t cursor = lo;
  for (const Interval& c : row) {
    if (c.hi < cursor) continue;
    if (c.lo > hi) break;
    if (c.lo > cursor) out.new_cells.push_back({i, cursor, c.lo - 1});
    cursor = std::max(cursor, c.hi + 1);
    if (cursor > hi) break;
  }
  if (cursor <= hi) out.new_cells.push_back({i, cursor, hi});
  // Merge [lo, hi] into the row.
  std::vector<Interval> merged;
  merged.reserve(row.size() + 1);
  Interval add{lo, hi};
  bool placed = false;
  for (const Interval& c : row) {
    if (c.hi + 1 < add.lo) {
      merged.push_back(c);
    } else if (add.hi + 1 < c.lo) {
      if (!placed) merged.push_back(add), placed = true;
      merged.push_back(c);
    } else {
      add.lo = std::min(add.lo, c.lo);
      add.hi = std::max(add.hi, c.hi);
    }
  }
  if (!placed) merged.push_back(add);
  row = std::move(merged);
}

void CandidateAreaTracker::cover_area_rows(const CandidateArea& area, std::int64_t first_row,
                                           AreaUpdate& out) {
  for (std::int64_t i = std::max(first_row, area.row_begin); i <= area.row_end; ++i) {
    cover_row(i, area.col_begin, area.col_end, out);
  }
}

AreaUpdate CandidateAreaTracker::update(const GateDecision& decision) {
  const std::int64_t i = decision.frame;
  if (i <= last_frame_ || i < 0) {
    throw DataError("gate", "frame " + std::to_string(i) +
                                ": frames must be >= 0 and strictly increasing (previous " +
                                std::to_string(last_frame_) + ")");
  }
  last_frame_ = i;
  AreaUpdate out;
  out.frame = i;

  // Areas that can no longer accept a frame (more than max_hole frames since their last gated frame).
  const std::int64_t max_step = static_cast<std::int64_t>(config_.area_max_hole_frames) + 1;
  std::vector<int> still_open;
  for (const int id : open_ids_) {
    CandidateArea& area = areas_[static_cast<std::size_t>(id)];
    if (i - area.i_last > max_step) {
      area.open = false;
      out.closed.push_back(id);
    } else {
      still_open.push_back(id);
    }
  }
  open_ids_ = std::move(still_open);

  // A hit whose nearest is closer in time than the pair margin cannot be a loop the matcher compares
  // (i - j < margin): it neither opens nor grows an area.
  if (decision.gated && decision.has_nearest &&
      i - decision.nearest_frame >= static_cast<std::int64_t>(pair_margin_frames_)) {
    const std::int64_t j = decision.nearest_frame;
    int best_id = -1;
    std::int64_t best_jump = 0;
    for (const int id : open_ids_) {  // ascending ids: ties keep the smallest
      const CandidateArea& area = areas_[static_cast<std::size_t>(id)];
      const std::int64_t jump = std::llabs(j - area.j_last);
      if (jump > config_.area_j_tolerance_frames + (i - area.i_last)) continue;
      if (best_id < 0 || jump < best_jump) {
        best_id = id;
        best_jump = jump;
      }
    }
    if (best_id >= 0) {
      CandidateArea& area = areas_[static_cast<std::size_t>(best_id)];
      const std::int64_t old_row_end = area.row_end;
      const std::int64_t old_col_begin = area.col_begin;
      const std::int64_t old_col_end = area.col_end;
      area.i_last = i;
      area.j_last = j;
      area.j_min = std::min(area.j_min, j);
      area.j_max = std::max(area.j_max, j);
      ++area.gated_frames;
      set_rectangle(area);
      const bool columns_grew = area.col_begin != old_col_begin || area.col_end != old_col_end;
      cover_area_rows(area, columns_grew ? area.row_begin : old_row_end + 1, out);
      out.joined_area = best_id;
    } else {
      CandidateArea area;
      area.id = static_cast<int>(areas_.size());
      area.i_first = area.i_last = i;
      area.j_min = area.j_max = area.j_last = j;
      area.gated_frames = 1;
      set_rectangle(area);
      areas_.push_back(area);
      open_ids_.push_back(area.id);
      cover_area_rows(areas_.back(), areas_.back().row_begin, out);
      out.joined_area = area.id;
      out.opened = true;
    }
  }

  for (const CellSpan& span : out.new_cells) {
    if (requests_.request(span.i)) out.new_descriptor_frames.push_back(span.i);
    for (std::int64_t j = span.j0; j <= span.j1; ++j) {
      if (requests_.request(j)) out.new_descriptor_frames.push_back(j);
    }
  }
  std::sort(out.new_descriptor_frames.begin(), out.new_descriptor_frames.end());
  return out;
}

std::vector<int> CandidateAreaTracker::finish() {
  std::vector<int> closed;
  for (const int id : open_ids_) {
    areas_[static_cast<std::size_t>(id)].open = false;
    closed.push_back(id);
  }
  open_ids_.clear();
  return closed;
}

std::vector<RowColumns> CandidateAreaTracker::columns_for_row(std::int64_t i) const {
  std::vector<RowColumns> out;
  for (const CandidateArea& area : areas_) {
    if (i < area.row_begin || i > area.row_end) continue;
    const std::int64_t hi = std::min(area.col_end, i - static_cast<std::int64_t>(pair_margin_frames_));
    if (hi < area.col_begin) continue;
    out.push_back({area.id, area.col_begin, hi});
  }
  return out;
}

std::vector<RowColumns> CandidateAreaTracker::covered_columns(std::int64_t i) const {
  std::vector<RowColumns> out;
  const auto it = covered_.find(i);
  if (it == covered_.end()) return out;
  for (const Interval& c : it->second) out.push_back({-1, c.lo, c.hi});
  return out;
}

bool CandidateAreaTracker::covers(std::int64_t i, std::int64_t j) const {
  const auto it = covered_.find(i);
  if (it == covered_.end()) return false;
  for (const Interval& c : it->second) {
    if (j >= c.lo && j <= c.hi) return true;
  }
  return false;
}

}  // namespace loopgate
