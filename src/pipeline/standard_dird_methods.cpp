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
#include "pipeline/descriptor_store.hpp"
#include "pipeline/detection_method.hpp"
#include "pipeline/frame_steps.hpp"
#include "pipeline/gated_cells.hpp"
#include "pipeline/loop_matching.hpp"
#include "pipeline/parallel_handoff.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"
#include "stages/match/row_assembler.hpp"

namespace loopgate {

namespace {

// The descriptors (raw and coded), the causal statistics, the scale and the loop matching of one run.
class StandardDird {
 public:
  explicit StandardDird(const MethodContext& context)
      : context_(context),
        extractor_(context.config.dird),
        raw_(context.capacity),
        codes_(new Descriptor[context.capacity]),
        norms_(context.capacity, 0.0),
        coded_(context.capacity, 0),
        loops_(context) {
    const PipelineConfig& config = context.config;
    if (config.standardize.enabled()) standardizer_.emplace(observations_config(config.standardize));
    if (standardizer_) {
      prior_ = standard_default_scale(config.standardize, config.dird.tau1);
    } else {
      prior_.mu = config.dird.mu;
      prior_.sigma = config.dird.sigma;
      prior_.cutoff_distance = logistic_distance_at(config.dird.tau1, config.dird.mu, config.dird.sigma);
    }
    if (config.scale.online()) online_.emplace(config.scale, config.dird.tau1, prior_);
    observe_every_ = standardizer_ ? static_cast<std::size_t>(config.standardize.observe_every) : 1;
  }

  // Frames whose raw descriptor feeds the statistics.
  bool observed_frame(std::size_t seq) const { return standardizer_ && seq % observe_every_ == 0; }

  // Describe node (parallel): the raw descriptor of `seq`, or none when there is no image.
  void describe(std::size_t seq, const cv::Mat* image) {
    if (image) {
      extractor_.extract(*image, raw_.slot(seq));
      descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
    }
    raw_.publish(seq, image != nullptr);
  }

  // Match node, first for frame seq: its raw descriptor joins the statistics when it is an observed frame;
  // the frames waiting for the warm-up are coded once it is over. The scale for this frame's similarities
  // is frozen.
  void begin_frame(std::size_t seq) {
    if (observed_frame(seq) && valid(seq)) {
      standardizer_->observe(static_cast<std::int64_t>(seq), raw_.descriptor(seq));
      if (standardizer_->ready() && !waiting_.empty()) {
        for (const std::size_t k : waiting_) code(k);
        waiting_.clear();
      }
    }
    scale_ = online_ ? online_->scale() : prior_;
  }

  // Appends to `out` the similarities of frame `seq` against frames [j_begin, j_end) (each described:
  // published), skipping frames without a descriptor or codes; returns the comparisons made.
  std::size_t similarity_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                               std::vector<SimilarityEntry>& out) {
    if (j_begin >= j_end || !code(seq)) return 0;
    for (std::size_t j = j_begin; j < j_end; ++j) {
      if (raw_.state(j) == DescriptorStore::State::kEmpty) {
        throw std::logic_error(fmt::format("similarity of seq {}: earlier seq {} not described yet", seq, j));
      }
      code(j);
    }
    const std::size_t count = j_end - j_begin;
    distances_.assign(count, std::numeric_limits<double>::quiet_NaN());
    const auto block_distances = [&](std::size_t block) {
      const std::size_t begin = block * kBlock, end = std::min(count, begin + kBlock);
      for (std::size_t k = begin; k < end; ++k) {
        const std::size_t j = j_begin + k;
        if (coded_[j]) distances_[k] = distance(seq, j);
      }
    };
    const std::size_t blocks = (count + kBlock - 1) / kBlock;
    if (blocks > 1) {
      parallel_for_with_handoff(blocks, block_distances);
    } else {
      block_distances(0);
    }
    std::size_t compared = 0;
    for (std::size_t k = 0; k < count; ++k) {
      const double d = distances_[k];
      if (std::isnan(d)) continue;
      ++compared;
      if (online_) online_->add(d);
      if (d >= scale_.cutoff_distance) continue;
      const double sim = logistic_similarity(d, scale_.mu, scale_.sigma);
      if (sim > context_.config.dird.tau1) out.push_back({static_cast<std::int64_t>(j_begin + k), sim});
    }
    similarities_computed_ += compared;
    return compared;
  }

  bool valid(std::size_t seq) const { return raw_.state(seq) == DescriptorStore::State::kValid; }
  LoopMatching& loops() { return loops_; }
  std::optional<FrameVerdict> detection(std::size_t seq, bool outside_areas) {
    return loops_.detection(seq, valid(seq), outside_areas);
  }

