// DIRD as a detection method, full (every frame described and compared with every earlier frame beyond the
// margin: the paper's pure-DIRD baseline) and gated (the paper's method: only inside the pose gate's
// candidate areas). Both share DirdMatching: the descriptor store, the similarity rows, the streaming
// sequence matcher and the frames' detection rows; they differ in which descriptors and similarities
// they compute.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <stdexcept>

#include "core/thread_cpu_time.hpp"
#include "io/dataset.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/loops/loop_matching.hpp"
#include "pipeline/methods/descriptor_store.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/gated_cells.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/row_assembler.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

namespace {

// What full and gated DIRD share: descriptors by sequence number, similarity rows, and the loop matching.
class DirdMatching {
 public:
  explicit DirdMatching(const MethodContext& context)
      : context_(context),
        extractor_(context.config.dird),
        similarity_(context.config.dird),
        store_(context.capacity),
        loops_(context) {}

  void describe(std::size_t seq, const cv::Mat& image) {
    extractor_.extract(image, store_.slot(seq));
    descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
  }
  DescriptorStore& store() { return store_; }
  const DescriptorStore& store() const { return store_; }

  // Appends to `out` the similarities of frame `seq` against the earlier frames [j_begin, j_end) of the
  // store (each must be published), skipping frames without a descriptor; returns the comparisons made.
  std::size_t similarity_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                               std::vector<SimilarityEntry>& out) const {
    if (j_begin >= j_end) return 0;
    bool any_missing = false;
    for (std::size_t j = j_begin; j < j_end; ++j) {
      const auto state = store_.state(j);
      if (state == DescriptorStore::State::kEmpty) {
        throw std::logic_error(fmt::format("similarity of seq {}: earlier seq {} not described yet", seq, j));
      }
      any_missing = any_missing || state == DescriptorStore::State::kNoDescriptor;
    }
    const std::size_t first_new = out.size();
    similarity_.sparse_row(store_.descriptor(seq), store_.data() + j_begin, j_end - j_begin,
                           static_cast<std::int64_t>(j_begin), out);
    std::size_t compared = j_end - j_begin;
    if (any_missing) {
      const auto is_missing = [this](const SimilarityEntry& e) {
        return store_.state(static_cast<std::size_t>(e.j)) != DescriptorStore::State::kValid;
      };
      out.erase(std::remove_if(out.begin() + static_cast<std::ptrdiff_t>(first_new), out.end(), is_missing),
                out.end());
      compared = 0;
      for (std::size_t j = j_begin; j < j_end; ++j)
        compared += store_.state(j) == DescriptorStore::State::kValid ? 1 : 0;
    }
    similarities_computed_.fetch_add(compared, std::memory_order_relaxed);
    return compared;
  }

  LoopMatching& loops() { return loops_; }
  const LoopMatching& loops() const { return loops_; }
  // Frame seq has a descriptor (published).
  bool valid(std::size_t seq) const { return store_.state(seq) == DescriptorStore::State::kValid; }
  // The detection row of `seq` once final; `outside_areas` (gated): its row had no cell; `requested` (gated):
  // its descriptor was requested in time for the row (PoseGatedCells::requested_within).
  std::optional<FrameVerdict> detection(std::size_t seq, bool outside_areas, bool requested = true) {
    return loops_.detection(seq, requested && valid(seq), outside_areas);
  }

  nlohmann::json summary() const {
    nlohmann::json out = loops_.summary();
    out["descriptors_computed"] = descriptors_computed_.load();
    out["similarities_computed"] = similarities_computed_.load();
    return out;
  }

  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const {
    if (const auto first = loops_.first_loop_seq()) {
      return std::pair{context_.seqs.frame(*first), store_.descriptor(static_cast<std::size_t>(*first))};
    }
    const Dataset& dataset = context_.images.dataset();
    const std::size_t frame = dataset.frame_count() / 2;
    return std::pair{frame, extractor_.extract(dataset.load_image(frame))};
  }

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdExtractor extractor_;
  DirdSimilarity similarity_;
  DescriptorStore store_;
  LoopMatching loops_;
  std::atomic<std::size_t> descriptors_computed_{0};
  mutable std::atomic<std::size_t> similarities_computed_{0};  // counted by the const similarity_range
};

