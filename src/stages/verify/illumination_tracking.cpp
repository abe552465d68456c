// The verifier's fallback across a change of illumination (geometric_verifier.hpp): j's triangulated points
// tracked into i on locally normalised images, started where the odometry's relative pose puts them, and
// the pose of i from them, confirmed from j's neighbour and by the odometry check.
#include <spdlog/fmt/fmt.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/klt.hpp"
#include "stages/verify/geometric_verifier.hpp"

namespace loopgate {

namespace {

// How well a PnP pose's position is determined by its inliers, in metres (the largest standard deviation
// of the camera position): Gauss-Newton information of the 6-DoF pose from each point's projection, whose
// noise is sigma_x (normalised image units) plus the point's own depth uncertainty from its triangulation
// (sigma_Z = Z^2 sigma_x / b, b the baseline across the ray from camera j to its neighbour's centre `c_n`).
// Points far away with a short baseline leave the position along the view free: a pose they "verify" can be
// metres off however many of them agree.
double pnp_position_sigma_m(const std::vector<Eigen::Vector3d>& p_cj, const Eigen::Isometry3d& T_ci_cj,
                            const Eigen::Vector3d& c_n, double sigma_x) {
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  for (std::size_t k = 0; k < p_cj.size(); ++k) {
    const Eigen::Vector3d& X = p_cj[k];
    const double Z = X.norm();
    const Eigen::Vector3d d = X / Z;
    const double b = (c_n - c_n.dot(d) * d).norm();
    const double sigma_Z = Z * Z * sigma_x / std::max(b, 1e-6);
    const Eigen::Vector3d P = T_ci_cj * X;
    if (!(P.z() > 1e-6)) continue;
    Eigen::Matrix<double, 2, 3> J_proj;
    J_proj << 1.0 / P.z(), 0.0, -P.x() / (P.z() * P.z()), 0.0, 1.0 / P.z(), -P.y() / (P.z() * P.z());
    const Eigen::Vector2d J_depth = J_proj * (T_ci_cj.linear() * d);
    const Eigen::Matrix2d C =
        sigma_x * sigma_x * Eigen::Matrix2d::Identity() + sigma_Z * sigma_Z * J_depth * J_depth.transpose();
    Eigen::Matrix<double, 3, 6> dP;
    dP.leftCols<3>().setIdentity();
    dP.rightCols<3>() << 0.0, P.z(), -P.y(), -P.z(), 0.0, P.x(), P.y(), -P.x(), 0.0;  // -[P]x
    const Eigen::Matrix<double, 2, 6> J = J_proj * dP;
    H += J.transpose() * C.inverse() * J;
  }
  const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(H);
  if (lu.rank() < 6) return std::numeric_limits<double>::infinity();  // some direction not observed at all
  const Eigen::Matrix3d cov_position = lu.inverse().topLeftCorner<3, 3>();
  const double largest =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov_position).eigenvalues().maxCoeff();
  return std::isfinite(largest) && largest > 0.0 ? std::sqrt(largest)
                                                 : std::numeric_limits<double>::infinity();
}

}  // namespace

double noise_sigma(const cv::Mat& grey) {
  if (grey.empty() || grey.rows < 3 || grey.cols < 3) return 0.0;
  // Immerkaer: the image convolved with the difference of two Laplacians has no response to smooth
  // structure; the mean absolute response of white noise of sigma s is s sqrt(2 / pi) x 6.
  const cv::Mat kernel = (cv::Mat_<float>(3, 3) << 1, -2, 1, -2, 4, -2, 1, -2, 1);
  cv::Mat response;
  cv::filter2D(grey, response, CV_32F, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_REPLICATE);
  const cv::Mat inner = response(cv::Rect(1, 1, grey.cols - 2, grey.rows - 2));
  const double sum = cv::norm(inner, cv::NORM_L1);
  constexpr double kSqrtHalfPi = 1.2533141373155003;
  return kSqrtHalfPi * sum / (6.0 * static_cast<double>(inner.total()));
}

