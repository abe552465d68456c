// The pose gate of a gated method (docs/gating.md): the gate (eq. 8-10) and the candidate-area tracker
// per frame, the cells each frame's update newly covers and the frames that newly need a descriptor, and
// everything the run reports about them (frames.csv gate columns, candidate_areas.csv, candidate_cells.csv,
// descriptors.csv, the summary's "gate" block, the evaluation's coverage). Every gated method (DIRD raw or
// standardised, SeqSLAM) owns one and differs only in what it computes for the cells.
//
// Threading: gate() is called serially in sequence order (the gate node); describe_list(seq) may be read by
// the describe node of frame seq after its gate(); take_cells(seq) by one serial node, after gate(seq) (DIRD:
// the match node; gated SeqSLAM: its gate node, which needs the cells to request their neighbours);
// request_descriptor(seq, ...) by the gate node right after gate(seq); the rest after finish().
#pragma once

#include <spdlog/fmt/fmt.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/csv_row.hpp"
#include "pipeline/frame/frame_record.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/frame/gate_feedback.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "stages/gate/candidate_areas.hpp"
#include "stages/gate/pose_gate.hpp"
#include "stages/gate/reanchor.hpp"
#include "stages/match/row_assembler.hpp"

namespace loopgate {

class PoseGatedCells {
 public:
  // Keeps the image cache (run.image_cache_frames) so that describe can read recent frames again.
  explicit PoseGatedCells(const MethodContext& context);

  // The gate's decision for frame r.seq (frames without a usable pose are not gated and not stored) and
  // the candidate-area update. With gate.feedback (context.feedback) the pose and covariance the gate uses
  // are re-anchored through the latest verified loop of a query frame <= frame(seq - L) (waiting for the
  // loop closer until every such loop is verified, gate_feedback.hpp). `describe_own_frame`: the method wants
  // frame r.seq's descriptor at its own time even when the gate does not ask for it (e.g. every k-th frame
  // for causal statistics).
  void gate(FrameRecord& r, bool describe_own_frame = false);

  // The method also wants the descriptor of `frame` (<= by_seq), outside the cells (gated SeqSLAM: the
  // sequence and contrast-window neighbours of its cells), computed by frame by_seq's describe. Call after
  // gate(by_seq). True when the frame was not requested before: it then joins describe_list(by_seq) and
  // descriptors.csv, and no later update asks for it again.
  bool request_descriptor(std::size_t by_seq, std::int64_t frame);

  // The frames (seqs, ascending) whose descriptors frame seq's describe computes.
  const std::vector<std::int64_t>& describe_list(std::size_t seq) const { return frames_[seq].describe; }
  // Whether frame seq's own descriptor is computed at its own time (by its own describe).
  bool described_at_own_time(std::size_t seq) const;
  // Whether frame seq's descriptor was requested by a frame <= seq + delay_frames (whose describe has run
  // once that frame has passed the match node). frames.csv's `descriptor` column asks it with the method's
  // verdict delay, so that the column does not depend on how far the describe node ran ahead when the row
  // was written. Any thread.
  bool requested_within(std::size_t seq, int delay_frames) const;
  // The cells frame seq's update covered (moved out; counted per row). Call once per frame, in order.
  std::vector<CellSpan> take_cells(std::size_t seq);
  // No cell was ever added to row seq (the frame lies outside every candidate area).
  bool row_empty(std::size_t seq) const { return row_cells_[seq] == 0; }
  void finish() { tracker_.finish(); }

  // frames.csv: nearest_frame, gate_d_m, gate_threshold_m, gated, area_id; with gate.feedback also
  // gate_sigma_m (the sigma the gate used), gate_anchor_i, gate_anchor_j (the loop it was re-anchored
  // through).
  void add_frame_cells(const FrameRecord& r, CsvRow& row) const;
  // candidate_areas.csv, candidate_cells.csv and descriptors.csv (`computed(seq)`: the descriptor exists)
  // for the frames [0, end_seq).
  void write_files(const std::filesystem::path& out_dir, std::size_t end_seq,
                   const std::function<bool(std::int64_t)>& computed) const;
  // "candidate_areas" and "gate" of summary.json, over the frames [0, end_seq).
  nlohmann::json summary(std::size_t end_seq) const;
  bool covers(std::int64_t i, std::int64_t j) const { return tracker_.covers(i, j); }
  const CandidateAreaTracker& tracker() const { return tracker_; }

