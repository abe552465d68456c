// Streaming clustering of gated frames into candidate areas (docs/gating.md § Candidate areas, paper §4.2 and
// Fig. 6).
//
// Feed every frame's GateDecision in order. Gated frames whose nearest j is too recent for the matcher
// (i - j < pair_margin) are ignored: they are along-track neighbours, not loops. A gated frame i with
// nearest j joins an open cluster when
//   i - i_last <= area_max_hole_frames + 1   and   |j - j_last| <= area_j_tolerance_frames + (i - i_last)
// (i_last, j_last: the cluster's latest gated frame and its nearest); among several, the one with the
// smallest |j - j_last| (then the smallest id). Otherwise it opens a new cluster. A cluster's candidate
// area is the rectangle
//   rows (query i)      [max(0, i_first - m_i), i_last]
//   columns (reference) [max(0, j_min - m_j), j_max + m_j], and per row i also j <= i - pair_margin
// which grows as frames join. Rows older than the current frame minus row_horizon_frames are final and
// take no new cells (a streaming consumer can finish them). Every update reports the cells (row, column
// interval) that became covered for the first time by any area, and the frames that newly need a descriptor
// (rows and columns of those cells), each frame at most once over the whole run.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "stages/gate/descriptor_requests.hpp"
#include "stages/gate/gate_config.hpp"
#include "stages/gate/pose_gate.hpp"

namespace loopgate {

struct CandidateArea {
  int id = 0;
  // Cluster extent: first/last gated query frame, nearest-j range and the latest nearest j.
  std::int64_t i_first = 0;
  std::int64_t i_last = 0;
  std::int64_t j_min = 0;
  std::int64_t j_max = 0;
  std::int64_t j_last = 0;
  std::int64_t gated_frames = 0;
  // Rectangle with margins, inclusive: rows [row_begin, row_end], columns [col_begin, col_end].
  std::int64_t row_begin = 0;
  std::int64_t row_end = 0;
  std::int64_t col_begin = 0;
  std::int64_t col_end = 0;
  bool open = true;  // false once more than area_max_hole_frames frames passed without a join
};

// Inclusive interval of reference frames [j0, j1] for query row i.
struct CellSpan {
  std::int64_t i = 0;
  std::int64_t j0 = 0;
  std::int64_t j1 = 0;
};

// Reference columns [j0, j1] that area `area_id` asks row i to be compared with.
struct RowColumns {
  int area_id = 0;
  std::int64_t j0 = 0;
  std::int64_t j1 = 0;
};

struct AreaUpdate {
  std::int64_t frame = -1;
  int joined_area = -1;             // area this frame's gate hit opened or grew; -1 when not gated
  bool opened = false;              // joined_area was created by this frame
  std::vector<int> closed;          // areas that stopped accepting frames at this update
  std::vector<CellSpan> new_cells;  // cells covered for the first time (disjoint from all earlier ones)
  std::vector<std::int64_t> new_descriptor_frames;  // ascending, never reported before
};

class CandidateAreaTracker {
 public:
  // sequence_length: the DP's L (area_margin_query_frames must be >= L, else ConfigError);
  // pair_margin_frames: only cells with i - j >= pair_margin_frames exist (match.margin, >= 0).
  CandidateAreaTracker(const GateConfig& config, int sequence_length, int pair_margin_frames);

  // Frames strictly increasing (DataError otherwise, source "gate"). After update(i), rows <= i -
  // row_horizon_frames never get another cell.
  AreaUpdate update(const GateDecision& decision);
  // Closes every open area (end of stream).
  std::vector<int> finish();

  const std::vector<CandidateArea>& areas() const { return areas_; }
  // Areas having row i, with the columns each asks for (empty spans omitted), by area id.
  std::vector<RowColumns> columns_for_row(std::int64_t i) const;
  // Union over all areas of the columns of row i, as disjoint ascending intervals.
  std::vector<RowColumns> covered_columns(std::int64_t i) const;
  bool covers(std::int64_t i, std::int64_t j) const;
  const DescriptorRequests& descriptor_requests() const { return requests_; }
  // Marks `frame` as described outside the cells (a method's own request); true when it was not yet
  // requested. Later updates never report it in new_descriptor_frames.
  bool request_descriptor(std::int64_t frame) { return requests_.request(frame); }

 private:
  struct Interval {
    std::int64_t lo;
    std::int64_t hi;
  };
  void cover_row(std::int64_t i, std::int64_t lo, std::int64_t hi, AreaUpdate& out);
  void cover_area_rows(const CandidateArea& area, std::int64_t first_row, AreaUpdate& out);
  void set_rectangle(CandidateArea& area) const;

  GateConfig config_;
  int pair_margin_frames_;
  std::int64_t last_frame_ = -1;
  std::vector<CandidateArea> areas_;
  std::vector<int> open_ids_;
  std::map<std::int64_t, std::vector<Interval>> covered_;  // row -> disjoint ascending column intervals
  DescriptorRequests requests_;
};

}  // namespace loopgate
