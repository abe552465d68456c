// dird-seqslam, full and gated (docs/illumination.md): DIRD distances (DirdDistances: raw, or standardised
// with causal statistics, the default) matched by contrast enhancement and sequence search
// (ContrastSequenceSearch). Full: every frame described, its row against every frame j <= seq - margin.
// Gated: the pose gate's cells (PoseGatedCells), rows kept open for gate.row_horizon_frames
// (BasicRowAssembler), then the search. Both give a frame's verdict match.sequence_length - 1 rows after
// its own row reached the search; loops.csv holds one loop per query, its best line when the line's mean z
// is at least dird_seqslam.min_score; the PR sweep runs over every query's best line.
#include <spdlog/fmt/fmt.h>

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <vector>

#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/dird_distances.hpp"
#include "pipeline/methods/gated_cells.hpp"
#include "pipeline/methods/viewpoint_distances.hpp"
#include "stages/match/contrast_search.hpp"
#include "stages/match/row_assembler.hpp"

namespace loopgate {

namespace {

// The search, its loops to loops.csv, and the frames' verdicts until the sink reads them.
class ContrastMatching {
 public:
  explicit ContrastMatching(const MethodContext& context)
      : context_(context),
        search_(context.config.dird_seqslam.search, context.config.match.sequence_length,
                ContrastSequenceSearch::Mode::kSingleSequence, context.config.match.margin, 0) {}

  // Row `seq` (the next one): its distances.
  void push(std::int64_t seq, const std::vector<DistanceEntry>& row) {
    ContrastOutput output;
    search_.push(seq, row, output);
    handle(output);
  }
  void flush() {
    ContrastOutput output;
    search_.flush(output);
    handle(output);
  }

  std::optional<FrameVerdict> detection(std::size_t seq, bool described, bool outside_areas) {
    std::lock_guard lock(finished_mutex_);
    while (!finished_.empty() && static_cast<std::size_t>(finished_.front().i) < seq) finished_.pop_front();
    if (finished_.empty()) return std::nullopt;
    const ContrastVerdict verdict = finished_.front();
    if (static_cast<std::size_t>(verdict.i) != seq) {
      throw std::logic_error(fmt::format("search verdict of seq {} while seq {} waits", verdict.i, seq));
    }
    finished_.pop_front();
    ContrastOutcomeContext c;
    c.described = described;
    c.outside_areas = outside_areas;
    c.before_margin = seq < static_cast<std::size_t>(context_.config.match.margin);
    c.margin_frames = context_.config.match.margin;
    c.min_score = context_.config.dird_seqslam.search.min_score;
    return FrameVerdict{described, contrast_detection(verdict, c)};
  }

  std::optional<std::int64_t> first_loop_seq() const { return first_loop_seq_; }
  // Rows after which the search's verdict of a row pushed is final.
  std::int64_t emission_delay() const { return search_.emission_delay(); }

  // Every query's best line (dataset frame indices), for the PR sweep.
  std::vector<Detection> ranked() const {
    std::lock_guard lock(finished_mutex_);
    return ranked_;
  }

  nlohmann::json summary() const {
    return {{"detection", {{"delay_frames", search_.emission_delay()}}},
            {"dird_seqslam",
             {{"velocities", context_.config.dird_seqslam.search.velocities()},
              {"sequence_length", search_.sequence_length()},
              {"queries_with_a_line", queries_with_line_},
              {"cells", cells_},
              {"cells_with_contrast", defined_}}}};
  }

