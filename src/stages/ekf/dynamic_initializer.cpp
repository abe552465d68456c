#include "stages/ekf/dynamic_initializer.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <stdexcept>

#include "core/geometry.hpp"
#include "stages/ekf/vi_alignment.hpp"

namespace loopgate {
namespace {

std::string fmt(const char* format, auto... args) {
  char buf[1024];
  std::snprintf(buf, sizeof(buf), format, args...);
  return buf;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

Eigen::Vector2d project(const Eigen::Vector3d& p) {
  return p.head<2>() / p.z();
}

}  // namespace

DynamicInitializer::DynamicInitializer(const EkfConfig& config, const Eigen::Isometry3d& T_i_c,
                                       double focal_px, const ImuNoise& noise)
    : config_(config), T_i_c_(T_i_c), focal_px_(focal_px), noise_(noise) {
  config_.validate();
  if (!(focal_px_ > 0.0 && std::isfinite(focal_px_))) throw std::invalid_argument("focal_px must be > 0");
  if (!(noise_.accel_noise_density >= 0.0 && noise_.gyro_noise_density >= 0.0 &&
        noise_.accel_random_walk >= 0.0)) {
    throw std::invalid_argument("IMU noise densities must be >= 0");
  }
}

void DynamicInitializer::reset() {
  window_.clear();
  last_sample_.reset();
  frames_seen_ = 0;
  status_ = "no image yet";
}

std::optional<InitialState> DynamicInitializer::add_frame(const InitFrame& frame) {
  const std::size_t index = frames_seen_++;
  // Time order of the images and of the IMU samples: a break empties the window (the alignment needs a
  // continuous IMU record between its images).
  if (!window_.empty() && frame.t_ns <= window_.back().t_ns) {
    window_.clear();
    last_sample_.reset();
    status_ = fmt("image %zu: time %lld ns not after the previous image's; window restarted", index,
                  static_cast<long long>(frame.t_ns));
    return std::nullopt;
  }
  Frame f;
  f.t_ns = frame.t_ns;
  if (frame.observations != nullptr) {
    for (const FeatureObservation& o : *frame.observations) {
      if (o.xy.allFinite()) f.features.emplace(o.id, o.xy);
    }
  }
  if (last_sample_) f.imu.push_back(*last_sample_);
  for (const ImuSample& s : frame.imu) {
    // The sample at the boundary between two images may be given with both.
    if (!f.imu.empty() && s.t_ns == f.imu.back().t_ns && s.gyro_radps == f.imu.back().gyro_radps &&
        s.accel_mps2 == f.imu.back().accel_mps2) {
      continue;
    }
    if (!s.gyro_radps.allFinite() || !s.accel_mps2.allFinite() ||
        (!f.imu.empty() && s.t_ns <= f.imu.back().t_ns)) {
      window_.clear();
      last_sample_.reset();
      status_ =
          fmt("image %zu: IMU sample at %lld ns not finite or not after the previous one; window restarted",
              index, static_cast<long long>(s.t_ns));
      return std::nullopt;
    }
    f.imu.push_back(s);
  }
  if (!f.imu.empty()) last_sample_ = f.imu.back();
  if (!window_.empty() && (f.imu.empty() || f.imu.front().t_ns > window_.back().t_ns ||
                           f.imu.back().t_ns < f.t_ns - s_to_ns(0.05))) {
    // No IMU reading covering the interval since the previous image (allowing 50 ms held at the end).
    window_.clear();
    window_.push_back(std::move(f));
    status_ = fmt(
        "image %zu: no IMU samples covering the interval since the previous image; window restarted", index);
    return std::nullopt;
  }
  window_.push_back(std::move(f));
  const Timestamp window_ns = s_to_ns(config_.dynamic_init_window_s);
  while (window_.size() > 2 && window_.back().t_ns - window_[1].t_ns >= window_ns) window_.pop_front();
  const double span_s = ns_to_s(window_.back().t_ns - window_.front().t_ns);
  if (window_.back().features.empty()) {
    status_ = fmt("image %zu: no features", index);
    return std::nullopt;
  }
  if (span_s < 0.95 * config_.dynamic_init_window_s) {
    status_ = fmt("collecting: %.2f s of %.2f s", span_s, config_.dynamic_init_window_s);
    return std::nullopt;
  }
  std::optional<InitialState> result = try_align();
  if (result) result->frame = index;
  return result;
}

namespace {

// Median rotation-compensated parallax (px) of the features seen in both images, and their number: the
// bearing of each feature of image a is rotated by R_b_a into image b and compared with its observation
// there.
std::pair<double, std::size_t> pair_parallax_px(const FeatureMap& fa, const FeatureMap& fb,
                                                const Eigen::Matrix3d& R_b_a, double focal) {
  std::vector<double> d;
  for (const auto& [id, xa] : fa) {
    const auto it = fb.find(id);
    if (it == fb.end()) continue;
    const Eigen::Vector3d r = R_b_a * Eigen::Vector3d(xa.x(), xa.y(), 1.0);
    if (r.z() <= 1e-6) continue;
    d.push_back((project(r) - it->second).norm() * focal);
  }
  return std::make_pair(median(d), d.size());
}

// The rotation that best maps the bearings of image a onto those of image b (Kabsch): the parallax left after
// it is what translation makes, free of the gyro bias.
Eigen::Matrix3d rotation_fit(const FeatureMap& fa, const FeatureMap& fb) {
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  for (const auto& [id, xa] : fa) {
    const auto it = fb.find(id);
    if (it == fb.end()) continue;
    M += xa.homogeneous().normalized() * it->second.homogeneous().normalized().transpose();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd3(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd3.matrixV() * svd3.matrixU().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return Eigen::Matrix3d(svd3.matrixV() * D * svd3.matrixU().transpose());
}

// PnP of an image with features `features` against `points` (c0), starting from `guess`; false (T_out
// untouched) when it fails.
bool pnp(const FeatureMap& features, const std::unordered_map<std::uint64_t, Eigen::Vector3d>& points,
         double max_reproj, const Eigen::Isometry3d& guess, Eigen::Isometry3d* T_out) {
  std::vector<Eigen::Vector3d> p_c0;
  std::vector<Eigen::Vector2d> xy;
  for (const auto& [id, x] : features) {
    const auto it = points.find(id);
    if (it == points.end()) continue;
    p_c0.push_back(it->second);
    xy.push_back(x);
  }
  return pnp_ransac(p_c0, xy, max_reproj, guess, T_out);
}

}  // namespace

std::optional<InitialState> DynamicInitializer::try_align() {
  const std::size_t n = window_.size();
  const double span_s = ns_to_s(window_.back().t_ns - window_.front().t_ns);
  if (n < 3) {
    status_ = fmt("only %zu images in %.2f s", n, span_s);
    return std::nullopt;
  }
  // The attempt runs on the images from its SfM pair's first image on: those before it share too few tracks
  // with any later image to enter the structure from motion. When the structure cannot be carried through
  // every later image (tracks that end before the newest image), the start moves to a later image.
  std::string structure_failure;
  for (std::size_t start = 0; start + 2 < n;) {
    Attempt at;
    const std::optional<std::size_t> first = choose_sfm_pair(start, span_s, &at);
    if (!first) break;
    std::deque<Frame> trimmed;
    if (*first > 0) trimmed.assign(window_.begin() + static_cast<std::ptrdiff_t>(*first), window_.end());
    at.frames = *first > 0 ? &trimmed : &window_;
    at.span_s = ns_to_s(at.frames->back().t_ns - at.frames->front().t_ns);
    integrate_all(&at);
    if (!measure_excitation(&at)) return std::nullopt;
    if (!relative_pose(&at) || !pose_all_images(&at)) {
      if (structure_failure.empty()) structure_failure = status_;
      start = *first + 1;
      continue;
    }
    if (!estimate_gyro_bias(&at)) return std::nullopt;
    build_align_input(&at);
    return finish(at);
  }
  if (!structure_failure.empty()) status_ = structure_failure + "; no later start of the window did better";
  return std::nullopt;
}

void DynamicInitializer::integrate_all(Attempt* at) const {
  const std::deque<Frame>& win = *at->frames;
  const std::size_t n = win.size();
  at->pre.resize(n);
  for (std::size_t k = 1; k < n; ++k) {
    at->pre[k] = preintegrate(win[k].imu, win[k - 1].t_ns, win[k].t_ns, at->bg);
  }
}

std::optional<std::size_t> DynamicInitializer::choose_sfm_pair(std::size_t start, double span_s,
                                                               Attempt* at) {
  // The SfM pair: the oldest image that shares at least dynamic_init_min_features tracks with a later image
  // at dynamic_init_min_parallax_px of rotation-compensated parallax, and that later image with the largest
  // such parallax. Starting from the oldest image keeps the window as long as the tracks allow; where tracks
  // live shorter than the window (fast motion, small images), the window starts later.
  const std::size_t n = window_.size();
  std::size_t max_common_oldest = 0;
  double best_parallax_oldest = -1.0;
  std::size_t best_common_oldest = 0;
  std::size_t best_oldest = 0;
  for (std::size_t a = start; a + 2 < n; ++a) {
    const FeatureMap& fa = window_[a].features;
    std::size_t best = 0;
    double best_parallax = -1.0;
    std::size_t best_common = 0;
    std::size_t max_common = 0;
    for (std::size_t k = a + 1; k < n; ++k) {
      const FeatureMap& fk = window_[k].features;
      const auto [par, common] = pair_parallax_px(fa, fk, rotation_fit(fa, fk), focal_px_);
      max_common = std::max(max_common, common);
      if (common < static_cast<std::size_t>(config_.dynamic_init_min_features)) continue;
      if (par > best_parallax) {
        best_parallax = par;
        best = k;
        best_common = common;
      }
    }
    if (a == start) {
      max_common_oldest = max_common;
      best_parallax_oldest = best_parallax;
      best_common_oldest = best_common;
      best_oldest = best;
    }
    if (best != 0 && best_parallax >= config_.dynamic_init_min_parallax_px) {
      at->best = best - a;
      return a;
    }
  }
  if (best_oldest == 0) {
    status_ = fmt(
        "features: at most %zu seen in image %zu and another of the window < %d (no later image of the "
        "window has both with another at %.1f px of parallax)",
        max_common_oldest, start, config_.dynamic_init_min_features, config_.dynamic_init_min_parallax_px);
  } else {
    status_ =
        fmt("parallax %.1f px < %.1f px (rotation-compensated, %zu features, images %zu-%zu over %.2f s; no "
            "later "
            "image of the window does better)",
            best_parallax_oldest, config_.dynamic_init_min_parallax_px, best_common_oldest, start,
            best_oldest, span_s);
  }
  return std::nullopt;
}

bool DynamicInitializer::measure_excitation(Attempt* at) {
  const std::deque<Frame>& win = *at->frames;
  // IMU excitation: the accelerometer's variation over the window.
  const std::size_t n = win.size();
  Eigen::Vector3d acc_mean = Eigen::Vector3d::Zero();
  std::size_t acc_count = 0;
  for (std::size_t k = 1; k < n; ++k) {
    for (const ImuSample& s : win[k].imu) {
      acc_mean += s.accel_mps2;
      ++acc_count;
    }
  }
  acc_mean /= static_cast<double>(std::max<std::size_t>(acc_count, 1));
  double acc_var = 0.0;
  for (std::size_t k = 1; k < n; ++k) {
    for (const ImuSample& s : win[k].imu) acc_var += (s.accel_mps2 - acc_mean).squaredNorm();
  }
  at->acc_std = std::sqrt(acc_var / static_cast<double>(std::max<std::size_t>(acc_count, 1)));
  if (at->acc_std < config_.dynamic_init_min_accel_std_mps2) {
    status_ = fmt("IMU excitation: accelerometer std %.3f m/s^2 < %.3f m/s^2 over %.2f s", at->acc_std,
                  config_.dynamic_init_min_accel_std_mps2, at->span_s);
    return false;
  }
  return true;
}

bool DynamicInitializer::relative_pose(Attempt* at) {
  const std::deque<Frame>& win = *at->frames;
  // Essential matrix and relative pose of the pair, then its inliers triangulated.
  const std::size_t n = win.size();
  const std::size_t best = at->best;
  const double focal = focal_px_;
  const FeatureMap& f0 = win.front().features;
  const FeatureMap& fb = win[best].features;
  std::vector<std::uint64_t> pair_ids;
  std::vector<cv::Point2d> pts0;
  std::vector<cv::Point2d> pts1;
  for (const auto& [id, x0] : f0) {
    const auto it = fb.find(id);
    if (it == fb.end()) continue;
    pair_ids.push_back(id);
    pts0.emplace_back(x0.x(), x0.y());
    pts1.emplace_back(it->second.x(), it->second.y());
  }
  const double thr = config_.ransac_threshold_px / focal;
  cv::Mat inlier_mask;
  const cv::Mat E =
      cv::findEssentialMat(pts0, pts1, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.999, thr, 1000, inlier_mask);
  if (E.rows != 3 || E.cols != 3) {
    status_ = fmt("essential matrix: no solution between images 0 and %zu (%zu features)", best, pts0.size());
    return false;
  }
  cv::Mat R_cv;
  cv::Mat t_cv;
  const int good = cv::recoverPose(E, pts0, pts1, cv::Mat::eye(3, 3, CV_64F), R_cv, t_cv, inlier_mask);
  if (good < config_.dynamic_init_min_features / 2) {
    status_ = fmt("relative pose: %d inliers in front of both cameras < %d (images 0-%zu)", good,
                  config_.dynamic_init_min_features / 2, best);
    return false;
  }
  Eigen::Matrix3d R_1_0;
  Eigen::Vector3d t_1_0;
  cv::cv2eigen(R_cv, R_1_0);
  cv::cv2eigen(t_cv, t_1_0);
  at->vision_parallax = pair_parallax_px(f0, fb, R_1_0, focal).first;
  if (at->vision_parallax < config_.dynamic_init_min_parallax_px) {
    status_ = fmt("parallax %.1f px < %.1f px (vision-compensated, images 0-%zu over %.2f s)",
                  at->vision_parallax, config_.dynamic_init_min_parallax_px, best, at->span_s);
    return false;
  }
  at->max_reproj = 3.0 * config_.ransac_threshold_px / focal + 2.0 / focal;
  at->T_ck_c0.assign(n, Eigen::Isometry3d::Identity());
  Eigen::Isometry3d T1 = Eigen::Isometry3d::Identity();
  T1.linear() = R_1_0;
  T1.translation() = t_1_0;
  at->T_ck_c0[best] = T1;
  at->points.clear();
  for (std::size_t i = 0; i < pair_ids.size(); ++i) {
    if (inlier_mask.at<unsigned char>(static_cast<int>(i)) == 0) continue;
    Eigen::Vector3d p;
    if (triangulate({at->T_ck_c0[0], T1}, {f0.at(pair_ids[i]), fb.at(pair_ids[i])}, at->max_reproj, &p)) {
      at->points[pair_ids[i]] = p;
    }
  }
  return true;
}

void DynamicInitializer::triangulate_new(std::size_t k, Attempt* at) const {
  const std::deque<Frame>& win = *at->frames;
  // Tracks of image k not triangulated yet, from their observations in the (posed) images before k.
  for (const auto& [id, x] : win[k].features) {
    if (at->points.contains(id)) continue;
    std::vector<Eigen::Isometry3d> poses;
    std::vector<Eigen::Vector2d> xy;
    for (std::size_t j = 0; j < k; ++j) {
      const auto it = win[j].features.find(id);
      if (it == win[j].features.end()) continue;
      poses.push_back(at->T_ck_c0[j]);
      xy.push_back(it->second);
    }
    if (xy.size() < 3) continue;
    // At least 1 degree between the first and the last ray (in c0): a point triangulated from less is
    // mostly noise in depth.
    const Eigen::Vector3d r0 = poses.front().linear().transpose() * xy.front().homogeneous();
    const Eigen::Vector3d r1 = poses.back().linear().transpose() * xy.back().homogeneous();
    if (r0.normalized().cross(r1.normalized()).norm() < 0.017) continue;
    Eigen::Vector3d p;
    if (triangulate(poses, xy, at->max_reproj, &p)) at->points[id] = p;
  }
}

bool DynamicInitializer::pose_all_images(Attempt* at) {
  const std::deque<Frame>& win = *at->frames;
  // PnP of the other images outwards from the pair, each starting from its neighbour's pose.
  const std::size_t n = win.size();
  for (std::size_t k = 1; k < n; ++k) {
    if (k == at->best) continue;
    if (k > at->best) triangulate_new(k, at);
    if (!pnp(win[k].features, at->points, at->max_reproj, at->T_ck_c0[k - 1], &at->T_ck_c0[k])) {
      status_ = fmt("PnP failed for image %zu of %zu (%zu triangulated points; pair 0-%zu)", k, n,
                    at->points.size(), at->best);
      return false;
    }
  }
  // Refinement by alternation (resection-intersection, a poor man's bundle adjustment): every track seen at
  // least three times, then every pose but the first (the gauge), a few times.
  for (int pass = 0; pass < 5; ++pass) {
    std::unordered_map<std::uint64_t, std::pair<std::vector<Eigen::Isometry3d>, std::vector<Eigen::Vector2d>>>
        tracks;
    for (std::size_t k = 0; k < n; ++k) {
      for (const auto& [id, x] : win[k].features) {
        tracks[id].first.push_back(at->T_ck_c0[k]);
        tracks[id].second.push_back(x);
      }
    }
    at->points.clear();
    for (const auto& [id, obs] : tracks) {
      if (obs.second.size() < 3) continue;
      Eigen::Vector3d p;
      if (triangulate(obs.first, obs.second, 2.0 * at->max_reproj, &p)) at->points[id] = p;
    }
    for (std::size_t k = 1; k < n; ++k) {
      if (!pnp(win[k].features, at->points, at->max_reproj, at->T_ck_c0[k], &at->T_ck_c0[k])) {
        status_ = fmt("PnP (refinement) failed for image %zu of %zu (%zu points)", k, n, at->points.size());
        return false;
      }
    }
  }
  return true;
}

bool DynamicInitializer::estimate_gyro_bias(Attempt* at) {
  const std::deque<Frame>& win = *at->frames;
  const std::size_t n = win.size();
  const Eigen::Matrix3d R_b_c = T_i_c_.linear();
  // Up-to-scale unit: the translation between the first and the last camera.
  at->R_c0_bk.resize(n);
  at->p_c0_ck.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Isometry3d T_c0_ck = at->T_ck_c0[k].inverse();
    at->R_c0_bk[k] = T_c0_ck.linear() * R_b_c.transpose();
    at->p_c0_ck[k] = T_c0_ck.translation();
  }
  at->unit = (at->p_c0_ck[n - 1] - at->p_c0_ck[0]).norm();
  if (at->unit < 1e-9) {
    status_ = "structure: no translation between the first and last images";
    return false;
  }
  for (Eigen::Vector3d& p : at->p_c0_ck) p /= at->unit;
  // Gyro bias: rotations of vision against the pre-integrated gyro.
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  Eigen::Vector3d g_vec = Eigen::Vector3d::Zero();
  for (std::size_t k = 1; k < n; ++k) {
    const Eigen::Matrix3d R_vis = at->R_c0_bk[k - 1].transpose() * at->R_c0_bk[k];
    const Eigen::Vector3d r = so3_log(at->pre[k].dR.transpose() * R_vis);
    H += at->pre[k].J_R_bg.transpose() * at->pre[k].J_R_bg;
    g_vec += at->pre[k].J_R_bg.transpose() * r;
  }
  const Eigen::LDLT<Eigen::Matrix3d> H_ldlt(H);
  at->bg = H_ldlt.solve(g_vec);
  if (!at->bg.allFinite()) {
    status_ = "gyro bias: singular system";
    return false;
  }
  integrate_all(at);
  return true;
}

void DynamicInitializer::build_align_input(Attempt* at) const {
  const std::deque<Frame>& win = *at->frames;
  // Alignment with the gyro's rotations: velocity, gravity and accelerometer bias in b0.
  const std::size_t n = win.size();
  AlignInput& in = at->in;
  in.R_b_c = T_i_c_.linear();
  in.p_b_c = T_i_c_.translation();
  in.R_b0_bk.assign(n, Eigen::Matrix3d::Identity());
  in.T_s.assign(n, 0.0);
  in.alpha.assign(n, Eigen::Vector3d::Zero());
  in.J_alpha_ba.assign(n, Eigen::Matrix3d::Zero());
  in.J_R_bg.assign(n, Eigen::Matrix3d::Zero());
  at->beta.assign(n, Eigen::Vector3d::Zero());
  at->J_beta_ba.assign(n, Eigen::Matrix3d::Zero());
  for (std::size_t k = 1; k < n; ++k) {
    const Preintegrated& p = at->pre[k];
    const Eigen::Matrix3d& R = in.R_b0_bk[k - 1];
    in.T_s[k] = in.T_s[k - 1] + p.dt_s;
    in.alpha[k] = in.alpha[k - 1] + at->beta[k - 1] * p.dt_s + R * p.dp;
    in.J_alpha_ba[k] = in.J_alpha_ba[k - 1] + at->J_beta_ba[k - 1] * p.dt_s + R * p.J_p_ba;
    at->beta[k] = at->beta[k - 1] + R * p.dv;
    at->J_beta_ba[k] = at->J_beta_ba[k - 1] + R * p.J_v_ba;
    in.J_R_bg[k] = p.dR.transpose() * in.J_R_bg[k - 1] + p.J_R_bg;
    in.R_b0_bk[k] = R * p.dR;
  }
  in.sfm_c0_ck = at->p_c0_ck;
  for (const auto& [id, point] : at->points) {
    std::vector<std::pair<std::size_t, Eigen::Vector2d>> obs;
    for (std::size_t k = 0; k < n; ++k) {
      const auto it = win[k].features.find(id);
      if (it != win[k].features.end()) obs.emplace_back(k, it->second);
    }
    if (obs.size() < 3) continue;
    in.tracks.push_back(std::move(obs));
    in.sfm_points_c0.push_back(point / at->unit);
  }
  in.sigma_xy = config_.pixel_sigma_px / focal_px_;
  in.sigma_ba_mps2 = config_.init_sigma_accel_bias_mps2;
  in.sigma_bg_radps = config_.init_sigma_gyro_bias_radps;
  in.gravity_mps2 = config_.gravity_mps2;
  in.outlier_xy = config_.triangulation_max_reproj_sigma * config_.pixel_sigma_px / focal_px_;
  in.accel_noise_density = noise_.accel_noise_density;
  in.gyro_noise_density = noise_.gyro_noise_density;
  in.accel_random_walk = noise_.accel_random_walk;
}

std::optional<InitialState> DynamicInitializer::finish(const Attempt& at) {
  const std::deque<Frame>& win = *at.frames;
  const std::size_t n = win.size();
  const AlignInput& in = at.in;
  const double focal = focal_px_;
  std::string why;
  const std::optional<AlignOutput> al = align_known_rotations(in, &why);
  if (!al) {
    status_ = why;
    return std::nullopt;
  }
  const double G = config_.gravity_mps2;
  if (!(std::abs(al->g_norm_free - G) <= config_.dynamic_init_max_gravity_error_mps2)) {
    status_ = fmt("gravity norm %.3f vs %.3f m/s^2 (tolerance %.2f; %zu tracks, reprojection RMS %.2f px)",
                  al->g_norm_free, G, config_.dynamic_init_max_gravity_error_mps2, al->tracks_used,
                  al->rms_xy * focal);
    return std::nullopt;
  }
  const double rms_px = al->rms_xy * focal;
  if (!(rms_px <= config_.triangulation_max_reproj_sigma * config_.pixel_sigma_px)) {
    status_ = fmt("alignment reprojection RMS %.2f px > %.2f px", rms_px,
                  config_.triangulation_max_reproj_sigma * config_.pixel_sigma_px);
    return std::nullopt;
  }
  const Eigen::Vector3d g = al->x.segment<3>(3);
  const Eigen::Vector3d ba = al->x.segment<3>(6);
  const Eigen::Vector3d dbg = al->x.segment<3>(9);
  const Eigen::Vector3d bg_refined = at.bg + dbg;
  const Eigen::Matrix3d R_n = in.R_b0_bk[n - 1] * so3_exp(in.J_R_bg[n - 1] * dbg);
  const double T_n = in.T_s[n - 1];
  const Eigen::Vector3d v_n = al->x.segment<3>(0) + g * T_n + at.beta[n - 1] + at.J_beta_ba[n - 1] * ba;
  Eigen::Matrix<double, 3, 9> J_vn;
  J_vn << Eigen::Matrix3d::Identity(), T_n * Eigen::Matrix3d::Identity(), at.J_beta_ba[n - 1];
  const Eigen::Matrix3d vel_cov_b0 = J_vn * al->cov.topLeftCorner<9, 9>() * J_vn.transpose();
  // The pixel noise's velocity sigma (scaled by the residuals) decides; the one with the pre-integration's
  // errors added is only reported: deciding on it refused right starts, no wrong one (docs/ekf.md).
  const double speed_sigma = std::sqrt(std::max(0.0, vel_cov_b0.trace()));
  const double speed_sigma_imu =
      std::sqrt(std::max(0.0, (J_vn * al->cov_imu.topLeftCorner<9, 9>() * J_vn.transpose()).trace()));
  const double speed_limit =
      config_.dynamic_init_max_speed_sigma_ratio * v_n.norm() + config_.dynamic_init_min_sigma_vel_mps;
  if (!(speed_sigma <= speed_limit)) {
    status_ =
        fmt("velocity sigma %.3f m/s > %.3f m/s (speed %.2f m/s; %.3f m/s with the IMU's pre-integration "
            "errors): too little excitation to fix the scale",
            speed_sigma, speed_limit, v_n.norm(), speed_sigma_imu);
    return std::nullopt;
  }
  const Eigen::Vector3d& p_b_c = in.p_b_c;
  const double translation_m = ((al->p_b0_bk[n - 1] + R_n * p_b_c) - (al->p_b0_bk[0] + p_b_c)).norm();
  if (translation_m < config_.dynamic_init_min_translation_m) {
    status_ = fmt("translation %.3f m < %.3f m over %.2f s", translation_m,
                  config_.dynamic_init_min_translation_m, at.span_s);
    return std::nullopt;
  }

  // The state at the last image, in a world frame with +z up and the IMU's yaw zero.
  const Eigen::Matrix3d R_w_b0 =
      Eigen::Quaterniond::FromTwoVectors(g.normalized(), -Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Matrix3d R_w_bn = R_w_b0 * R_n;
  const double yaw = std::atan2(R_w_bn(1, 0), R_w_bn(0, 0));
  const Eigen::Matrix3d R_w =
      Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R_w_b0;  // b0 -> world

  InitialState out;
  out.method = InitMethod::kDynamic;
  out.state.t_ns = win.back().t_ns;
  out.state.q_w_i = Eigen::Quaterniond(R_w * R_n).normalized();
  out.state.p_w_m.setZero();
  out.state.v_w_mps = R_w * v_n;
  out.state.gyro_bias_radps = bg_refined;
  out.state.accel_bias_mps2 = ba;
  if (!win.back().imu.empty()) out.state.omega_i_radps = win.back().imu.back().gyro_radps - bg_refined;
  // Covariances: those of the least squares (scaled by their residuals), floored by the config.
  const double sigma_tilt = std::max(config_.dynamic_init_min_sigma_tilt_rad,
                                     std::sqrt(std::max(al->cov.block<3, 3>(3, 3).trace() / 2.0, 0.0)) / G);
  out.rot_cov_world = Eigen::Vector3d(sigma_tilt * sigma_tilt, sigma_tilt * sigma_tilt,
                                      config_.init_sigma_yaw_rad * config_.init_sigma_yaw_rad)
                          .asDiagonal();
  const double min_v2 = config_.dynamic_init_min_sigma_vel_mps * config_.dynamic_init_min_sigma_vel_mps;
  out.vel_cov_m2ps2 = R_w * vel_cov_b0 * R_w.transpose() + Eigen::Matrix3d::Identity() * min_v2;
  const double min_bg2 =
      config_.dynamic_init_min_sigma_gyro_bias_radps * config_.dynamic_init_min_sigma_gyro_bias_radps;
  out.gyro_bias_cov = al->cov.block<3, 3>(9, 9) + Eigen::Matrix3d::Identity() * min_bg2;
  out.joint_cov = joint_start_covariance(*al, in, R_w, R_n, v_n, J_vn, config_);
  out.scale = translation_m;
  out.window_s = at.span_s;
  out.detail =
      fmt("dynamic: %zu images over %.2f s, SfM pair 0-%zu parallax %.1f px, %zu tracks (%zu dropped), "
          "translation %.2f m, speed %.2f +- %.3f m/s (%.3f with the IMU's pre-integration errors), |g| %.3f "
          "before the norm constraint, reprojection RMS %.2f px, gyro bias (%.4f %.4f %.4f) rad/s, accel "
          "bias (%.3f %.3f %.3f) m/s^2, accel std %.2f m/s^2",
          n, at.span_s, at.best, at.vision_parallax, al->tracks_used, al->tracks_dropped, translation_m,
          v_n.norm(), speed_sigma, speed_sigma_imu, al->g_norm_free, rms_px, bg_refined.x(), bg_refined.y(),
          bg_refined.z(), ba.x(), ba.y(), ba.z(), at.acc_std);
  status_ = out.detail;
  return out;
}

}  // namespace loopgate
