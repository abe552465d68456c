#include "stages/ekf/feature_tracker.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <string>

#include "core/error.hpp"

namespace loopgate {
namespace {

constexpr int kMinRansacPoints = 8;

}  // namespace

FeatureTracker::FeatureTracker(const EkfConfig& config, const CameraCalibration& camera)
    : config_(config), camera_(camera), focal_px_(0.5 * (camera.fx + camera.fy)) {}

void FeatureTracker::reset() {
  previous_pyramid_.clear();
  features_.clear();
  stats_ = {};
}

std::vector<FeatureObservation> FeatureTracker::observations() const {
  std::vector<FeatureObservation> out;
  out.reserve(features_.size());
  for (const TrackedFeature& f : features_) out.push_back(FeatureObservation{f.id, f.xy});
  return out;
}

const std::vector<TrackedFeature>& FeatureTracker::track(const cv::Mat& grey) {
  const CameraCalibration& calib = camera_.calibration();
  if (grey.empty() || grey.type() != CV_8UC1) {
    throw DataError("<image>", "ekf tracker: expected a non-empty 8-bit grey image");
  }
  if (grey.cols != calib.width_px || grey.rows != calib.height_px) {
    throw DataError("<image>", "ekf tracker: image is " + std::to_string(grey.cols) + "x" +
                                   std::to_string(grey.rows) + ", the camera calibration says " +
                                   std::to_string(calib.width_px) + "x" + std::to_string(calib.height_px));
  }
  stats_ = {};
  const cv::Size window(config_.klt_window_px, config_.klt_window_px);
  std::vector<cv::Mat> pyramid;
  cv::buildOpticalFlowPyramid(grey, pyramid, window, config_.klt_pyramid_levels);

  if (!previous_pyramid_.empty() && !features_.empty()) {
    std::vector<cv::Point2f> previous_pts;
    previous_pts.reserve(features_.size());
    for (const TrackedFeature& f : features_) previous_pts.push_back(f.uv_px);
    const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                    config_.klt_max_iterations, config_.klt_epsilon);
    std::vector<cv::Point2f> current_pts;
    std::vector<unsigned char> status_fwd;
    std::vector<float> error;
    cv::calcOpticalFlowPyrLK(previous_pyramid_, pyramid, previous_pts, current_pts, status_fwd, error, window,
                             config_.klt_pyramid_levels, criteria);
    std::vector<cv::Point2f> back_pts = previous_pts;
    std::vector<unsigned char> status_bwd;
    cv::calcOpticalFlowPyrLK(pyramid, previous_pyramid_, current_pts, back_pts, status_bwd, error, window,
                             config_.klt_pyramid_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    const auto border = static_cast<float>(config_.border_px);
    const float max_x = static_cast<float>(grey.cols - 1) - border;
    const float max_y = static_cast<float>(grey.rows - 1) - border;
    std::vector<TrackedFeature> kept;
    std::vector<cv::Point2f> kept_previous_und;
    std::vector<cv::Point2f> kept_current_und;
    kept.reserve(features_.size());
    for (std::size_t i = 0; i < features_.size(); ++i) {
      const cv::Point2f& p = current_pts[i];
      if (status_fwd[i] == 0 || p.x < border || p.y < border || p.x > max_x || p.y > max_y) {
        ++stats_.lost_klt;
        continue;
      }
      const cv::Point2f d = back_pts[i] - previous_pts[i];
      if (status_bwd[i] == 0 || std::sqrt(d.dot(d)) > config_.fb_check_max_px) {
        ++stats_.rejected_fb;
        continue;
      }
      TrackedFeature f = features_[i];
      f.uv_px = p;
      f.xy = camera_.undistort_normalized(Eigen::Vector2d(p.x, p.y));
      ++f.track_length;
      // RANSAC works on undistorted points scaled to pixels of the mean focal length.
      kept_previous_und.emplace_back(static_cast<float>(features_[i].xy.x() * focal_px_),
                                     static_cast<float>(features_[i].xy.y() * focal_px_));
      kept_current_und.emplace_back(static_cast<float>(f.xy.x() * focal_px_),
                                    static_cast<float>(f.xy.y() * focal_px_));
      kept.push_back(f);
    }
    if (static_cast<int>(kept.size()) >= kMinRansacPoints) {
      std::vector<unsigned char> inliers;
      const cv::Mat F =
          cv::findFundamentalMat(kept_previous_und, kept_current_und, cv::FM_RANSAC,
                                 config_.ransac_threshold_px, config_.ransac_confidence, inliers);
      if (!F.empty() && inliers.size() == kept.size()) {
        std::vector<TrackedFeature> filtered;
        filtered.reserve(kept.size());
        for (std::size_t i = 0; i < kept.size(); ++i) {
          if (inliers[i] != 0) {
            filtered.push_back(kept[i]);
          } else {
            ++stats_.rejected_ransac;
          }
        }
        kept = std::move(filtered);
      }
    }
    features_ = std::move(kept);
  } else {
    features_.clear();
  }
  stats_.tracked = static_cast<int>(features_.size());
  detect(grey);
  previous_pyramid_ = std::move(pyramid);
  return features_;
}

void FeatureTracker::detect(const cv::Mat& grey) {
  const int target = config_.max_features;
  if (static_cast<int>(features_.size()) >= target) return;
  const int cells = config_.grid_cols * config_.grid_rows;
  const int per_cell = std::max(1, (target + cells - 1) / cells);
  const double cell_w = static_cast<double>(grey.cols) / config_.grid_cols;
  const double cell_h = static_cast<double>(grey.rows) / config_.grid_rows;
  auto cell_of = [&](const cv::Point2f& p) {
    const int cx = std::clamp(static_cast<int>(p.x / cell_w), 0, config_.grid_cols - 1);
    const int cy = std::clamp(static_cast<int>(p.y / cell_h), 0, config_.grid_rows - 1);
    return cy * config_.grid_cols + cx;
  };
  // Mask out the border and the neighbourhood of existing features.
  cv::Mat mask(grey.size(), CV_8UC1, cv::Scalar(0));
  const int b = config_.border_px;
  mask(cv::Rect(b, b, grey.cols - 2 * b, grey.rows - 2 * b)).setTo(255);
  const int radius = static_cast<int>(std::lround(config_.min_feature_distance_px));
  std::vector<int> count(static_cast<std::size_t>(cells), 0);
  for (const TrackedFeature& f : features_) {
    cv::circle(mask, f.uv_px, radius, cv::Scalar(0), cv::FILLED);
    ++count[static_cast<std::size_t>(cell_of(f.uv_px))];
  }
  const int needed = target - static_cast<int>(features_.size());
  std::vector<cv::Point2f> corners;
  // Ask for more than needed so that empty cells can be filled before crowded ones.
  cv::goodFeaturesToTrack(grey, corners, 3 * needed + cells, config_.shi_tomasi_quality,
                          config_.min_feature_distance_px, mask, config_.shi_tomasi_block_size);
  // Corners come sorted by strength: first fill each cell up to per_cell, then take the rest in order.
  std::vector<bool> taken(corners.size(), false);
  int added = 0;
  for (int pass = 0; pass < 2 && added < needed; ++pass) {
    for (std::size_t i = 0; i < corners.size() && added < needed; ++i) {
      if (taken[i]) continue;
      const auto cell = static_cast<std::size_t>(cell_of(corners[i]));
      if (pass == 0 && count[cell] >= per_cell) continue;
      taken[i] = true;
      ++count[cell];
      ++added;
      TrackedFeature f;
      f.id = next_id_++;
      f.uv_px = corners[i];
      f.xy = camera_.undistort_normalized(Eigen::Vector2d(corners[i].x, corners[i].y));
      features_.push_back(f);
    }
  }
  stats_.detected = added;
}

}  // namespace loopgate