// run.mode full. describe extracts the frame's descriptor and computes its similarities against the frames
// j <= i - max(margin, K), which have certainly left the sink (the producer releases seq i only when at most
// K - 1 frames are in flight, and the sink retires frames in order); match adds the pairs i - K < j <= i -
// margin (only when margin < K) and feeds the matcher. The row is the same set of pairs whatever the timing.
class DirdFull final : public DetectionMethod {
 public:
  explicit DirdFull(const MethodContext& context)
      : context_(context), dird_(context), rows_(context.capacity), described_(context.capacity, 0) {
    const RunConfig& run = context.config.run;
    if (run.max_in_flight > context.config.match.margin) {
      spdlog::info(
          "run: match.margin {} < run.max_in_flight {}: the similarities against the last {} frames before "
          "the margin are computed in the (serial) match node",
          context.config.match.margin, run.max_in_flight, run.max_in_flight - context.config.match.margin);
    }
  }
  std::string name() const override { return "dird"; }
  std::string mode() const override { return "full"; }
  bool needs_every_image() const override { return true; }

  void describe(FrameRecord& r) override {
    const auto seq = static_cast<std::size_t>(r.seq);
    const bool described = r.decoded;
    if (described) dird_.describe(seq, r.image);
    described_[seq] = described ? 1 : 0;
    dird_.store().publish(seq, described);
    if (!described) return;
    const std::size_t limit = std::max(margin(), in_flight());
    if (seq >= limit) {  // matching work done here so that rows run in parallel: booked as match
      const std::int64_t start_ns = thread_cpu_ns();
      dird_.similarity_range(seq, 0, seq - limit + 1, rows_[seq]);
      r.match_in_describe_cpu_ns += thread_cpu_ns() - start_ns;
    }
  }

  void match(FrameRecord& r) override {
    const auto seq = static_cast<std::size_t>(r.seq);
    std::vector<SimilarityEntry>& row = rows_[seq];
    if (described_[seq] && margin() < in_flight() && seq >= margin()) {
      const std::size_t j_begin = seq + 1 >= in_flight() ? seq + 1 - in_flight() : 0;
      dird_.similarity_range(seq, j_begin, seq - margin() + 1, row);
    }
    dird_.loops().push(seq, row);
    std::vector<SimilarityEntry>().swap(row);
  }

  void finish() override { dird_.loops().flush(); }

  std::optional<FrameVerdict> detection(std::size_t seq) override { return dird_.detection(seq, false); }
  nlohmann::json summary() const override { return dird_.summary(); }
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const override {
    return dird_.example_descriptor();
  }

 private:
  std::size_t margin() const { return static_cast<std::size_t>(context_.config.match.margin); }
  std::size_t in_flight() const { return static_cast<std::size_t>(context_.config.run.max_in_flight); }

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdMatching dird_;
  std::vector<std::vector<SimilarityEntry>> rows_;  // S(., seq): describe fills j <= seq - K, match the rest
  std::vector<std::uint8_t> described_;
};

// run.mode gated. gate runs the pose gate and the candidate-area tracker (PoseGatedCells): the cells newly
// covered and the frames newly needing a descriptor; describe computes exactly those descriptors (past
// frames read again, several in parallel, each at most once); match computes the new cells' similarities
// into rows kept open for gate.row_horizon_frames (RowAssembler), then final rows go to the matcher.
class DirdGated final : public GatedDirdMethod<DirdMatching> {
 public:
  using GatedDirdMethod::GatedDirdMethod;

  void gate(FrameRecord& r) override { cells_.gate(r); }

  // The descriptors the gate asked for, each computed once, several in parallel.
  void describe(FrameRecord& r) override {
    describe_frames(r, cells_.describe_list(r.seq), context_, [this](std::size_t k, const cv::Mat* image) {
      if (image) dird_.describe(k, *image);
      dird_.store().publish(k, image != nullptr);
    });
  }

  // The similarities of the cells this frame's gate update covered (every descriptor they need was requested
  // at this frame or earlier, so it has passed describe), into rows still open; rows older than the horizon
  // go to the matcher.
  void match(FrameRecord& r) override {
    for (const CellSpan& span : cells_.take_cells(r.seq)) {
      std::vector<SimilarityEntry>& row = rows_.row(span.i);
      if (!dird_.valid(static_cast<std::size_t>(span.i))) continue;
      dird_.similarity_range(static_cast<std::size_t>(span.i), static_cast<std::size_t>(span.j0),
                             static_cast<std::size_t>(span.j1) + 1, row);
    }
    advance(r.seq);
  }
};

}  // namespace

std::unique_ptr<DetectionMethod> make_dird_full(const MethodContext& context) {
  return std::make_unique<DirdFull>(context);
}
std::unique_ptr<DetectionMethod> make_dird_gated(const MethodContext& context) {
  return std::make_unique<DirdGated>(context);
}

}  // namespace loopgate
