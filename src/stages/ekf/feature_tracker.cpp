#include "stages/ekf/feature_tracker.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#ifdef __SSE2__
#include <emmintrin.h>
#endif
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
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

namespace {

// out[x] = ((A + C) / 2 - sqrt(((A - C) / 2)^2 + B^2)) x scale in float, four at a time where SSE2 is (the
// same operations in the same order as the scalar tail, so the same bits).
void min_eigenvalues(const std::int32_t* A, const std::int32_t* B, const std::int32_t* C, int n, float scale,
                     float* out) {
  int x = 0;
#ifdef __SSE2__
  const __m128 half = _mm_set1_ps(0.5F);
  const __m128 s = _mm_set1_ps(scale);
  for (; x + 4 <= n; x += 4) {
    const __m128 a = _mm_cvtepi32_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(A + x)));
    const __m128 b = _mm_cvtepi32_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(B + x)));
    const __m128 c = _mm_cvtepi32_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(C + x)));
    const __m128 half_diff = _mm_mul_ps(_mm_sub_ps(a, c), half);
    const __m128 root = _mm_sqrt_ps(_mm_add_ps(_mm_mul_ps(half_diff, half_diff), _mm_mul_ps(b, b)));
    _mm_storeu_ps(out + x, _mm_mul_ps(_mm_sub_ps(_mm_mul_ps(_mm_add_ps(a, c), half), root), s));
  }
#endif
  for (; x < n; ++x) {
    const auto a = static_cast<float>(A[x]);
    const auto b = static_cast<float>(B[x]);
    const auto c = static_cast<float>(C[x]);
    const float half_diff = (a - c) * 0.5F;
    const float root = std::sqrt(half_diff * half_diff + b * b);
    out[x] = ((a + c) * 0.5F - root) * scale;
  }
}

}  // namespace

