#include "stages/dird/viewpoint.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>

#include "core/validate.hpp"

namespace loopgate {

namespace {
// Half a DIRD pooling cell as a fraction of the image width: 12 cells across (docs/detection.md § DIRD), so
// the edge columns (W / 2 from the centre) move by a half cell per 1 / 12 of the offset ratio d / D.
constexpr double kHalfCellsPerUnitOffset = 12.0;
}  // namespace

void ViewpointConfig::validate() const {
  require_in("dird_seqslam.viewpoint_lateral_m", lateral_m, 0.0, 50.0, "m (0 = off)");
  require_in("dird_seqslam.viewpoint_side_distance_m", side_distance_m, 0.5, 1000.0, "m");
  require(lateral_m < 0.9 * side_distance_m, "dird_seqslam.viewpoint_lateral_m",
          "below 0.9 x dird_seqslam.viewpoint_side_distance_m (" + std::to_string(side_distance_m) +
              " m: a camera cannot move through the sides)",
          std::to_string(lateral_m));
  require_in("dird_seqslam.viewpoint_max_warps_per_side", max_warps_per_side, 1, 16, "warps");
}

std::vector<double> viewpoint_offsets(const ViewpointConfig& config, int width_px) {
  std::vector<double> offsets;
  if (!config.enabled() || width_px < 2) return offsets;
  const double largest = config.lateral_m / config.side_distance_m;
  const int n = std::clamp(static_cast<int>(std::ceil(kHalfCellsPerUnitOffset * largest - 1e-9)), 1,
                           config.max_warps_per_side);
  for (int k = 1; k <= n; ++k) offsets.push_back(largest * k / n);
  for (int k = 1; k <= n; ++k) offsets.push_back(-largest * k / n);
  return offsets;
}

cv::Mat warp_lateral(const cv::Mat& image, double offset, double cx_px) {
  if (!(std::abs(offset) < 1.0)) {
    throw std::invalid_argument("warp_lateral: offset ratio " + std::to_string(offset) +
                                " is not in (-1, 1)");
  }
  cv::Mat map_x(image.rows, image.cols, CV_32FC1);
  cv::Mat map_y(image.rows, image.cols, CV_32FC1);
  std::vector<float> source_x(static_cast<std::size_t>(image.cols));
  for (int x = 0; x < image.cols; ++x) {
    const double from_centre = x - cx_px;
    const double scale = from_centre < 0.0 ? 1.0 + offset : 1.0 - offset;
    source_x[static_cast<std::size_t>(x)] = static_cast<float>(cx_px + from_centre / scale);
  }
  for (int y = 0; y < image.rows; ++y) {
    float* mx = map_x.ptr<float>(y);
    float* my = map_y.ptr<float>(y);
    for (int x = 0; x < image.cols; ++x) {
      mx[x] = source_x[static_cast<std::size_t>(x)];
      my[x] = static_cast<float>(y);
    }
  }
  cv::Mat out;
  cv::remap(image, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
  return out;
}

}  // namespace loopgate
