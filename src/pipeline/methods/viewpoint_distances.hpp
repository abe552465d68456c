// dird-seqslam's viewpoint tolerance (dird_seqslam.viewpoint_*, stages/dird/viewpoint.hpp,
// docs/viewpoint.md): the query rows' frames are also described with their image warped as seen from a few
// metres to either side, and every distance of a row becomes the smallest over the frame's descriptors.
// Gated, only the frames the pose gate describes (the candidate areas) pay: their warped descriptors, and the
// extra distances of their rows' cells.
//
// Per frame: describe(seq, image, current_seq) in the describe node (parallel; before DirdDistances::describe
// of the same frame, whose publish hands the warped descriptors over to the match node), then in the serial
// match node refine(seq, ...) on the entries distance_range() appended for row seq, and release_before(seq)
// once rows before seq are final.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/dird_distances.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/viewpoint.hpp"

namespace loopgate {

class ViewpointDistances {
 public:
  // `dird`: the method's descriptor configuration. The warps are about the dataset camera's principal point
  // (the image centre when the dataset has no calibration).
  ViewpointDistances(const MethodContext& context, const DirdConfig& dird, const ViewpointConfig& config,
                     int row_horizon_frames);

  bool enabled() const { return config_.enabled(); }

  // Describe node (parallel): the warped descriptors of frame `seq` when its row may still get cells at
  // frame `current_seq` (seq + row horizon >= current_seq); nothing without an image.
  void describe(std::size_t seq, const cv::Mat* image, std::size_t current_seq);
  // Match node: row `seq`'s entries out[first..] (from DirdDistances::distance_range) become the smallest
  // distance over the frame's descriptors.
  void refine(std::size_t seq, DirdDistances& distances, std::vector<DistanceEntry>& out, std::size_t first);
  // Match node: drops the warped descriptors of the frames before `seq` (their rows are final).
  void release_before(std::size_t seq);

  // summary.json "viewpoint": the configuration, the offset ratios, frames described with warps, rows
  // refined, distances computed with a warp, pairs whose best distance came from a warp.
  nlohmann::json summary() const;

 private:
  struct Warped {
    std::vector<Descriptor> raw;    // one per warp, written by describe
    std::vector<Descriptor> codes;  // coded by the match node on first use
    std::vector<double> norms;
    bool coded = false;
  };

  ViewpointConfig config_;
  double cx_fraction_ = 0.5;  // principal point / image width
  std::size_t horizon_ = 0;
  DirdExtractor extractor_;
  std::vector<std::unique_ptr<Warped>> frames_;  // by seq
  std::size_t released_ = 0;
  std::atomic<std::size_t> frames_described_{0};
  std::atomic<int> summary_width_px_{0};
  std::size_t warped_distances_ = 0, pairs_improved_ = 0, rows_refined_ = 0;
};

}  // namespace loopgate