 private:
  void handle(const ContrastOutput& output) {
    LoopsWriter& loops = context_.loops;
    for (const LoopClosure& loop : output.loops) {
      if (!first_loop_seq_) first_loop_seq_ = loop.i;
      loops.write(context_.seqs.frame(loop.i), context_.seqs.frame(loop.j), context_.seqs.t_ns(loop.i),
                  context_.seqs.t_ns(loop.j), loop.score);
    }
    if (!output.loops.empty()) loops.flush();
    if (output.frames.empty()) return;
    std::lock_guard lock(finished_mutex_);
    for (const ContrastVerdict& v : output.frames) {
      finished_.push_back(v);
      cells_ += v.cells;
      defined_ += v.defined;
      if (v.best_j < 0) continue;
      ++queries_with_line_;
      ranked_.push_back(Detection{context_.seqs.frame(v.i), context_.seqs.frame(v.best_j), v.score});
    }
  }

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  ContrastSequenceSearch search_;
  std::optional<std::int64_t> first_loop_seq_;
  mutable std::mutex finished_mutex_;
  std::deque<ContrastVerdict> finished_;
  std::vector<Detection> ranked_;
  std::size_t cells_ = 0, defined_ = 0, queries_with_line_ = 0;
};

// The method's descriptors: DIRD with its own normalisation and resize, its own standardisation.
DirdDistances make_distances(const MethodContext& context) {
  const PipelineConfig& c = context.config;
  return DirdDistances(context, c.dird_seqslam.descriptor(c.dird),
                       c.dird_seqslam.standardization(c.standardize), c.dird_seqslam.codes);
}

// The viewpoint tolerance's warped descriptors, with the method's descriptor configuration.
ViewpointDistances make_viewpoint(const MethodContext& context, int row_horizon_frames) {
  const PipelineConfig& c = context.config;
  return ViewpointDistances(context, c.dird_seqslam.descriptor(c.dird), c.dird_seqslam.viewpoint,
                            row_horizon_frames);
}

// What the full and gated methods report alike.
nlohmann::json method_summary(const DirdDistances& distances, const ContrastMatching& matching,
                              const ViewpointDistances& viewpoint) {
  nlohmann::json out = matching.summary();
  out.update(viewpoint.summary());
  out["descriptors_computed"] = distances.descriptors_computed();
  out["similarities_computed"] = distances.distances_computed();
  out.update(distances.summary());
  return out;
}

MethodEvaluation method_evaluation(const ContrastMatching& matching) {
  MethodEvaluation e;
  e.ranked = matching.ranked();
  return e;
}

class DirdSeqSlamFull final : public DetectionMethod {
 public:
  explicit DirdSeqSlamFull(const MethodContext& context)
      : context_(context),
        distances_(make_distances(context)),
        viewpoint_(make_viewpoint(context, 0)),
        matching_(context) {}
  std::string name() const override { return "dird-seqslam"; }
  std::string mode() const override { return "full"; }
  bool needs_every_image() const override { return true; }

  void describe(FrameRecord& r) override {
    viewpoint_.describe(r.seq, r.decoded ? &r.image : nullptr, r.seq);
    distances_.describe(r.seq, r.decoded ? &r.image : nullptr);
  }

  void match(FrameRecord& r) override {
    const std::size_t seq = r.seq;
    distances_.begin_frame(seq);
    row_.clear();
    const auto margin = static_cast<std::size_t>(context_.config.match.margin);
    if (seq >= margin) distances_.distance_range(seq, 0, seq - margin + 1, row_);
    viewpoint_.refine(seq, distances_, row_, 0);
    viewpoint_.release_before(seq + 1);
    matching_.push(static_cast<std::int64_t>(seq), row_);
  }
  void finish() override {
    matching_.flush();
    distances_.release_codes();  // no distance after the stream: the end of the run reuses their memory
  }

  std::optional<FrameVerdict> detection(std::size_t seq) override {
    return matching_.detection(seq, distances_.valid(seq), false);
  }
  nlohmann::json summary() const override { return method_summary(distances_, matching_, viewpoint_); }
  MethodEvaluation evaluation() const override { return method_evaluation(matching_); }
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const override {
    return distances_.example_descriptor(matching_.first_loop_seq());
  }

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdDistances distances_;
  ViewpointDistances viewpoint_;
  ContrastMatching matching_;
  std::vector<DistanceEntry> row_;
};

class DirdSeqSlamGated final : public DetectionMethod {
 public:
  explicit DirdSeqSlamGated(const MethodContext& context)
      : context_(context),
        distances_(make_distances(context)),
        viewpoint_(make_viewpoint(context, context.config.gate.row_horizon_frames)),
        matching_(context),
        cells_(context),
        rows_(context.config.gate.row_horizon_frames) {}
  std::string name() const override { return "dird-seqslam"; }
  std::string mode() const override { return "gated"; }

