// Viewpoint tolerance for whole-image DIRD matching (docs/viewpoint.md): a revisit driven a few metres to the
// side of its reference (the other lane) sees the street from elsewhere. For a forward-looking camera between
// two sides (facades, parked cars, hedges) at a lateral distance D, a camera moved sideways by d sees a point
// of the side at the same depth Z and height, only at another column: the column's distance from the
// principal point scales by (D - d) / D on the side it moved towards and by (D + d) / D on the other (x = f X
// / Z, X -> X - d; rows do not move). The query frame is also described warped so, for a few offsets d to
// either side, and each pair keeps the best distance over the warps.
//
// The rule for the warps: offsets d = +-lateral_m * k / n, k = 1..n. The largest moves the image's edge
// columns by (W / 2) * lateral_m / side_distance_m pixels; a warp moving them by less than half a DIRD
// pooling cell (W / 24: 4 x 4 tiles of 3 x 3 cells, 12 cells across) moves few samples into another cell, so
// n = min(max_warps_per_side, ceil(12 * lateral_m / side_distance_m)).
#pragma once

#include <opencv2/core/mat.hpp>
#include <vector>

namespace loopgate {

// Keys of section dird_seqslam (viewpoint_*).
struct ViewpointConfig {
  // Largest lateral offset between a revisit and its reference to compensate, metres; 0 = off (no warps).
  double lateral_m = 0.0;
  // Lateral distance of what lines the path (facades along a street) from the camera, metres.
  double side_distance_m = 8.0;
  // At most this many warps to each side.
  int max_warps_per_side = 3;

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("viewpoint_lateral_m", self.lateral_m);
    v("viewpoint_side_distance_m", self.side_distance_m);
    v("viewpoint_max_warps_per_side", self.max_warps_per_side);
  }
  // Throws ConfigError naming "dird_seqslam.viewpoint_<key>" and its range.
  void validate() const;
  bool enabled() const { return lateral_m > 0.0; }
};

// The signed offsets d / side_distance_m of the warps (positive: the camera moved right), by the rule above,
// for images `width_px` wide. Empty when the tolerance is off.
std::vector<double> viewpoint_offsets(const ViewpointConfig& config, int width_px);

// `image` as seen from a camera moved right by offset * D between sides at lateral distance D (offset =
// d / D, |offset| < 1), about the column `cx_px` (the principal point): a column at x - cx on the left of it
// comes from (x - cx) / (1 + offset), on the right from (x - cx) / (1 - offset). Columns that come from
// beyond the image are the image mirrored there (cv::BORDER_REFLECT_101). Bilinear; same size and type.
// Throws std::invalid_argument for |offset| >= 1.
cv::Mat warp_lateral(const cv::Mat& image, double offset, double cx_px);

}  // namespace loopgate