  nlohmann::json summary() const {
    nlohmann::json out = loops_.summary();
    out["descriptors_computed"] = descriptors_computed_.load();
    out["similarities_computed"] = similarities_computed_;
    const LogisticScale scale = online_ ? online_->scale() : prior_;
    out["scale"] = {{"mode", context_.config.scale.mode},
                    {"mu", scale.mu},
                    {"sigma", scale.sigma},
                    {"cutoff_distance", scale.cutoff_distance},
                    {"estimated", scale.estimated},
                    {"distances", online_ ? online_->count() : 0}};
    if (standardizer_) {
      out["standardize"] = {{"mode", context_.config.standardize.mode},
                            {"distance", context_.config.standardize.distance},
                            {"observations", standardizer_->observations()},
                            {"snapshots", standardizer_->snapshots()},
                            {"frames_coded", frames_coded_},
                            {"frames_before_statistics", frames_before_statistics_}};
    }
    return out;
  }

  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const {
    if (const auto first = loops_.first_loop_seq()) {
      return std::pair{context_.seqs.frame(*first), raw_.descriptor(static_cast<std::size_t>(*first))};
    }
    const Dataset& dataset = context_.images.dataset();
    const std::size_t frame = dataset.frame_count() / 2;
    return std::pair{frame, extractor_.extract(dataset.load_image(frame))};
  }

 private:
  static constexpr std::size_t kBlock = 256;  // comparisons per parallel block

  // Codes (and norm) of `seq` once; false when it has no descriptor or the statistics are not ready yet
  // (then it waits for them).
  bool code(std::size_t seq) {
    if (coded_[seq]) return true;
    if (!valid(seq)) return false;
    if (!standardizer_) {
      codes_[seq] = raw_.descriptor(seq);
    } else if (!standardizer_->ready()) {
      if (std::find(waiting_.begin(), waiting_.end(), seq) == waiting_.end()) {
        waiting_.push_back(seq);
        ++frames_before_statistics_;
      }
      return false;
    } else {
      standardizer_->standardize(static_cast<std::int64_t>(seq), raw_.descriptor(seq), codes_[seq]);
      if (context_.config.standardize.cosine()) norms_[seq] = standard_norm(codes_[seq]);
    }
    coded_[seq] = 1;
    ++frames_coded_;
    return true;
  }

  double distance(std::size_t a, std::size_t b) const {
    if (!standardizer_) {
      return context_.config.dird.l2_metric() ? l2_distance(codes_[a], codes_[b])
                                              : static_cast<double>(l1_distance(codes_[a], codes_[b]));
    }
    if (context_.config.standardize.cosine()) {
      return standard_cosine_distance(codes_[a], norms_[a], codes_[b], norms_[b]);
    }
    return static_cast<double>(l1_distance(codes_[a], codes_[b]));
  }

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdExtractor extractor_;
  DescriptorStore raw_;                  // written by describe (parallel), published
  std::unique_ptr<Descriptor[]> codes_;  // match node only
  std::vector<double> norms_;            // match node only
  std::vector<std::uint8_t> coded_;      // match node only
  std::optional<CausalStandardizer> standardizer_;
  std::size_t observe_every_ = 1;
  LogisticScale prior_;
  std::optional<OnlineScale> online_;
  LogisticScale scale_;               // frozen for the current frame
  std::vector<std::size_t> waiting_;  // frames described before the statistics were ready
  std::vector<double> distances_;     // the current range's distances (NaN: not compared)
  std::atomic<std::size_t> descriptors_computed_{0};
  std::size_t similarities_computed_ = 0, frames_coded_ = 0, frames_before_statistics_ = 0;
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
class StandardDirdGated final : public DetectionMethod {
 public:
  explicit StandardDirdGated(const MethodContext& context)
      : context_(context), dird_(context), cells_(context), rows_(context.config.gate.row_horizon_frames) {}
  std::string name() const override { return "dird"; }
  std::string mode() const override { return "gated"; }

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
    match_end_seq_ = r.seq + 1;
    MatchOutput output;
    rows_.advance(static_cast<std::int64_t>(r.seq), dird_.loops().matcher(), output);
    dird_.loops().handle(output);
  }

  void finish() override {
    cells_.finish();
    MatchOutput output;
    rows_.finish(static_cast<std::int64_t>(match_end_seq_), dird_.loops().matcher(), output);
    dird_.loops().handle(output);
    dird_.loops().flush();
  }

  void add_frame_cells(const FrameRecord& r, CsvRow& row) const override { cells_.add_frame_cells(r, row); }
  std::optional<FrameVerdict> detection(std::size_t seq) override {
    return dird_.detection(seq, cells_.row_empty(seq));
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

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  StandardDird dird_;
  PoseGatedCells cells_;
  RowAssembler rows_;
  std::size_t match_end_seq_ = 0;
};

}  // namespace

std::unique_ptr<DetectionMethod> make_standard_dird_full(const MethodContext& context) {
  return std::make_unique<StandardDirdFull>(context);
}
std::unique_ptr<DetectionMethod> make_standard_dird_gated(const MethodContext& context) {
  return std::make_unique<StandardDirdGated>(context);
}

}  // namespace loopgate
