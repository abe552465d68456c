// Full SeqSLAM as a detection method (run.method seqslam, run.mode full; docs/detection.md § SeqSLAM; the
// gated one is seqslam_gated_method.cpp): describe preprocesses every frame (parallel, stored by sequence
// number in a SeqSlamBatch); the search runs over the whole run at the end of the stream (a query's sequence
// needs ds/2 later frames and the contrast statistics need neighbouring rows), so every frame's detection row
// is known only then.
#include <spdlog/fmt/fmt.h>

#include <atomic>
#include <cmath>
#include <stdexcept>

#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/seqslam_batch.hpp"
#include "stages/seqslam/seqslam_outcome.hpp"

namespace loopgate {

namespace {

class SeqSlamMethod final : public DetectionMethod {
 public:
  explicit SeqSlamMethod(const MethodContext& context)
      : context_(context),
        batch_(context.config.seqslam, context.capacity),
        described_(context.capacity, 0) {}

  std::string name() const override { return "seqslam"; }
  std::string mode() const override { return "full"; }  // every frame
  bool needs_every_image() const override { return true; }

  void describe(FrameRecord& r) override {
    const auto seq = static_cast<std::size_t>(r.seq);
    if (r.decoded) {
      try {
        batch_.add(seq, r.image);
        described_[seq] = 1;
        descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
      } catch (const std::invalid_argument& e) {
        add_message(r.errors, std::string("seqslam preprocessing: ") + e.what());
      }
    }
    if (!described_[seq]) batch_.add_missing(seq);
  }

  void match(FrameRecord& r) override { frames_ = static_cast<std::size_t>(r.seq) + 1; }

  // The search over every frame seen; loops.csv for the accepted matches.
  void finish() override {
    matches_ = batch_.run(frames_, &differences_computed_);
    searched_ = true;
    for (const SeqSlamMatch& m : matches_) {
      if (!m.has_match || !std::isfinite(m.ratio)) continue;
      const std::size_t frame_i = context_.seqs.frame(static_cast<std::int64_t>(m.query));
      const std::size_t frame_j = context_.seqs.frame(static_cast<std::int64_t>(m.reference));
      ranked_.push_back(Detection{frame_i, frame_j, m.ratio});
      if (!m.accepted) continue;
      context_.loops.write(frame_i, frame_j, context_.seqs.t_ns(static_cast<std::int64_t>(m.query)),
                           context_.seqs.t_ns(static_cast<std::int64_t>(m.reference)), m.ratio);
    }
  }

  std::optional<FrameVerdict> detection(std::size_t seq) override {
    if (!searched_) return std::nullopt;
    SeqSlamOutcomeContext c;
    c.query_count = frames_;
    return FrameVerdict{described_[seq] != 0,  // else it took part as a zero image
                        seqslam_detection(matches_.at(seq), context_.config.seqslam, c)};
  }

  ScoreOrder score_order() const override { return ScoreOrder::kLowerIsBetter; }
  nlohmann::json summary() const override {
    return {{"descriptors_computed", descriptors_computed_.load()},
            {"similarities_computed", differences_computed_}};  // difference-matrix entries
  }
  // The PR sweep runs over every query's match, accepted or not: the ratio is the threshold.
  MethodEvaluation evaluation() const override {
    MethodEvaluation e;
    e.ranked = ranked_;
    return e;
  }

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  SeqSlamBatch batch_;
  std::vector<std::uint8_t> described_;  // per seq, written once by describe, read after the search
  std::atomic<std::size_t> descriptors_computed_{0};
  std::size_t frames_ = 0;  // frames through match
  std::size_t differences_computed_ = 0;
  bool searched_ = false;
  std::vector<SeqSlamMatch> matches_;
  std::vector<Detection> ranked_;  // every query's finite match, dataset frame indices
};

}  // namespace

std::unique_ptr<DetectionMethod> make_seqslam(const MethodContext& context) {
  return std::make_unique<SeqSlamMethod>(context);
}

}  // namespace loopgate
