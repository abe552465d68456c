// The DIRD distances of one single-sequence run, raw or standardised (docs/standardize.md): the raw
// descriptors by sequence number (written by the describe node, in parallel), the causal statistics, each
// frame's codes (made once, in the serial match node, with the statistics of its own time) and the distances
// of a frame to a range of earlier frames (in parallel blocks). The standardised DIRD methods turn the
// distances into logistic similarities for the DP; the dird-seqslam methods contrast-enhance them.
//
// Per frame, in the serial match node and in sequence order: begin_frame(seq) (its raw descriptor joins the
// statistics when it is an observed frame: seq % standardize.observe_every == 0), then distance_range(seq,
// ...) for its cells. No frame's distances depend on a later frame, and a gated run's distances are the
// full run's restricted to its cells, as long as both observe the same frames (a gated run describes the
// observed frames at their own time: describe_own_frame in PoseGatedCells::gate).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <utility>
#include <vector>

#include "pipeline/methods/descriptor_store.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "stages/dird/dird_codes.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_standardize.hpp"
#include "stages/match/contrast_search.hpp"

namespace loopgate {

class DirdDistances {
 public:
  // Descriptors extracted with `dird`, standardised when `standardize` is enabled (mode causal; the caller
  // rejects batch), matched in the representation `codes` (a compact code needs the standardisation). With a
  // compact code a frame is coded as soon as its statistics allow (at the latest when its own frame or a
  // later one is matched) and its raw descriptor is dropped then.
  DirdDistances(const MethodContext& context, const DirdConfig& dird, const StandardizeConfig& standardize,
                const DirdCodeConfig& codes = {});

  bool standardized() const { return standardizer_.has_value() || coder_.has_value() || released_; }
  // Frames whose raw descriptor feeds the statistics.
  bool observed_frame(std::size_t seq) const { return standardized() && seq % observe_every_ == 0; }

  // Describe node (parallel): the raw descriptor of `seq`, or none when there is no image.
  void describe(std::size_t seq, const cv::Mat* image);
  // Match node, first for frame seq: its raw descriptor joins the statistics when it is an observed frame;
  // the frames waiting for the warm-up are coded once it is over.
  void begin_frame(std::size_t seq);
  // Appends to `out` the distances of frame `seq` to frames [j_begin, j_end) (each published by describe),
  // skipping frames without a descriptor or codes; returns the comparisons made.
  std::size_t distance_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                             std::vector<DistanceEntry>& out);

  // After the method's last distance (its finish()): with a compact code, frees the code matrix and the
  // statistics' snapshots, which nothing reads after the stream (the plots' example descriptor is described
  // again from the dataset), so that the end of the run (outputs, evaluation, summary) reuses their memory
  // instead of adding to it. summary() still reports them; distance_range() throws std::logic_error after.
  // Nothing to free with int8 codes (example_descriptor() reads their raw descriptors).
  void release_codes();

  // Viewpoint tolerance (pipeline/methods/viewpoint_distances.hpp): `raw`, another descriptor of frame seq
  // (a warped image), coded as frame seq is (same statistics); false when seq is not coded. Not with a
  // compact code (the caller's config refuses it).
  bool code_like(std::size_t seq, const Descriptor& raw, Descriptor& code, double& norm);
  // The distance of such a code to coded frame j, as distance_range() computes it.
  double distance_to(const Descriptor& code, double norm, std::size_t j) const;

  bool valid(std::size_t seq) const { return raw_.state(seq) == DescriptorStore::State::kValid; }
  std::size_t descriptors_computed() const { return descriptors_computed_.load(); }
  std::size_t distances_computed() const { return distances_computed_; }
  // summary.json: "standardize" (when standardised): mode, distance, observations, snapshots, frames coded,
  // frames before the statistics.
  nlohmann::json summary() const;
  // The plots' descriptor: frame `seq`'s raw descriptor when given, else the middle frame of the dataset.
  std::pair<std::size_t, Descriptor> example_descriptor(std::optional<std::int64_t> seq) const;

 private:
  static constexpr std::size_t kBlock = 256;  // comparisons per parallel block

  // Codes (and norm) of `seq` once; false when it has no descriptor or the statistics are not ready yet
  // (then it waits for them).
  bool code(std::size_t seq);
  double distance(std::size_t a, std::size_t b) const;
  bool statistics_ready() const { return coder_ ? coder_->ready() : standardizer_->ready(); }
  // The raw descriptor of a described frame not yet dropped.
  const Descriptor& raw(std::size_t seq) const;

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  DirdConfig dird_;
  StandardizeConfig standardize_;
  DirdExtractor extractor_;
  DescriptorStore raw_;                             // written by describe (parallel), published
  std::unique_ptr<Descriptor[]> codes_;             // match node only
  std::vector<double> norms_;                       // match node only
  std::vector<std::uint8_t> coded_;                 // match node only
  std::optional<CausalStandardizer> standardizer_;  // int8 codes
  DirdCodeConfig code_config_;
  std::optional<CausalCompactCoder> coder_;   // compact codes: the statistics kept as cuts
  std::optional<CompactCodeMatrix> compact_;  // match node only
  // Compact codes: the raw descriptors until coded (written by describe before the store's publish, read
  // after its state; the store's own slots stay unwritten).
  std::vector<std::unique_ptr<Descriptor>> pending_;
  std::size_t observe_every_ = 1;
  std::vector<std::size_t> waiting_;  // frames described before the statistics were ready
  std::vector<double> distances_;     // the current range's distances (NaN: not compared)
  std::atomic<std::size_t> descriptors_computed_{0};
  std::size_t distances_computed_ = 0, frames_coded_ = 0, frames_before_statistics_ = 0;
  bool released_ = false;            // release_codes() freed the compact codes
  nlohmann::json released_summary_;  // summary() as it was then
};

}  // namespace loopgate