cv::Mat normalise_illumination(const cv::Mat& grey, double sigma_px, double noise_target, double noise) {
  cv::Mat f;
  grey.convertTo(f, CV_32F);
  // A Gaussian of sigma b divides white noise by 2 sqrt(pi) b; at least half a pixel against aliasing.
  constexpr double kTwoSqrtPi = 3.5449077018110318;
  if (noise < 0.0) noise = noise_sigma(grey);
  const double blur_px = noise_target > 0.0 ? std::max(0.5, noise / (kTwoSqrtPi * noise_target)) : 0.5;
  cv::GaussianBlur(f, f, cv::Size(0, 0), blur_px);
  // Local mean and variance under a Gaussian of sigma_px, as three box filters of side 2 round(sigma) + 1
  // (running sums: the cost does not grow with the window; the variance of three boxes of side w is
  // w^2 / 4, so the sigma is w / 2).
  const int side = 2 * static_cast<int>(std::lround(sigma_px)) + 1;
  const auto smooth = [side](const cv::Mat& in) {
    cv::Mat a;
    cv::Mat b;
    const cv::Size box(side, side);
    cv::boxFilter(in, a, CV_32F, box, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
    cv::boxFilter(a, b, CV_32F, box, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
    cv::boxFilter(b, a, CV_32F, box, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
    return a;
  };
  const cv::Mat deviation = f - smooth(f);
  const cv::Mat variance = smooth(deviation.mul(deviation));
  // A floor of one grey level: flat regions stay flat instead of amplifying quantisation.
  cv::Mat sd;
  cv::sqrt(variance + 1.0, sd);
  cv::Mat out;
  cv::Mat(deviation / sd).convertTo(out, CV_8U, 32.0, 128.0);
  return out;
}

VerifyResult GeometricVerifier::track_fallback(
    const OrbFeatures& fi, const OrbFeatures& fj, const OrbFeatures& fn, const Eigen::Isometry3d& T_w_cj,
    const Eigen::Isometry3d& T_cn_cj, const std::vector<Eigen::Vector3d>& p_cj,
    const std::vector<int>& point_rows, const std::vector<int>& jn, const Eigen::Isometry3d* T_w_bi,
    double threshold, const std::function<bool(VerifyResult&)>& vetoed, VerifyResult result) const {
  if (config_.track_pyramid_levels == 0 || fi.image.empty() || fj.image.empty() ||
      point_rows.size() < static_cast<std::size_t>(config_.min_inliers))
    return result;
  // Only across a change of illumination: a sensor's noise grows as the square root of its gain, so a noise
  // ratio of 2 is a gain (exposure) ratio of 4 or more. Between two images lit alike ORB's rejection stands.
  const double noise_i = noise_sigma(fi.image);
  const double noise_j = noise_sigma(fj.image);
  const double noise_ratio = std::max(noise_i, noise_j) / std::max(1e-9, std::min(noise_i, noise_j));
  if (!(noise_ratio >= config_.track_min_noise_ratio)) return result;

  // ORB did not verify it: track j's triangulated points into i across the illumination change, from j and
  // again from its neighbour n (the same points, seen from n). The three images are smoothed to the noise of
  // the cleanest, but not below one grey level (the 8-bit step): a night image's photon noise would otherwise
  // be normalised into texture.
  const double noise_n = noise_sigma(fn.image);
  const double cleanest = std::max(1.0, std::min({noise_i, noise_j, noise_n}));
  TrackSources sources;
  sources.pyramid_i = normalised_pyramid(fi.image, noise_i, cleanest);
  sources.pyramid_j = normalised_pyramid(fj.image, noise_j, cleanest);
  sources.pyramid_n = normalised_pyramid(fn.image, noise_n, cleanest);
  sources.T_w_cj = T_w_cj;
  sources.T_cn_cj = T_cn_cj;
  for (const int row : point_rows) {
    const auto a = static_cast<std::size_t>(row);
    sources.from_j.push_back(fj.keypoints[a].pt);
    sources.from_n.push_back(fn.keypoints[static_cast<std::size_t>(jn[a])].pt);
    sources.points_j.push_back(p_cj[a]);
    sources.points_n.push_back(T_cn_cj * p_cj[a]);
  }
  // Three starts for the tracking, each tried only when the one before does not verify the loop: where the
  // odometry's pose of i puts j's triangulated points; where the odometry's rotation alone moves them (i
  // placed at j); where they are in j. The first follows the parallax of the revisit's offset (a near facade
  // moves tens of pixels for a metre sideways, more than the tracking's reach on a noisy night image), but
  // carries the odometry's position drift from j to i; the second carries only its heading drift, a few
  // degrees after a long loop (tens of pixels); the third none: the place descriptor matched i to j because i
  // sees the place much as j did.
  struct Start {
    std::optional<Eigen::Isometry3d> T_w_bi;
    const char* label;  // before its note when it fails
    const char* after;  // after the reason when it verifies, behind the failed starts' notes
  };
  std::vector<Start> starts;
  if (T_w_bi != nullptr) {
    const Eigen::Isometry3d& T_b_c = camera_->calibration().T_b_c;
    Eigen::Isometry3d T_w_ci_at_j = *T_w_bi * T_b_c;
    T_w_ci_at_j.translation() = T_w_cj.translation();
    starts.push_back({*T_w_bi, "; tracked: ", ""});
    starts.push_back({T_w_ci_at_j * T_b_c.inverse(),
                      "; tracked from the odometry's rotation: ", "; from the odometry's rotation, after"});
  }
  starts.push_back({std::nullopt, starts.empty() ? "; tracked: " : "; tracked from the images' rotation: ",
                    "; from the images' rotation, after"});
  std::string notes;
  for (const Start& start : starts) {
    std::string note;
    VerifyResult tracked =
        track_from_j_and_n(sources, start.T_w_bi ? &*start.T_w_bi : nullptr, threshold, vetoed, note);
    if (tracked.verified) {
      tracked.points = result.points;
      if (!notes.empty()) tracked.reason += start.after + notes;
      return tracked;
    }
    notes += start.label + note;
  }
  result.key = VerifyReason::kIllumination;  // the tracking ran and did not verify it
  result.reason += notes;
  return result;
}

VerifyResult GeometricVerifier::track_from_j_and_n(const TrackSources& s, const Eigen::Isometry3d* T_w_bi,
                                                   double threshold,
                                                   const std::function<bool(VerifyResult&)>& vetoed,
                                                   std::string& note) const {
  const Eigen::Isometry3d& T_b_c = camera_->calibration().T_b_c;
  const Eigen::Isometry3d T_w_cn = s.T_w_cj * s.T_cn_cj.inverse();
  const Eigen::Vector3d centre_n_in_j = s.T_cn_cj.inverse().translation();
  const TrackedPose by_j = track_into_i(s.pyramid_j, s.pyramid_i, s.from_j, s.points_j, s.T_w_cj,
                                        centre_n_in_j, T_w_bi, threshold);
  if (!by_j.result.verified) {
    note = by_j.note;
    return by_j.result;
  }
  const TrackedPose by_n = track_into_i(s.pyramid_n, s.pyramid_i, s.from_n, s.points_n, T_w_cn,
                                        s.T_cn_cj.translation(), T_w_bi, threshold);
  // A street's repeated facades can lure the tracking to the look-alike at the starting point, so that i
  // appears to stand where the tracking started: from j at j, from n at n. Tracked right, the two agree
  // on where i is; they may differ by 3 sigma of the difference of two edges (3 sqrt(2) sigma_position_m).
  VerifyResult tracked = by_j.result;
  const double max_apart_m = 3.0 * std::sqrt(2.0) * config_.sigma_position_m;
  if (!by_n.result.verified) {
    tracked.verified = false;
    note = by_j.note + "; not from j's neighbour: " + by_n.note;
    return tracked;
  }
  const Eigen::Isometry3d T_bj_bn = T_b_c * s.T_cn_cj.inverse() * T_b_c.inverse();
  const double apart_m = (tracked.T_j_i.translation() - (T_bj_bn * by_n.result.T_j_i).translation()).norm();
  if (!(apart_m <= max_apart_m)) {
    tracked.verified = false;
    note = fmt::format("{}; from j and from its neighbour i is {:.2f} m apart > {:.2f} m", by_j.note, apart_m,
                       max_apart_m);
    return tracked;
  }
  if (vetoed(tracked)) {
    note = fmt::format("{}, {}", by_j.note, tracked.reason);
    return tracked;
  }
  tracked.tracked = true;
  tracked.key = VerifyReason::kVerifiedByTracking;
  tracked.reason =
      fmt::format("verified by tracking ({}; from j's neighbour {:.2f} m apart)", by_j.note, apart_m);
  return tracked;
}

GeometricVerifier::TrackedPose GeometricVerifier::track_into_i(
    const Pyramid& pyramid_src, const Pyramid& pyramid_i, std::vector<cv::Point2f> uv_src,
    const std::vector<Eigen::Vector3d>& p_csrc, const Eigen::Isometry3d& T_w_csrc,
    const Eigen::Vector3d& c_other, const Eigen::Isometry3d* T_w_bi, double threshold) const {
  const CameraModel& camera = *camera_;
  const Eigen::Isometry3d& T_b_c = camera.calibration().T_b_c;
  // Start where the odometry's pose of i puts each point (its triangulated position seen from i), else where
  // it is in the source image.
  std::vector<cv::Point2f> start_i = uv_src;
  if (T_w_bi != nullptr) {
    const Eigen::Isometry3d T_ci_csrc = (*T_w_bi * T_b_c).inverse() * T_w_csrc;
    for (std::size_t k = 0; k < uv_src.size(); ++k) {
      const Eigen::Vector3d P = T_ci_csrc * p_csrc[k];
      Eigen::Vector2d uv;
      if (P.z() > 0.0 && camera.project(P, &uv) && uv.allFinite())
        start_i[k] = cv::Point2f(static_cast<float>(uv.x()), static_cast<float>(uv.y()));
    }
  }
  const std::vector<unsigned char> found = track_across_illumination(pyramid_src, pyramid_i, start_i, uv_src);
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (std::size_t r = 0; r < uv_src.size(); ++r) {
    if (found[r] == 0) continue;
    const Eigen::Vector2d x_i = camera.undistort_normalized(Eigen::Vector2d(uv_src[r].x, uv_src[r].y));
    object.emplace_back(p_csrc[r].x(), p_csrc[r].y(), p_csrc[r].z());
    image.emplace_back(x_i.x(), x_i.y());
  }
  TrackedPose out;
  VerifyResult& r = out.result;
  r.matches = static_cast<int>(object.size());
  if (r.matches >= config_.min_inliers) solve_pose(object, image, threshold, T_b_c, r);
  out.note = fmt::format("{} of {} points, {} inliers", r.matches, uv_src.size(), r.inliers);
  if (!r.verified) return out;
  // Tracking keeps far points where near ones change too much (a revisit metres along the road): the
  // inliers must pin the position down to the edge's own sigma.
  const Eigen::Isometry3d T_ci_csrc = T_b_c.inverse() * r.T_j_i.inverse() * T_b_c;
  std::vector<Eigen::Vector3d> inliers;
  for (std::size_t k = 0; k < object.size(); ++k) {
    const Eigen::Vector3d X(object[k].x, object[k].y, object[k].z);
    const Eigen::Vector3d P = T_ci_csrc * X;
    if (P.z() > 0.0 && (P.head<2>() / P.z() - Eigen::Vector2d(image[k].x, image[k].y)).norm() <= threshold)
      inliers.push_back(X);
  }
  const double sigma_m = pnp_position_sigma_m(inliers, T_ci_csrc, c_other, 0.5 * threshold);
  out.note += fmt::format(", position sigma {:.2f} m", sigma_m);
  if (!(sigma_m <= config_.sigma_position_m)) {
    r.verified = false;
    out.note += fmt::format(" > {} m", config_.sigma_position_m);
    return out;
  }
  // The model's covariance shrinks with the inlier count, but tracked points can be many and still leave the
  // position loose (far points, a short baseline from j to its neighbour): the edge is taken no more certain
  // than its inliers' geometry makes it, the model's covariance scaled up to that position sigma.
  const double model_sigma_m = std::sqrt(r.cov(0, 0));
  if (model_sigma_m > 0.0 && sigma_m > model_sigma_m)
    r.cov *= (sigma_m * sigma_m) / (model_sigma_m * model_sigma_m);
  return out;
}

GeometricVerifier::Pyramid GeometricVerifier::normalised_pyramid(const cv::Mat& grey, double noise,
                                                                 double noise_target) const {
  Pyramid pyramid;
  const cv::Size window(config_.track_window_px, config_.track_window_px);
  build_klt_pyramid(normalise_illumination(grey, config_.track_norm_sigma_px, noise_target, noise), window,
                    config_.track_pyramid_levels, pyramid);
  return pyramid;
}

std::vector<unsigned char> GeometricVerifier::track_across_illumination(
    const Pyramid& pyramid_j, const Pyramid& pyramid_i, const std::vector<cv::Point2f>& start_i,
    std::vector<cv::Point2f>& points) const {
  std::vector<unsigned char> found(points.size(), 0);
  if (points.empty() || pyramid_j.empty() || pyramid_i.empty()) return found;
  const cv::Size window(config_.track_window_px, config_.track_window_px);
  const int levels = config_.track_pyramid_levels;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  // Forward from the predicted start; backward from the point's own pixel moved by what the forward track
  // corrected of the prediction (the same model both ways).
  std::vector<cv::Point2f> in_i = start_i;
  std::vector<unsigned char> forward_ok;
  std::vector<unsigned char> backward_ok;
  // cv::calcOpticalFlowPyrLK's tracking with exact integer window sums (core/klt.hpp).
  track_klt(pyramid_j, pyramid_i, points, in_i, forward_ok, window, levels, criteria, true);
  std::vector<cv::Point2f> back(points.size());
  for (std::size_t k = 0; k < points.size(); ++k) back[k] = points[k] - (in_i[k] - start_i[k]);
  track_klt(pyramid_i, pyramid_j, in_i, back, backward_ok, window, levels, criteria, true);
  const float max_x = static_cast<float>(pyramid_i.front().cols - 1);
  const float max_y = static_cast<float>(pyramid_i.front().rows - 1);
  for (std::size_t k = 0; k < points.size(); ++k) {
    const cv::Point2f& p = in_i[k];
    const cv::Point2f d = back[k] - points[k];
    if (forward_ok[k] == 0 || backward_ok[k] == 0 ||
        !(p.x >= 0.0F && p.y >= 0.0F && p.x <= max_x && p.y <= max_y) ||
        !(std::sqrt(d.dot(d)) <= config_.track_fb_max_px))
      continue;
    found[k] = 1;
    points[k] = p;
  }
  return found;
}

}  // namespace loopgate
