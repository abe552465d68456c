// KLT front end of the ekf source (docs/ekf.md): Shi-Tomasi corners, pyramidal Lucas-Kanade
// with a forward-backward check, RANSAC (fundamental matrix on undistorted points) and grid-based
// re-detection to keep about config.max_features tracked. With the rotation between the two images (from
// the gyro) the KLT search starts at the rotation-predicted position, which needs fewer iterations and
// pyramid levels and loses fewer features under fast turns.
#pragma once

#include <Eigen/Core>
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
  int predicted = 0;        // KLT searches started at a rotation-predicted position
  // Wall time of the steps (the per-frame profile of the front end).
  double pyramid_ms = 0;
  double klt_ms = 0;  // forward + backward Lucas-Kanade
  double ransac_ms = 0;
  double detect_ms = 0;
};

// What the tracker needs of one image before it tracks into it, and which does not depend on earlier
// images: the image after image_blur_sigma_px (detection runs on it) and its KLT pyramid with derivatives.
// FeatureTracker::prepare computes it (const: on any thread, e.g. where the pipeline decodes frames in
// parallel); track() then does the work that has to run in order.
struct TrackerImage {
  cv::Mat image;
  std::vector<cv::Mat> pyramid;
  double prepare_ms = 0;  // wall time of prepare(), reported as TrackerStats::pyramid_ms
};

// The median of a CV_32F image's values in every second row and column (the element std::nth_element puts
// at index n / 2; 0 for an empty image): the noise level of the corner detection's responses, computed for
// every grid cell it searches, 2.5-3x faster than nth_element over all of them (bench_ekf_frame).
float quarter_median(const cv::Mat& response);

// Shi-Tomasi's corner response (the smaller eigenvalue of the structure tensor) of `grey` (CV_8UC1) over
// `roi`, into `response` (CV_32F, the roi's size), as cv::cornerMinEigenVal(grey(roi), response, block_size,
// 3) computes it: 3 x 3 Sobel derivatives (the pixels around the roi where the image has them, reflected at
// the image's edges), their products summed over block_size x block_size (reflected at the roi's edges), in
// OpenCV's units. The derivatives and sums are exact integers here (OpenCV's are floats), so a response can
// differ from OpenCV's in its last bits; about twice as fast (bench_ekf_frame).
void shi_tomasi_response(const cv::Mat& grey, const cv::Rect& roi, int block_size, cv::Mat& response);

class FeatureTracker {
 public:
  // Throws ConfigError for a bad camera calibration (see CameraModel).
  FeatureTracker(const EkfConfig& config, const CameraCalibration& camera);

  // Tracks into `grey` (8-bit, one channel); returns the current features. Throws DataError when the
  // image is empty, not 8-bit grey, or of another size than the calibration.
  const std::vector<TrackedFeature>& track(const cv::Mat& grey);
  // As above; `R_cur_prev` rotates bearings of the previous camera frame into the current one (from the
  // gyro), used to predict where each feature moved. nullptr: no prediction (the previous position).
  const std::vector<TrackedFeature>& track(const cv::Mat& grey, const Eigen::Matrix3d* R_cur_prev);
  // The same on an image prepare()d beforehand (by this tracker or another with the same config and
  // calibration): the same features, bit for bit.
  const std::vector<TrackedFeature>& track(const TrackerImage& image, const Eigen::Matrix3d* R_cur_prev);

  // Validates `grey` (DataError as track()) and computes what track() needs of it. Thread-safe.
  TrackerImage prepare(const cv::Mat& grey) const;

  const std::vector<TrackedFeature>& features() const { return features_; }
  const TrackerStats& last_stats() const { return stats_; }
  void reset();

  // The current features as filter observations.
  std::vector<FeatureObservation> observations() const;

 private:
  void detect(const cv::Mat& grey);
  // Shi-Tomasi corners of one grid cell outside `mask`, strongest first, appended to `corners`.
  void detect_in(const cv::Mat& grey, const cv::Mat& mask, const cv::Rect& roi, int count,
                 std::vector<cv::Point2f>* corners) const;

  EkfConfig config_;
  CameraModel camera_;
  double focal_px_;
  std::vector<cv::Mat> previous_pyramid_;
  std::vector<int> cell_cooldown_;  // images until an empty grid cell is searched again
  std::vector<TrackedFeature> features_;
  TrackerStats stats_;
  std::uint64_t next_id_ = 0;
};

}  // namespace loopgate