void shi_tomasi_response(const cv::Mat& grey, const cv::Rect& roi, int block_size, cv::Mat& response) {
  if (grey.type() != CV_8UC1 || roi.width <= 0 || roi.height <= 0 ||
      (roi & cv::Rect(0, 0, grey.cols, grey.rows)) != roi || block_size < 1 || block_size % 2 == 0)
    throw std::invalid_argument(
        "shi_tomasi_response: expected a CV_8UC1 image, a roi inside it and an odd block size");
  const int w = roi.width;
  const int h = roi.height;
  const int r = block_size / 2;
  // The roi with one pixel around it: the image's own pixels where it has them, reflected beyond (what
  // OpenCV's filters do on a view).
  cv::Mat padded;
  cv::copyMakeBorder(grey(roi), padded, 1, 1, 1, 1, cv::BORDER_REFLECT_101);
  // Products of the derivatives per roi row, each row with r entries on both ends reflected
  // (BORDER_REFLECT_101 within the roi, as OpenCV's box filter on the products), then summed along the row.
  const int ext = w + 2 * r;
  std::vector<std::int32_t> xx(static_cast<std::size_t>(ext)), xy(xx.size()), yy(xx.size());
  std::vector<std::int32_t> sum_xx(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::vector<std::int32_t> sum_xy(sum_xx.size()), sum_yy(sum_xx.size());
  std::vector<int> reflect_col(static_cast<std::size_t>(2 * r));
  for (int k = 0; k < r; ++k) {
    reflect_col[static_cast<std::size_t>(k)] = cv::borderInterpolate(k - r, w, cv::BORDER_REFLECT_101);
    reflect_col[static_cast<std::size_t>(r + k)] = cv::borderInterpolate(w + k, w, cv::BORDER_REFLECT_101);
  }
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* a = padded.ptr<std::uint8_t>(y);
    const std::uint8_t* b = padded.ptr<std::uint8_t>(y + 1);
    const std::uint8_t* c = padded.ptr<std::uint8_t>(y + 2);
    std::int32_t* pxx = xx.data() + r;
    std::int32_t* pxy = xy.data() + r;
    std::int32_t* pyy = yy.data() + r;
    for (int x = 0; x < w; ++x) {
      const int dx = (a[x + 2] - a[x]) + 2 * (b[x + 2] - b[x]) + (c[x + 2] - c[x]);
      const int dy = (c[x] + 2 * c[x + 1] + c[x + 2]) - (a[x] + 2 * a[x + 1] + a[x + 2]);
      pxx[x] = dx * dx;
      pxy[x] = dx * dy;
      pyy[x] = dy * dy;
    }
    for (int k = 0; k < r; ++k) {
      const auto left = static_cast<std::size_t>(k);
      const auto right = static_cast<std::size_t>(r + w + k);
      const auto from_left = static_cast<std::size_t>(r + reflect_col[left]);
      const auto from_right = static_cast<std::size_t>(r + reflect_col[static_cast<std::size_t>(r + k)]);
      xx[left] = xx[from_left];
      xy[left] = xy[from_left];
      yy[left] = yy[from_left];
      xx[right] = xx[from_right];
      xy[right] = xy[from_right];
      yy[right] = yy[from_right];
    }
    // Summed along the row: the first term, then the others added one shifted copy at a time (a form the
    // compiler vectorises).
    std::int32_t* out_xx = sum_xx.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    std::int32_t* out_xy = sum_xy.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    std::int32_t* out_yy = sum_yy.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    std::copy_n(xx.begin(), w, out_xx);
    std::copy_n(xy.begin(), w, out_xy);
    std::copy_n(yy.begin(), w, out_yy);
    for (int k = 1; k <= 2 * r; ++k) {
      const std::int32_t* in_xx = xx.data() + k;
      const std::int32_t* in_xy = xy.data() + k;
      const std::int32_t* in_yy = yy.data() + k;
      for (int x = 0; x < w; ++x) {
        out_xx[x] += in_xx[x];
        out_xy[x] += in_xy[x];
        out_yy[x] += in_yy[x];
      }
    }
  }
  // Down the columns (rows reflected at the roi's edges), and the smaller eigenvalue of
  // [[A, B], [B, C]] / 2: (A + C) / 2 - sqrt(((A - C) / 2)^2 + B^2), in float as OpenCV computes it and in
  // its units (its derivatives are scaled by 1 / (4 x block_size x 255), the sums by the square of that).
  const double unit = 1.0 / (4.0 * block_size * 255.0);
  const auto scale = static_cast<float>(unit * unit);
  response.create(h, w, CV_32F);
  std::vector<std::int32_t> col_xx(static_cast<std::size_t>(w)), col_xy(col_xx.size()), col_yy(col_xx.size());
  for (int y = 0; y < h; ++y) {
    for (int k = -r; k <= r; ++k) {
      const auto src = static_cast<std::size_t>(cv::borderInterpolate(y + k, h, cv::BORDER_REFLECT_101)) *
                       static_cast<std::size_t>(w);
      const std::int32_t* in_xx = sum_xx.data() + src;
      const std::int32_t* in_xy = sum_xy.data() + src;
      const std::int32_t* in_yy = sum_yy.data() + src;
      if (k == -r) {
        std::copy_n(in_xx, w, col_xx.begin());
        std::copy_n(in_xy, w, col_xy.begin());
        std::copy_n(in_yy, w, col_yy.begin());
        continue;
      }
      for (int x = 0; x < w; ++x) {
        col_xx[static_cast<std::size_t>(x)] += in_xx[x];
        col_xy[static_cast<std::size_t>(x)] += in_xy[x];
        col_yy[static_cast<std::size_t>(x)] += in_yy[x];
      }
    }
    min_eigenvalues(col_xx.data(), col_xy.data(), col_yy.data(), w, scale, response.ptr<float>(y));
  }
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
    // cv::calcOpticalFlowPyrLK's tracking with exact integer window sums, twice as fast (core/klt.hpp).
    track_klt(previous_pyramid_, pyramid, previous_pts, current_pts, status_fwd, window,
              config_.klt_pyramid_levels, criteria, true);
    std::vector<cv::Point2f> back_pts = previous_pts;
    std::vector<unsigned char> status_bwd;
    const int check_levels =
        config_.klt_check_pyramid_levels < 0 ? config_.klt_pyramid_levels : config_.klt_check_pyramid_levels;
    track_klt(pyramid, previous_pyramid_, current_pts, back_pts, status_bwd, window, check_levels, criteria,
              true);
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
  shi_tomasi_response(grey, roi, config_.shi_tomasi_block_size, response);
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