 private:
  // Per sequence number (kept for the whole run: 96 bytes a frame): what frames.csv shows of the gate's
  // decision, the area joined, the loop the pose was re-anchored through, and the frame's lists. Seqs fit in
  // 32 bits (the constructor checks the capacity).
  struct GateFrame {
    double distance_m = 0, threshold_m = 0, sigma_m = 0;  // the decision's (GateDecision)
    std::int32_t nearest_seq = -1;                        // the decision's nearest_frame (-1: none)
    std::int32_t area_id = -1;
    std::int32_t anchor_query = -1;  // gate.feedback: the loop (seqs) the pose was re-anchored through
    std::int32_t anchor_reference = -1;
    bool ran = false, has_nearest = false, gated = false;
    bool growth_clamped = false;         // the odometry's covariance growth since the loop was not PSD
    std::vector<std::int64_t> describe;  // seqs whose descriptors this frame's describe computes
    std::vector<CellSpan> cells;         // cells its match computes
  };
  // gate.feedback: the poses of a frame the gate stored (by seq).
  struct FramePoses {
    bool stored = false;
    Eigen::Isometry3d T_w_odo = Eigen::Isometry3d::Identity();  // the odometry's
    Eigen::Matrix3d P_odo_m2 = Eigen::Matrix3d::Zero();
    Eigen::Isometry3d T_w_gate = Eigen::Isometry3d::Identity();  // what the gate used (the map)
    Eigen::Matrix3d P_gate_m2 = Eigen::Matrix3d::Zero();
  };
  // gate.feedback: re-anchors (T_w_b, P_m2) of frame seq in place when a verified loop applies.
  void reanchor_frame(std::size_t seq, Eigen::Isometry3d& T_w_b, Eigen::Matrix3d& P_m2, GateFrame& g);
  // The sequence number of dataset frame `frame` among [0, end_seq), if it was released.
  std::optional<std::size_t> seq_of(std::size_t frame, std::size_t end_seq) const;

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  PoseGate pose_gate_;
  CandidateAreaTracker tracker_;
  std::vector<GateFrame> frames_;
  std::vector<std::uint32_t> row_cells_;  // cells per row (match node)
  // The seq whose describe computes frame k's descriptor (-1: not requested); written by the gate node.
  std::vector<std::atomic<std::int64_t>> requested_by_;
  std::size_t frames_gate_ran_ = 0, frames_gated_ = 0, gate_errors_ = 0;
  std::vector<std::pair<std::int64_t, std::int64_t>> describe_requests_;  // (seq described, requesting seq)
  GateFeedback* feedback_ = nullptr;                                      // gate.feedback (nullptr: off)
  std::vector<FramePoses> poses_;                                         // by seq, only with feedback
  std::size_t frames_reanchored_ = 0, growth_clamped_ = 0;
  std::vector<std::pair<std::int64_t, std::int64_t>>
      anchors_used_;  // (q, r) seqs of the loops used, distinct
};

// The describe step of a gated method: work(seq, image) for every frame of `seqs` (several in parallel),
// with the current frame's decoded image when decode has it and every other frame read again (recent ones
// from the image cache); a frame that cannot be read gets work(seq, nullptr) and a warning on r. The time of
// every read (CPU) is added to r.reread_cpu_ns (the time accounting books it as decode).
template <class Work>
void describe_frames(FrameRecord& r, const std::vector<std::int64_t>& seqs, const MethodContext& context,
                     Work work) {
  std::vector<std::string> problems(seqs.size());
  const auto describe_one = [&](std::size_t index) {
    const auto k = static_cast<std::size_t>(seqs[index]);
    if (k == r.seq && r.decoded) {
      work(k, &r.image);
      return;
    }
    cv::Mat image;
    const std::int64_t start_ns = thread_cpu_ns();
    // The read is a decode wherever it runs: booked as decode, not describe (r.reread_cpu_ns).
    const auto book_read = [&] {
      r.reread_cpu_ns.fetch_add(thread_cpu_ns() - start_ns, std::memory_order_relaxed);
    };
    try {
      image = context.images.read_again(k);
      book_read();
    } catch (const DataError& e) {
      book_read();
      problems[index] =
          fmt::format("describe: frame {} could not be read: {}", context.seqs.frame(seqs[index]), e.what());
      work(k, static_cast<const cv::Mat*>(nullptr));
      return;
    }
    work(k, &image);
  };
  if (seqs.size() > 1) {
    parallel_for_with_handoff(seqs.size(), describe_one);
  } else if (seqs.size() == 1) {
    describe_one(0);
  }
  for (auto& problem : problems) {
    if (!problem.empty()) add_message(r.warnings, std::move(problem));
  }
}

// What a gated DIRD method (the paper's matcher, on raw or standardised descriptors) does whatever its
// descriptors: the pose gate's cells, rows kept open for gate.row_horizon_frames (RowAssembler) and then
// the sequence matcher, and everything reported about them. `Dird` gives loops() (LoopMatching),
// valid(seq) (a descriptor was computed), detection(seq, outside_areas, requested), summary() and
// example_descriptor(); the method adds gate(), describe() and match(), which fills rows_ and calls
// advance().
template <class Dird>
class GatedDirdMethod : public DetectionMethod {
 public:
  explicit GatedDirdMethod(const MethodContext& context)
      : context_(context), dird_(context), cells_(context), rows_(context.config.gate.row_horizon_frames) {}
  std::string name() const override { return "dird"; }
  std::string mode() const override { return "gated"; }

