#include "pipeline/methods/gated_cells.hpp"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/error.hpp"
#include "io/writers.hpp"
#include "pipeline/frame/frame_steps.hpp"

namespace loopgate {

PoseGatedCells::PoseGatedCells(const MethodContext& context)
    : context_(context),
      pose_gate_(context.config.gate, "odometry (gate)"),
      tracker_(context.config.gate, context.config.match.sequence_length, context.config.match.margin),
      frames_(context.capacity),
      row_cells_(context.capacity, 0),
      requested_by_(context.capacity),
      feedback_(context.feedback) {
  for (std::atomic<std::int64_t>& by : requested_by_) by.store(-1, std::memory_order_relaxed);
  if (context.capacity > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    throw std::invalid_argument("PoseGatedCells: more than 2^31 - 1 frames");
  pose_gate_.reserve(context.capacity);
  context.images.keep_recent(static_cast<std::size_t>(std::max(0, context.config.run.image_cache_frames)));
  if (feedback_) poses_.resize(context.capacity);
}

std::optional<std::size_t> PoseGatedCells::seq_of(std::size_t frame, std::size_t end_seq) const {
  std::size_t lo = 0, hi = end_seq;  // seqs.frame() increases with seq
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (context_.seqs.frame(static_cast<std::int64_t>(mid)) < frame) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  if (lo < end_seq && context_.seqs.frame(static_cast<std::int64_t>(lo)) == frame) return lo;
  return std::nullopt;
}

void PoseGatedCells::reanchor_frame(std::size_t seq, Eigen::Isometry3d& T_w_b, Eigen::Matrix3d& P_m2,
                                    GateFrame& g) {
  const std::size_t lag = feedback_->lag_frames();
  if (lag == 0) throw std::logic_error("gate feedback: the lag L was not set before the run");
  if (seq < lag) return;
  const std::size_t last_query_frame = context_.seqs.frame(static_cast<std::int64_t>(seq - lag));
  std::size_t q = 0, r = 0;
  const auto usable = [&](const FeedbackLoop& loop) {
    const auto sq = seq_of(loop.query, seq);
    const auto sr = seq_of(loop.reference, seq);
    if (!sq || !sr || !poses_[*sq].stored || !poses_[*sr].stored) return false;
    q = *sq;
    r = *sr;
    return true;
  };
  const std::optional<FeedbackLoop> loop = feedback_->anchor_through(last_query_frame, usable);
  if (!loop) return;
  LoopAnchor anchor;
  anchor.T_w_q_odo = poses_[q].T_w_odo;
  anchor.P_q_odo_m2 = poses_[q].P_odo_m2;
  anchor.T_w_r = poses_[r].T_w_gate;
  anchor.P_r_m2 = poses_[r].P_gate_m2;
  anchor.T_r_q = loop->T_r_q;
  anchor.P_loop_r_m2 = loop->P_loop_r_m2;
  const ReanchoredPose pose = reanchor(anchor, T_w_b, P_m2);
  T_w_b = pose.T_w_i;
  P_m2 = pose.P_m2;
  g.anchor_query = static_cast<std::int32_t>(q);
  g.anchor_reference = static_cast<std::int32_t>(r);
  g.growth_clamped = pose.growth_clamped;
}

void PoseGatedCells::gate(FrameRecord& r, bool describe_own_frame) {
  const auto seq = static_cast<std::int64_t>(r.seq);
  GateFrame& g = frames_[r.seq];
  GateDecision decision;
  decision.frame = seq;
  if (r.usable_pose()) {
    try {
      Eigen::Isometry3d T_w_b = r.odometry.pose.T_w_b;
      Eigen::Matrix3d P_m2 = r.odometry.pose.position_cov_m2();
      if (feedback_) reanchor_frame(r.seq, T_w_b, P_m2, g);
      decision = pose_gate_.process(seq, T_w_b.translation(), P_m2);
      if (feedback_) {
        poses_[r.seq] = FramePoses{true, r.odometry.pose.T_w_b, r.odometry.pose.position_cov_m2(), T_w_b,
                                   0.5 * (P_m2 + P_m2.transpose())};
        if (g.anchor_query >= 0) {
          ++frames_reanchored_;
          growth_clamped_ += g.growth_clamped ? 1 : 0;
          const std::pair<std::int64_t, std::int64_t> anchor(g.anchor_query, g.anchor_reference);
          if (anchors_used_.empty() || anchors_used_.back() != anchor) anchors_used_.push_back(anchor);
        }
      }
      g.ran = true;
      ++frames_gate_ran_;
      if (decision.gated) ++frames_gated_;
    } catch (const DataError& e) {
      add_message(r.warnings, std::string("gate: pose not usable: ") + e.what());
      ++gate_errors_;
      g.anchor_query = g.anchor_reference = -1;
      decision = GateDecision{};
      decision.frame = seq;
    }
  }
  g.distance_m = decision.distance_m;
  g.threshold_m = decision.threshold_m;
  g.sigma_m = decision.sigma_m;
  g.nearest_seq = static_cast<std::int32_t>(decision.nearest_frame);
  g.has_nearest = decision.has_nearest;
  g.gated = decision.gated;
  AreaUpdate update = tracker_.update(decision);
  g.area_id = update.joined_area;
  g.cells = std::move(update.new_cells);
  g.describe = std::move(update.new_descriptor_frames);
  // The method's own request goes through the tracker's set, so that no later cell asks for it again.
  if (describe_own_frame && tracker_.request_descriptor(seq)) g.describe.push_back(seq);
  for (const std::int64_t k : g.describe) {
    describe_requests_.emplace_back(k, seq);
    requested_by_[static_cast<std::size_t>(k)].store(static_cast<std::int64_t>(seq),
                                                     std::memory_order_relaxed);
  }
}

bool PoseGatedCells::requested_within(std::size_t seq, int delay_frames) const {
  const std::int64_t by = requested_by_[seq].load(std::memory_order_relaxed);
  return by >= 0 && by <= static_cast<std::int64_t>(seq) + delay_frames;
}

bool PoseGatedCells::request_descriptor(std::size_t by_seq, std::int64_t frame) {
  if (frame < 0 || frame > static_cast<std::int64_t>(by_seq)) {
    throw std::logic_error("descriptor of frame seq " + std::to_string(frame) + " requested by seq " +
                           std::to_string(by_seq) + ": only frames up to the requesting one");
  }
  if (!tracker_.request_descriptor(frame)) return false;
  std::vector<std::int64_t>& list = frames_[by_seq].describe;
  list.insert(std::upper_bound(list.begin(), list.end(), frame), frame);
  describe_requests_.emplace_back(frame, static_cast<std::int64_t>(by_seq));
  requested_by_[static_cast<std::size_t>(frame)].store(static_cast<std::int64_t>(by_seq),
                                                       std::memory_order_relaxed);
  return true;
}

bool PoseGatedCells::described_at_own_time(std::size_t seq) const {
  const std::vector<std::int64_t>& list = frames_[seq].describe;
  return !list.empty() && list.back() == static_cast<std::int64_t>(seq);
}

std::vector<CellSpan> PoseGatedCells::take_cells(std::size_t seq) {
  GateFrame& g = frames_[seq];
  std::vector<CellSpan> cells;
  cells.swap(g.cells);
  for (const CellSpan& span : cells)
    row_cells_[static_cast<std::size_t>(span.i)] += static_cast<std::uint32_t>(span.j1 - span.j0 + 1);
  return cells;
}

void PoseGatedCells::add_frame_cells(const FrameRecord& r, CsvRow& row) const {
  const GateFrame& g = frames_[r.seq];
  const bool has_nearest = g.ran && g.has_nearest;
  row.add("nearest_frame", has_nearest ? std::to_string(context_.seqs.label(g.nearest_seq)) : "");
  row.add("gate_d_m", has_nearest ? format_fixed(g.distance_m, 6) : "");
  row.add("gate_threshold_m", g.ran ? format_fixed(g.threshold_m, 6) : "");
  row.add("gated", g.gated ? "y" : "n");
  row.add("area_id", std::to_string(g.area_id));
  if (feedback_) {
    row.add("gate_sigma_m", g.ran ? format_fixed(g.sigma_m, 6) : "");
    const bool anchored = g.anchor_query >= 0;
    row.add("gate_anchor_i", anchored ? std::to_string(context_.seqs.label(g.anchor_query)) : "");
    row.add("gate_anchor_j", anchored ? std::to_string(context_.seqs.label(g.anchor_reference)) : "");
  }
}

// candidate_areas.csv: one rectangle per area (the bounding box of its cells; rows = query frames i,
// columns = reference frames j, inclusive); candidate_cells.csv: the cells actually compared, per row as
// disjoint column intervals; descriptors.csv: every frame described, with the frame whose gate update asked
// for it. Frames by their numbers (SeqIndex::label).
void PoseGatedCells::write_files(const std::filesystem::path& out_dir, std::size_t end_seq,
                                 const std::function<bool(std::int64_t)>& computed) const {
  if (end_seq == 0) return;
  const auto last_seq = static_cast<std::int64_t>(end_seq) - 1;
  const auto frame = [&](std::int64_t seq) {
    return std::to_string(context_.seqs.label(std::min(seq, last_seq)));
  };
  CsvWriter areas(out_dir / "candidate_areas.csv", {"id", "row_begin", "row_end", "col_begin", "col_end",
                                                    "i_first", "i_last", "j_min", "j_max", "gated_frames"});
  for (const CandidateArea& a : tracker_.areas()) {
    areas.write_row({std::to_string(a.id), frame(a.row_begin), frame(a.row_end), frame(a.col_begin),
                     frame(a.col_end), frame(a.i_first), frame(a.i_last), frame(a.j_min), frame(a.j_max),
                     std::to_string(a.gated_frames)});
  }
  areas.close();
  CsvWriter cells(out_dir / "candidate_cells.csv", {"i", "j_first", "j_last"});
  for (std::int64_t i = 0; i <= last_seq; ++i) {
    for (const RowColumns& span : tracker_.covered_columns(i))
      cells.write_row({frame(i), frame(span.j0), frame(span.j1)});
  }
  cells.close();
  CsvWriter described(out_dir / "descriptors.csv", {"frame", "requested_by_frame", "computed"});
  for (const auto& [k, by] : describe_requests_)
    described.write_row({frame(k), frame(by), computed(k) ? "y" : "n"});
  described.close();
}

nlohmann::json PoseGatedCells::summary(std::size_t end_seq) const {
  std::size_t cells = 0, rows = 0;
  for (std::size_t seq = 0; seq < end_seq; ++seq) {
    cells += row_cells_[seq];
    rows += row_cells_[seq] > 0 ? 1 : 0;
  }
  nlohmann::json out;
  out["candidate_areas"] = tracker_.areas().size();
  out["gate"] = {
      {"enabled", true},
      {"frames_with_pose", frames_gate_ran_},
      {"frames_gated", frames_gated_},
      {"pass_rate", frames_gate_ran_ ? static_cast<double>(frames_gated_) / frames_gate_ran_ : 0.0},
      {"pose_errors", gate_errors_},
      {"candidate_areas", tracker_.areas().size()},
      {"cells", cells},
      {"rows_with_cells", rows},
      {"kdtree_frames", pose_gate_.frames_in_tree()}};
  nlohmann::json feedback = {{"enabled", feedback_ != nullptr}};
  if (feedback_) {
    feedback["lag_frames"] = feedback_->lag_frames();
    feedback["frames_reanchored"] = frames_reanchored_;
    feedback["anchor_loops"] = anchors_used_.size();
    feedback["growth_clamped"] = growth_clamped_;
    feedback["frames_waited"] = feedback_->frames_waited();
    feedback["wait_ms"] = feedback_->wait_ms();
  }
  out["gate"]["feedback"] = std::move(feedback);
  return out;
}

}  // namespace loopgate
