#include "stages/ekf/feature_tracker.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <stdexcept>
#include <string>

#include "core/error.hpp"
#include "core/klt.hpp"

namespace loopgate {
namespace {

constexpr int kMinRansacPoints = 8;

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Orders floats as their values do (negative ones reversed): the key of the histogram below.
std::uint32_t order_key(float value) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof bits);
  return (bits & 0x80000000U) != 0 ? ~bits : bits | 0x80000000U;
}

}  // namespace

// A histogram of the top 12 bits of order_key() finds the bucket that holds the median and its rank there;
// only that bucket's values, a few percent, are then partially sorted.
float quarter_median(const cv::Mat& response) {
  if (!response.empty() && response.type() != CV_32FC1)
    throw std::invalid_argument("quarter_median: expected a CV_32F single-channel image");
  constexpr int kShift = 20;
  std::array<std::uint32_t, std::size_t{1} << (32 - kShift)> histogram{};
  std::size_t n = 0;
  for (int y = 0; y < response.rows; y += 2) {
    const float* r = response.ptr<float>(y);
    for (int x = 0; x < response.cols; x += 2, ++n) ++histogram[order_key(r[x]) >> kShift];
  }
  if (n == 0) return 0.0F;  // an empty cell: no noise level
  std::size_t rank = n / 2;
  std::uint32_t bucket = 0;
  while (rank >= histogram[bucket]) rank -= histogram[bucket++];
  std::vector<float> values;
  values.reserve(histogram[bucket]);
  for (int y = 0; y < response.rows; y += 2) {
    const float* r = response.ptr<float>(y);
    for (int x = 0; x < response.cols; x += 2) {
      if (order_key(r[x]) >> kShift == bucket) values.push_back(r[x]);
    }
  }
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(rank);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

FeatureTracker::FeatureTracker(const EkfConfig& config, const CameraCalibration& camera)
    : config_(config), camera_(camera), focal_px_(0.5 * (camera.fx + camera.fy)) {}

void FeatureTracker::reset() {
  previous_pyramid_.clear();
  features_.clear();
  cell_cooldown_.clear();
  stats_ = {};
}

std::vector<FeatureObservation> FeatureTracker::observations() const {
  std::vector<FeatureObservation> out;
  out.reserve(features_.size());
  for (const TrackedFeature& f : features_) out.push_back(FeatureObservation{f.id, f.xy});
  return out;
}

const std::vector<TrackedFeature>& FeatureTracker::track(const cv::Mat& grey) {
  return track(grey, nullptr);
}

TrackerImage FeatureTracker::prepare(const cv::Mat& grey) const {
  const CameraCalibration& calib = camera_.calibration();
  if (grey.empty() || grey.type() != CV_8UC1) {
    throw DataError("<image>", "ekf tracker: expected a non-empty 8-bit grey image");
  }
  if (grey.cols != calib.width_px || grey.rows != calib.height_px) {
    throw DataError("<image>", "ekf tracker: image is " + std::to_string(grey.cols) + "x" +
                                   std::to_string(grey.rows) + ", the camera calibration says " +
                                   std::to_string(calib.width_px) + "x" + std::to_string(calib.height_px));
  }
  const auto t0 = Clock::now();
  TrackerImage out;
  // Pixel noise (dark, high-gain images) breeds corners on noise and drags the KLT: smooth it first.
  if (config_.image_blur_sigma_px > 0.0) {
    cv::GaussianBlur(grey, out.image, cv::Size(0, 0), config_.image_blur_sigma_px);
  } else {
    out.image = grey;
  }
  const cv::Size window(config_.klt_window_px, config_.klt_window_px);
  // cv::buildOpticalFlowPyramid's pyramid, byte for byte, in less time (core/klt.hpp).
  build_klt_pyramid(out.image, window, config_.klt_pyramid_levels, out.pyramid);
  out.prepare_ms = ms_since(t0);
  return out;
}

const std::vector<TrackedFeature>& FeatureTracker::track(const cv::Mat& grey,
                                                         const Eigen::Matrix3d* R_cur_prev) {
  return track(prepare(grey), R_cur_prev);
}

const std::vector<TrackedFeature>& FeatureTracker::track(const TrackerImage& prepared,
                                                         const Eigen::Matrix3d* R_cur_prev) {
  const CameraCalibration& calib = camera_.calibration();
  const cv::Mat& grey = prepared.image;
  if (grey.empty() || grey.type() != CV_8UC1 || grey.cols != calib.width_px || grey.rows != calib.height_px ||
      prepared.pyramid.empty()) {
    throw DataError("<image>", "ekf tracker: the prepared image does not fit this tracker's calibration");
  }
  stats_ = {};
  stats_.pyramid_ms = prepared.prepare_ms;
  const cv::Size window(config_.klt_window_px, config_.klt_window_px);
  const std::vector<cv::Mat>& pyramid = prepared.pyramid;

  if (!previous_pyramid_.empty() && !features_.empty()) {
    std::vector<cv::Point2f> previous_pts;
    previous_pts.reserve(features_.size());
    for (const TrackedFeature& f : features_) previous_pts.push_back(f.uv_px);
    const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                    config_.klt_max_iterations, config_.klt_epsilon);
    auto t0 = Clock::now();
    // Initial positions: the previous ones moved by the camera rotation (far points move with it).
    std::vector<cv::Point2f> current_pts = previous_pts;
    if (R_cur_prev != nullptr) {
      for (std::size_t i = 0; i < features_.size(); ++i) {
        const Eigen::Vector3d ray = *R_cur_prev * features_[i].xy.homogeneous();
        Eigen::Vector2d uv;
        if (ray.z() > 0.0 && camera_.project(ray, &uv) && uv.x() >= 0.0 && uv.y() >= 0.0 &&
            uv.x() <= grey.cols - 1 && uv.y() <= grey.rows - 1) {
          current_pts[i] = cv::Point2f(static_cast<float>(uv.x()), static_cast<float>(uv.y()));
          ++stats_.predicted;
        }
      }
    }
    std::vector<unsigned char> status_fwd;
    // No error output: OpenCV then skips its extra pass over every window at level 0 (unused here).
    cv::calcOpticalFlowPyrLK(previous_pyramid_, pyramid, previous_pts, current_pts, status_fwd, cv::noArray(),
                             window, config_.klt_pyramid_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    std::vector<cv::Point2f> back_pts = previous_pts;
    std::vector<unsigned char> status_bwd;
    const int check_levels =
        config_.klt_check_pyramid_levels < 0 ? config_.klt_pyramid_levels : config_.klt_check_pyramid_levels;
    cv::calcOpticalFlowPyrLK(pyramid, previous_pyramid_, current_pts, back_pts, status_bwd, cv::noArray(),
                             window, check_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    stats_.klt_ms = ms_since(t0);
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
    t0 = Clock::now();
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
    stats_.ransac_ms = ms_since(t0);
  } else {
    features_.clear();
  }
  stats_.tracked = static_cast<int>(features_.size());
  const auto t_detect = Clock::now();
  detect(grey);
  stats_.detect_ms = ms_since(t_detect);
  previous_pyramid_ = pyramid;  // shares the pixels
  return features_;
}

void FeatureTracker::detect_in(const cv::Mat& grey, const cv::Mat& mask, const cv::Rect& roi, int count,
                               std::vector<cv::Point2f>* corners) const {
  // Shi-Tomasi as cv::goodFeaturesToTrack, with one more threshold: the response must exceed
  // corner_noise_factor times the median response of the region, so that on a dark, noisy image the
  // corners of sensor noise (a high median) are not taken for features.
  cv::Mat response;
  cv::cornerMinEigenVal(grey(roi), response, config_.shi_tomasi_block_size, 3);
  const cv::Mat roi_mask = mask(roi);
  // The largest response where the mask is set (0 where it is set nowhere, as cv::minMaxLoc gives).
  float max_masked = -std::numeric_limits<float>::infinity();
  bool any_masked = false;
  for (int y = 0; y < response.rows; ++y) {
    const float* r = response.ptr<float>(y);
    const unsigned char* m = roi_mask.ptr<unsigned char>(y);
    for (int x = 0; x < response.cols; ++x) {
      if (m[x] != 0) {
        any_masked = true;
        max_masked = std::max(max_masked, r[x]);
      }
    }
  }
  const double max_response = any_masked ? static_cast<double>(max_masked) : 0.0;
  double threshold = config_.shi_tomasi_quality * max_response;
  if (config_.corner_noise_factor > 0.0) {
    // Median over every second row and column (a quarter of the pixels is plenty for a noise level).
    threshold =
        std::max(threshold, config_.corner_noise_factor * static_cast<double>(quarter_median(response)));
  }
  struct Candidate {
    float response;
    int x;
    int y;
  };
  std::vector<Candidate> candidates;
  // Local maxima above the threshold: no response of the 3 x 3 neighbourhood is larger (what comparing with
  // the response dilated by a 3 x 3 rectangle tells, looking only at the few pixels above the threshold).
  for (int y = 1; y + 1 < response.rows; ++y) {
    const float* up = response.ptr<float>(y - 1);
    const float* r = response.ptr<float>(y);
    const float* down = response.ptr<float>(y + 1);
    const unsigned char* m = roi_mask.ptr<unsigned char>(y);
    for (int x = 1; x + 1 < response.cols; ++x) {
      const float v = r[x];
      if (m[x] == 0 || !(v > threshold)) continue;
      if (up[x - 1] <= v && up[x] <= v && up[x + 1] <= v && r[x - 1] <= v && r[x + 1] <= v &&
          down[x - 1] <= v && down[x] <= v && down[x + 1] <= v)
        candidates.push_back(Candidate{v, x, y});
    }
  }
  // Strongest first, ties in scan order (row, then column): the order of a stable sort by response. Only
  // the first few are taken (count, often a handful, of hundreds), so they come off a heap one by one
  // instead of sorting them all.
  const auto after = [](const Candidate& a, const Candidate& b) {
    if (a.response != b.response) return a.response < b.response;
    return a.y != b.y ? a.y > b.y : a.x > b.x;
  };
  std::make_heap(candidates.begin(), candidates.end(), after);
  const double min_d2 = config_.min_feature_distance_px * config_.min_feature_distance_px;
  const std::size_t first = corners->size();
  while (!candidates.empty() && static_cast<int>(corners->size() - first) < count) {
    std::pop_heap(candidates.begin(), candidates.end(), after);
    const Candidate c = candidates.back();
    candidates.pop_back();
    const cv::Point2f p(static_cast<float>(c.x + roi.x), static_cast<float>(c.y + roi.y));
    bool far = true;
    for (std::size_t k = first; k < corners->size() && far; ++k) {
      const cv::Point2f d = (*corners)[k] - p;
      far = static_cast<double>(d.dot(d)) >= min_d2;
    }
    if (far) corners->push_back(p);
  }
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
  int added = 0;
  auto add = [&](const cv::Point2f& p) {
    TrackedFeature f;
    f.id = next_id_++;
    f.uv_px = p;
    f.xy = camera_.undistort_normalized(Eigen::Vector2d(p.x, p.y));
    features_.push_back(f);
    cv::circle(mask, p, radius, cv::Scalar(0), cv::FILLED);
    ++count[static_cast<std::size_t>(cell_of(p))];
    ++added;
  };
  // Pass 1: corners only inside the cells below their share, the emptiest first. Usually a few features
  // are lost per image, so this looks at a few cells instead of the whole image. Pass 2: when cells
  // without texture leave the set short by at least redetect_min_missing, the other cells take more than
  // their share. A cell that gives fewer corners than asked is left alone for empty_cell_retry_frames
  // images (dark or texture-poor parts of the image would otherwise be searched in every image).
  if (cell_cooldown_.size() != static_cast<std::size_t>(cells))
    cell_cooldown_.assign(static_cast<std::size_t>(cells), 0);
  std::vector<int> order(static_cast<std::size_t>(cells));
  for (int c = 0; c < cells; ++c) order[static_cast<std::size_t>(c)] = c;
  std::stable_sort(order.begin(), order.end(), [&](int a, int c) {
    return count[static_cast<std::size_t>(a)] < count[static_cast<std::size_t>(c)];
  });
  std::vector<bool> barren(static_cast<std::size_t>(cells), false);
  for (int& cooldown : cell_cooldown_) cooldown = std::max(0, cooldown - 1);
  std::vector<cv::Point2f> corners;
  for (int pass = 1; pass <= 2; ++pass) {
    if (pass == 2 && needed - added < config_.redetect_min_missing) break;
    for (int c : order) {
      const auto cell = static_cast<std::size_t>(c);
      if (cell_cooldown_[cell] > 0 || barren[cell]) continue;
      const int share = pass == 1 ? per_cell - count[cell] : needed - added;
      const int wanted = std::min(share, needed - added);
      if (wanted <= 0) continue;
      const int x0 = static_cast<int>(std::lround((c % config_.grid_cols) * cell_w));
      const int y0 = static_cast<int>(std::lround((c / config_.grid_cols) * cell_h));
      const int x1 = static_cast<int>(std::lround((c % config_.grid_cols + 1) * cell_w));
      const int y1 = static_cast<int>(std::lround((c / config_.grid_cols + 1) * cell_h));
      corners.clear();
      detect_in(grey, mask, cv::Rect(x0, y0, x1 - x0, y1 - y0), wanted, &corners);
      for (const cv::Point2f& p : corners) add(p);
      if (static_cast<int>(corners.size()) < wanted) {
        // Nothing more to find here: not again in this image, nor in the next empty_cell_retry_frames.
        barren[cell] = true;
        cell_cooldown_[cell] = config_.empty_cell_retry_frames;
      }
    }
  }
  stats_.detected = added;
}

}  // namespace loopgate