  void finish() override {
    cells_.finish();
    MatchOutput output;
    rows_.finish(static_cast<std::int64_t>(match_end_seq_), dird_.loops().matcher(), output);
    dird_.loops().handle(output);
    dird_.loops().flush();
  }

  void add_frame_cells(const FrameRecord& r, CsvRow& row) const override { cells_.add_frame_cells(r, row); }
  // Row s goes to the matcher at match(s + horizon) (RowAssembler), its verdict is final NMS-delay rows
  // later.
  std::optional<int> verdict_delay_frames() const override {
    return context_.config.gate.row_horizon_frames + static_cast<int>(dird_.loops().emission_delay());
  }
  std::optional<FrameVerdict> detection(std::size_t seq) override {
    return dird_.detection(seq, cells_.row_empty(seq), cells_.requested_within(seq, *verdict_delay_frames()));
  }
  void write_files(const std::filesystem::path& out_dir) const override {
    cells_.write_files(out_dir, match_end_seq_,
                       [this](std::int64_t k) { return dird_.valid(static_cast<std::size_t>(k)); });
  }
  nlohmann::json summary() const override {
    nlohmann::json out = dird_.summary();
    out.update(cells_.summary(match_end_seq_));
    return out;
  }
  MethodEvaluation evaluation() const override {
    MethodEvaluation e;
    e.covers = [this](std::int64_t i, std::int64_t j) { return cells_.covers(i, j); };
    return e;
  }
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const override {
    return dird_.example_descriptor();
  }

 protected:
  // After match() filled frame seq's cells into rows_: the rows older than the horizon go to the matcher.
  void advance(std::size_t seq) {
    match_end_seq_ = seq + 1;
    MatchOutput output;
    rows_.advance(static_cast<std::int64_t>(seq), dird_.loops().matcher(), output);
    dird_.loops().handle(output);
  }

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  Dird dird_;
  PoseGatedCells cells_;
  RowAssembler rows_;

 private:
  std::size_t match_end_seq_ = 0;
};

}  // namespace loopgate