  void gate(FrameRecord& r) override { cells_.gate(r, distances_.observed_frame(r.seq)); }

  void describe(FrameRecord& r) override {
    describe_frames(r, cells_.describe_list(r.seq), context_,
                    [this, &r](std::size_t k, const cv::Mat* image) {
                      viewpoint_.describe(k, image, r.seq);
                      distances_.describe(k, image);
                    });
  }

  void match(FrameRecord& r) override {
    distances_.begin_frame(r.seq);
    for (const CellSpan& span : cells_.take_cells(r.seq)) {
      std::vector<DistanceEntry>& row = rows_.row(span.i);
      const std::size_t first = row.size();
      distances_.distance_range(static_cast<std::size_t>(span.i), static_cast<std::size_t>(span.j0),
                                static_cast<std::size_t>(span.j1) + 1, row);
      viewpoint_.refine(static_cast<std::size_t>(span.i), distances_, row, first);
    }
    if (r.seq > static_cast<std::size_t>(context_.config.gate.row_horizon_frames))
      viewpoint_.release_before(r.seq - static_cast<std::size_t>(context_.config.gate.row_horizon_frames));
    match_end_seq_ = r.seq + 1;
    rows_.advance(static_cast<std::int64_t>(r.seq),
                  [this](std::int64_t i, const std::vector<DistanceEntry>& row) { matching_.push(i, row); });
  }

  void finish() override {
    cells_.finish();
    rows_.finish(static_cast<std::int64_t>(match_end_seq_),
                 [this](std::int64_t i, const std::vector<DistanceEntry>& row) { matching_.push(i, row); });
    matching_.flush();
    distances_.release_codes();  // no distance after the stream: the end of the run reuses their memory
  }

  void add_frame_cells(const FrameRecord& r, CsvRow& row) const override { cells_.add_frame_cells(r, row); }
  // Row s goes to the search at match(s + horizon) (BasicRowAssembler), its verdict is final L - 1 rows
  // later.
  std::optional<int> verdict_delay_frames() const override {
    return context_.config.gate.row_horizon_frames + static_cast<int>(matching_.emission_delay());
  }
  std::optional<FrameVerdict> detection(std::size_t seq) override {
    const bool described = cells_.requested_within(seq, *verdict_delay_frames()) && distances_.valid(seq);
    return matching_.detection(seq, described, cells_.row_empty(seq));
  }
  void write_files(const std::filesystem::path& out_dir) const override {
    cells_.write_files(out_dir, match_end_seq_,
                       [this](std::int64_t k) { return distances_.valid(static_cast<std::size_t>(k)); });
  }
  nlohmann::json summary() const override {
    nlohmann::json out = method_summary(distances_, matching_, viewpoint_);
    out.update(cells_.summary(match_end_seq_));
    return out;
  }
  MethodEvaluation evaluation() const override {
    MethodEvaluation e = method_evaluation(matching_);
    e.covers = [this](std::int64_t i, std::int64_t j) { return cells_.covers(i, j); };
    return e;
  }
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const override {
    return distances_.example_descriptor(matching_.first_loop_seq());
  }

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdDistances distances_;
  ViewpointDistances viewpoint_;
  ContrastMatching matching_;
  PoseGatedCells cells_;
  BasicRowAssembler<DistanceEntry> rows_;
  std::size_t match_end_seq_ = 0;
};

}  // namespace

std::unique_ptr<DetectionMethod> make_dird_seqslam_full(const MethodContext& context) {
  return std::make_unique<DirdSeqSlamFull>(context);
}
std::unique_ptr<DetectionMethod> make_dird_seqslam_gated(const MethodContext& context) {
  return std::make_unique<DirdSeqSlamGated>(context);
}

}  // namespace loopgate
