// KLT front end of the ekf source (vio-ekf.md § Front end): Shi-Tomasi corners, pyramidal Lucas-Kanade
// with a forward-backward check, RANSAC (fundamental matrix on undistorted points) and grid-based
// re-detection to keep about config.max_features tracked.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "core/camera_model.hpp"
#include "core/types.hpp"
#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/msckf.hpp"

namespace loopgate {

struct TrackedFeature {
  std::uint64_t id = 0;
  cv::Point2f uv_px;                             // distorted pixel position in the current image
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();  // undistorted normalised coordinates
  int track_length = 1;                          // images this feature has been seen in
};

struct TrackerStats {
  int tracked = 0;          // carried over from the previous image (after all checks)
  int lost_klt = 0;         // LK failure or out of image
  int rejected_fb = 0;      // forward-backward check
  int rejected_ransac = 0;  // RANSAC outliers
  int detected = 0;         // new corners
};

class FeatureTracker {
 public:
  // Throws ConfigError for a bad camera calibration (see CameraModel).
  FeatureTracker(const EkfConfig& config, const CameraCalibration& camera);

  // Tracks into `grey` (8-bit, one channel); returns the current features. Throws DataError when the
  // image is empty, not 8-bit grey, or of another size than the calibration.
  const std::vector<TrackedFeature>& track(const cv::Mat& grey);

  const std::vector<TrackedFeature>& features() const { return features_; }
  const TrackerStats& last_stats() const { return stats_; }
  void reset();

  // The current features as filter observations.
  std::vector<FeatureObservation> observations() const;

 private:
  void detect(const cv::Mat& grey);

  EkfConfig config_;
  CameraModel camera_;
  double focal_px_;
  std::vector<cv::Mat> previous_pyramid_;
  std::vector<TrackedFeature> features_;
  TrackerStats stats_;
  std::uint64_t next_id_ = 0;
};

}  // namespace loopgate
