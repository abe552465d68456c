#include "pipeline/methods/viewpoint_distances.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "pipeline/frame/frame_steps.hpp"

namespace loopgate {

ViewpointDistances::ViewpointDistances(const MethodContext& context, const DirdConfig& dird,
                                       const ViewpointConfig& config, int row_horizon_frames)
    : config_(config), horizon_(static_cast<std::size_t>(std::max(0, row_horizon_frames))), extractor_(dird) {
  if (!config_.enabled()) return;
  frames_.resize(context.capacity);
  // The principal point as a fraction of the width (the image centre without a calibration).
  const std::optional<CameraCalibration> camera = context.images.dataset().camera();
  if (camera && camera->width_px > 0 && camera->cx > 0.0 && camera->cx < camera->width_px)
    cx_fraction_ = (camera->cx + 0.5) / camera->width_px;
}

void ViewpointDistances::describe(std::size_t seq, const cv::Mat* image, std::size_t current_seq) {
  if (!enabled() || !image || seq + horizon_ < current_seq) return;
  const std::vector<double> offsets = viewpoint_offsets(config_, image->cols);
  if (offsets.empty()) return;
  const double cx_px = cx_fraction_ * image->cols - 0.5;
  auto warped = std::make_unique<Warped>();
  warped->raw.reserve(offsets.size());
  for (const double offset : offsets)
    warped->raw.push_back(extractor_.extract(warp_lateral(*image, offset, cx_px)));
  frames_.at(seq) = std::move(warped);
  frames_described_.fetch_add(1, std::memory_order_relaxed);
  summary_width_px_.store(image->cols, std::memory_order_relaxed);
}

void ViewpointDistances::refine(std::size_t seq, DirdDistances& distances, std::vector<DistanceEntry>& out,
                                std::size_t first) {
  if (!enabled() || first >= out.size() || seq >= frames_.size() || !frames_[seq]) return;
  Warped& warped = *frames_[seq];
  if (!warped.coded) {
    std::vector<Descriptor> codes;
    std::vector<double> norms;
    codes.reserve(warped.raw.size());
    for (const Descriptor& raw : warped.raw) {
      Descriptor code{};
      double norm = 0.0;
      if (!distances.code_like(seq, raw, code, norm)) return;
      codes.push_back(code);
      norms.push_back(norm);
    }
    warped.codes = std::move(codes);
    warped.norms = std::move(norms);
    warped.coded = true;
  }
  ++rows_refined_;
  for (std::size_t e = first; e < out.size(); ++e) {
    const auto j = static_cast<std::size_t>(out[e].j);
    double best = out[e].distance;
    for (std::size_t k = 0; k < warped.codes.size(); ++k) {
      best = std::min(best, distances.distance_to(warped.codes[k], warped.norms[k], j));
    }
    warped_distances_ += warped.codes.size();
    if (best < out[e].distance) ++pairs_improved_;
    out[e].distance = best;
  }
}

void ViewpointDistances::release_before(std::size_t seq) {
  if (!enabled()) return;
  seq = std::min(seq, frames_.size());
  for (; released_ < seq; ++released_) frames_[released_].reset();
}

nlohmann::json ViewpointDistances::summary() const {
  if (!enabled()) return nlohmann::json::object();
  const int width = summary_width_px_.load(std::memory_order_relaxed);
  return {{"viewpoint",
           {{"lateral_m", config_.lateral_m},
            {"side_distance_m", config_.side_distance_m},
            {"principal_point_fraction", cx_fraction_},
            {"offset_ratios", viewpoint_offsets(config_, width)},
            {"frames_with_warps", frames_described_.load()},
            {"rows_refined", rows_refined_},
            {"warped_distances", warped_distances_},
            {"pairs_improved", pairs_improved_}}}};
}

}  // namespace loopgate
