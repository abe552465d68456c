// DIRD with causal descriptor standardisation (docs/standardize.md) and a data-driven logistic scale, full
// and gated. Chosen by make_detection_method when run.method is dird and standardize.mode is causal, or
// scale.mode is online (then on raw bytes).
//
// Per frame, in the serial match node and in sequence order:
//   1. observe: frame seq's raw descriptor joins the causal statistics when seq % standardize.observe_every
//      == 0 (full and gated runs observe the same frames: a gated run describes them at their own time);
//   2. code: a frame's codes are computed once, the first time a similarity needs them, with the statistics
//      of its own time (CausalStandardizer's snapshot rule); frames before the warm-up is over are coded as
//      soon as it is (a similarity that needs a frame before that is skipped and counted);
//   3. similarities: distances on the codes (cosine with precomputed norms, or L1), in parallel blocks,
//      turned into sim = 1 / (1 + exp((d - mu) / sigma)) with the scale frozen before this frame's
//      distances (scale.mode online: then its distances join the estimate).
// So no frame's similarity depends on a later frame, and the codes (hence the rows) of the gated run are
// those of the full run restricted to the candidate cells. Describe (raw extraction) stays parallel.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/loops/loop_matching.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/dird_distances.hpp"
#include "pipeline/methods/gated_cells.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"
#include "stages/match/row_assembler.hpp"

namespace loopgate {

namespace {

// The distances (raw or standardised), the scale and the loop matching of one run.
class StandardDird {
 public:
  explicit StandardDird(const MethodContext& context)
      : context_(context),
        distances_(context, context.config.dird, context.config.standardize),
        loops_(context) {
    const PipelineConfig& config = context.config;
    if (distances_.standardized()) {
      prior_ = standard_default_scale(config.standardize, config.dird.tau1);
    } else {
      prior_.mu = config.dird.mu;
      prior_.sigma = config.dird.sigma;
      prior_.cutoff_distance = logistic_distance_at(config.dird.tau1, config.dird.mu, config.dird.sigma);
    }
    if (config.scale.online()) online_.emplace(config.scale, config.dird.tau1, prior_);
  }

  bool observed_frame(std::size_t seq) const { return distances_.observed_frame(seq); }
  void describe(std::size_t seq, const cv::Mat* image) { distances_.describe(seq, image); }

  // Match node, first for frame seq: the statistics (DirdDistances::begin_frame), then the scale for this
  // frame's similarities is frozen.
  void begin_frame(std::size_t seq) {
    distances_.begin_frame(seq);
    scale_ = online_ ? online_->scale() : prior_;
  }

  // Appends to `out` the similarities of frame `seq` against frames [j_begin, j_end) (each described:
  // published), skipping frames without a descriptor or codes; returns the comparisons made.
  std::size_t similarity_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                               std::vector<SimilarityEntry>& out) {
    row_.clear();
    const std::size_t compared = distances_.distance_range(seq, j_begin, j_end, row_);
    for (const DistanceEntry& e : row_) {
      if (online_) online_->add(e.distance);
      if (e.distance >= scale_.cutoff_distance) continue;
      const double sim = logistic_similarity(e.distance, scale_.mu, scale_.sigma);
      if (sim > context_.config.dird.tau1) out.push_back({e.j, sim});
    }
    return compared;
  }

  bool valid(std::size_t seq) const { return distances_.valid(seq); }
  LoopMatching& loops() { return loops_; }
  const LoopMatching& loops() const { return loops_; }
  // `requested` (gated): the descriptor was requested in time for the row (PoseGatedCells::requested_within).
  std::optional<FrameVerdict> detection(std::size_t seq, bool outside_areas, bool requested = true) {
    return loops_.detection(seq, requested && valid(seq), outside_areas);
  }

  nlohmann::json summary() const {
    nlohmann::json out = loops_.summary();
    out["descriptors_computed"] = distances_.descriptors_computed();
    out["similarities_computed"] = distances_.distances_computed();
    const LogisticScale scale = online_ ? online_->scale() : prior_;
    out["scale"] = {{"mode", enum_name(context_.config.scale.mode)},
                    {"mu", scale.mu},
                    {"sigma", scale.sigma},
                    {"cutoff_distance", scale.cutoff_distance},
                    {"estimated", scale.estimated},
                    {"distances", online_ ? online_->count() : 0}};
    out.update(distances_.summary());
    return out;
  }

  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const {
    return distances_.example_descriptor(loops_.first_loop_seq());
  }

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdDistances distances_;
  LogisticScale prior_;
  std::optional<OnlineScale> online_;
  LogisticScale scale_;             // frozen for the current frame
  std::vector<DistanceEntry> row_;  // scratch: the current range's distances
  LoopMatching loops_;
};

// Every frame described (describe node, parallel); its row against every frame j <= seq - margin computed in
// the match node (the codes need the statistics of the frames before it), in parallel blocks.
class StandardDirdFull final : public DetectionMethod {
 public:
  explicit StandardDirdFull(const MethodContext& context) : context_(context), dird_(context) {}
  std::string name() const override { return "dird"; }
  std::string mode() const override { return "full"; }
  bool needs_every_image() const override { return true; }

  void describe(FrameRecord& r) override { dird_.describe(r.seq, r.decoded ? &r.image : nullptr); }

  void match(FrameRecord& r) override {
    const std::size_t seq = r.seq;
    dird_.begin_frame(seq);
    std::vector<SimilarityEntry> row;
    const auto margin = static_cast<std::size_t>(context_.config.match.margin);
    if (seq >= margin) dird_.similarity_range(seq, 0, seq - margin + 1, row);
    dird_.loops().push(seq, row);
  }
  void finish() override { dird_.loops().flush(); }

  std::optional<FrameVerdict> detection(std::size_t seq) override { return dird_.detection(seq, false); }
  nlohmann::json summary() const override { return dird_.summary(); }
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const override {
    return dird_.example_descriptor();
  }

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  StandardDird dird_;
};

// The pose gate's candidate cells (PoseGatedCells) with standardised DIRD: the frames the gate asks for and
// the observed frames are described; the cells' similarities go into rows kept open for
// gate.row_horizon_frames, then to the matcher.
class StandardDirdGated final : public GatedDirdMethod<StandardDird> {
 public:
  using GatedDirdMethod::GatedDirdMethod;

  void gate(FrameRecord& r) override { cells_.gate(r, dird_.observed_frame(r.seq)); }

  void describe(FrameRecord& r) override {
    describe_frames(r, cells_.describe_list(r.seq), context_,
                    [this](std::size_t k, const cv::Mat* image) { dird_.describe(k, image); });
  }

  void match(FrameRecord& r) override {
    dird_.begin_frame(r.seq);
    for (const CellSpan& span : cells_.take_cells(r.seq)) {
      dird_.similarity_range(static_cast<std::size_t>(span.i), static_cast<std::size_t>(span.j0),
                             static_cast<std::size_t>(span.j1) + 1, rows_.row(span.i));
    }
    advance(r.seq);
  }
};

}  // namespace

std::unique_ptr<DetectionMethod> make_standard_dird_full(const MethodContext& context) {
  return std::make_unique<StandardDirdFull>(context);
}
std::unique_ptr<DetectionMethod> make_standard_dird_gated(const MethodContext& context) {
  return std::make_unique<StandardDirdGated>(context);
}

}  // namespace loopgate
