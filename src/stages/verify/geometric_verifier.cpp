#include "stages/verify/geometric_verifier.hpp"

#include <spdlog/fmt/fmt.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <stdexcept>
#include <vector>

#include "core/error.hpp"
#include "core/klt.hpp"

namespace loopgate {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Linear triangulation of normalised points x_a (camera a = reference) and x_b with T_b_a; the point in a.
Eigen::Vector3d triangulate(const Eigen::Vector2d& x_a, const Eigen::Vector2d& x_b,
                            const Eigen::Isometry3d& T_b_a) {
  Eigen::Matrix<double, 3, 4> P_a = Eigen::Matrix<double, 3, 4>::Zero();
  P_a.leftCols<3>().setIdentity();
  const Eigen::Matrix<double, 3, 4> P_b = T_b_a.matrix().topRows<3>();
  Eigen::Matrix4d A;
  A.row(0) = x_a.x() * P_a.row(2) - P_a.row(0);
  A.row(1) = x_a.y() * P_a.row(2) - P_a.row(1);
  A.row(2) = x_b.x() * P_b.row(2) - P_b.row(0);
  A.row(3) = x_b.y() * P_b.row(2) - P_b.row(1);
  const Eigen::JacobiSVD<Eigen::Matrix4d> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d X = svd.matrixV().col(3);
  if (std::abs(X.w()) < 1e-12) return Eigen::Vector3d::Constant(std::nan(""));
  return X.head<3>() / X.w();
}

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

// Binary descriptors as rows of 64-bit words (zero-padded), so that a distance is a few popcounts.
std::vector<std::uint64_t> as_words(const cv::Mat& descriptors, std::size_t words) {
  std::vector<std::uint64_t> out(static_cast<std::size_t>(descriptors.rows) * words, 0);
  const auto bytes = static_cast<std::size_t>(descriptors.cols);
  for (int r = 0; r < descriptors.rows; ++r)
    std::memcpy(out.data() + static_cast<std::size_t>(r) * words, descriptors.ptr<std::uint8_t>(r), bytes);
  return out;
}

// For each query row: the train row at the smallest Hamming distance when it passes the ratio test against
// the second smallest (a tie for the smallest fails it), else -1.
[[gnu::always_inline]] inline void ratio_match_body(const std::uint64_t* query, std::size_t queries,
                                                    const std::uint64_t* train, std::size_t trains,
                                                    std::size_t words, double ratio, int* out) {
  for (std::size_t q = 0; q < queries; ++q) {
    const std::uint64_t* a = query + q * words;
    int first = std::numeric_limits<int>::max(), second = first, index = -1;
    for (std::size_t t = 0; t < trains; ++t) {
      const std::uint64_t* b = train + t * words;
      int d = 0;
      for (std::size_t w = 0; w < words; ++w) d += __builtin_popcountll(a[w] ^ b[w]);
      if (d < first) {
        second = first;
        first = d;
        index = static_cast<int>(t);
      } else if (d < second) {
        second = d;
      }
    }
    out[q] = static_cast<double>(first) < ratio * static_cast<double>(second) ? index : -1;
  }
}

// The same compiled for the popcnt instruction, called when the CPU has it (a plain check, not an ifunc:
// ifunc resolvers run before the sanitizers' runtimes start and crash the tsan build).
[[gnu::target("popcnt")]] void ratio_match_popcnt(const std::uint64_t* query, std::size_t queries,
                                                  const std::uint64_t* train, std::size_t trains,
                                                  std::size_t words, double ratio, int* out) {
  ratio_match_body(query, queries, train, trains, words, ratio, out);
}

}  // namespace

std::vector<int> ratio_match_hamming(const cv::Mat& query, const cv::Mat& train, double ratio) {
  std::vector<int> out(static_cast<std::size_t>(query.rows), -1);
  if (query.empty() || train.rows < 2) return out;
  if (query.type() != CV_8U || train.type() != CV_8U || query.cols != train.cols)
    throw std::invalid_argument("ratio_match_hamming: descriptors must be CV_8U rows of the same width");
  const std::size_t words = (static_cast<std::size_t>(query.cols) + 7) / 8;
  const std::vector<std::uint64_t> q = as_words(query, words);
  const std::vector<std::uint64_t> t = as_words(train, words);
  static const bool has_popcnt = __builtin_cpu_supports("popcnt");
  if (has_popcnt) {
    ratio_match_popcnt(q.data(), out.size(), t.data(), static_cast<std::size_t>(train.rows), words, ratio,
                       out.data());
  } else {
    ratio_match_body(q.data(), out.size(), t.data(), static_cast<std::size_t>(train.rows), words, ratio,
                     out.data());
  }
  return out;
}

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

std::string verify_reason_key(const std::string& reason) {
  const auto has = [&reason](const char* text) { return reason.find(text) != std::string::npos; };
  const auto starts = [&reason](const char* text) { return reason.rfind(text, 0) == 0; };
  if (reason == "verified") return "verified";
  if (starts("verified by tracking")) return "verified_by_tracking";
  if (starts("skipped: information gain")) return "small_information_gain";
  if (starts("skipped: near")) return "skip_window";
  if (starts("skipped:") && has("already verified")) return "max_per_query";
  if (has("; tracked:")) return "illumination";  // the tracking fallback ran (an illumination change)
  if (has("no camera calibration")) return "no_calibration";
  if (has("image too small")) return "image_too_small";
  if (has("has no images") || has("image missing")) return "image_missing";
  if (has("no odometry pose")) return "no_odometry_pose";
  if (has("baseline")) return "short_baseline";
  if (has("matches with 3-D points")) return "too_few_features";
  if (has("inliers <")) return "too_few_inliers";
  if (has("PnP")) return "pnp_failed";
  if (has("relative translation")) return "translation_too_large";
  if (has("from the odometry's frame i")) return "odometry_disagreement";
  return "other";
}

void VerifyConfig::validate() const {
  if (features < 50) throw ConfigError("verify.features: must be >= 50");
  if (orb_patch_px < 5) throw ConfigError("verify.orb_patch_px: must be >= 5");
  if (orb_fast_threshold < 1) throw ConfigError("verify.orb_fast_threshold: must be >= 1");
  if (!(std::isfinite(min_information_gain) && min_information_gain >= 0.0 && min_information_gain < 1.0))
    throw ConfigError(
        "verify.min_information_gain: must be a finite number in [0, 1) (0: verify regardless)");
  if (max_per_query < 0) throw ConfigError("verify.max_per_query: must be >= 0 (0: no limit)");
  if (skip_after_verified_frames < 0) throw ConfigError("verify.skip_after_verified_frames: must be >= 0");
  if (skip_after_rejected_frames < 0) throw ConfigError("verify.skip_after_rejected_frames: must be >= 0");
  if (feature_cache_frames < 3) throw ConfigError("verify.feature_cache_frames: must be >= 3");
  if (!(ratio > 0.0 && ratio <= 1.0)) throw ConfigError("verify.ratio: must be in (0, 1]");
  if (min_inliers < 6) throw ConfigError("verify.min_inliers: must be >= 6 (PnP needs 4, RANSAC more)");
  if (!(std::isfinite(reprojection_px) && reprojection_px > 0.0))
    throw ConfigError("verify.reprojection_px: must be a finite number > 0");
  if (neighbour_offset_frames == 0) throw ConfigError("verify.neighbour_offset_frames: must not be 0");
  if (!(std::isfinite(min_baseline_m) && min_baseline_m >= 0.0))
    throw ConfigError("verify.min_baseline_m: must be a finite number >= 0");
  if (!(std::isfinite(min_parallax_deg) && min_parallax_deg >= 0.0 && min_parallax_deg < 90.0))
    throw ConfigError("verify.min_parallax_deg: must be in [0, 90)");
  if (min_image_px < 16) throw ConfigError("verify.min_image_px: must be >= 16");
  if (ransac_iterations < 10) throw ConfigError("verify.ransac_iterations: must be >= 10");
  if (!(std::isfinite(max_translation_m) && max_translation_m > 0.0))
    throw ConfigError("verify.max_translation_m: must be a finite number > 0");
  if (!(std::isfinite(sigma_position_m) && sigma_position_m > 0.0))
    throw ConfigError("verify.sigma_position_m: must be a finite number > 0");
  if (!(std::isfinite(sigma_rotation_rad) && sigma_rotation_rad > 0.0))
    throw ConfigError("verify.sigma_rotation_rad: must be a finite number > 0");
  if (track_pyramid_levels < 0 || track_pyramid_levels > 8)
    throw ConfigError("verify.track_pyramid_levels: must be in [0, 8] (0: no tracking fallback)");
  if (track_window_px < 5 || track_window_px > 101 || track_window_px % 2 == 0)
    throw ConfigError("verify.track_window_px: must be odd, in [5, 101]");
  if (!(std::isfinite(track_norm_sigma_px) && track_norm_sigma_px >= 1.0 && track_norm_sigma_px <= 50.0))
    throw ConfigError("verify.track_norm_sigma_px: must be in [1, 50]");
  if (!(std::isfinite(track_min_noise_ratio) && track_min_noise_ratio >= 1.0))
    throw ConfigError(
        "verify.track_min_noise_ratio: must be a finite number >= 1 (1: after every rejection)");
  if (!(std::isfinite(track_fb_max_px) && track_fb_max_px > 0.0))
    throw ConfigError("verify.track_fb_max_px: must be a finite number > 0");
  if (!(std::isfinite(odometry_chi2) && odometry_chi2 >= 0.0))
    throw ConfigError(
        "verify.odometry_chi2: must be a finite number >= 0 (0: no check against the odometry)");
}

std::string odometry_disagreement(const Eigen::Isometry3d& T_w_bi, const Eigen::Isometry3d& T_w_bj,
                                  const VerifyResult& loop, double sigma_i_m, double sigma_j_m,
                                  double chi2_bound) {
  if (chi2_bound <= 0.0) return {};
  if (!(std::isfinite(sigma_i_m) && sigma_i_m > 0.0 && std::isfinite(sigma_j_m) && sigma_j_m > 0.0))
    return {};
  if (sigma_i_m < sigma_j_m) return {};  // the odometry learnt where it is in between: no bound from j to i
  const double edge_var_m2 = loop.cov.topLeftCorner<3, 3>().diagonal().maxCoeff();
  const double var_m2 = sigma_i_m * sigma_i_m - sigma_j_m * sigma_j_m + std::max(0.0, edge_var_m2);
  if (!(var_m2 > 0.0)) return {};
  const Eigen::Vector3d p_w_i_loop = (T_w_bj * loop.T_j_i).translation();
  const double distance_m = (p_w_i_loop - T_w_bi.translation()).norm();
  const double chi2 = distance_m * distance_m / var_m2;
  if (chi2 <= chi2_bound) return {};
  return fmt::format("geometry: {:.2f} m from the odometry's frame i, {:.1f} sigma > {:.2f}", distance_m,
                     std::sqrt(chi2), std::sqrt(chi2_bound));
}

GeometricVerifier::GeometricVerifier(const VerifyConfig& config,
                                     const std::optional<CameraCalibration>& camera)
    : config_(config) {
  if (camera) camera_.emplace(*camera);
}

std::string GeometricVerifier::unusable_reason(const cv::Size& image_size) const {
  if (!camera_) return "geometry: no camera calibration";
  if (image_size.width < config_.min_image_px || image_size.height < config_.min_image_px) {
    return fmt::format("geometry: image too small for features ({}x{} < {} px)", image_size.width,
                       image_size.height, config_.min_image_px);
  }
  return {};
}

OrbFeatures GeometricVerifier::detect(const cv::Mat& image) const {
  OrbFeatures f;
  f.image_size = image.size();
  f.image = image;
  if (!camera_ || image.empty()) return f;
  const cv::Ptr<cv::ORB> orb =
      cv::ORB::create(config_.features, 1.2f, 8, config_.orb_patch_px, 0, 2, cv::ORB::HARRIS_SCORE,
                      config_.orb_patch_px, config_.orb_fast_threshold);
  orb->detectAndCompute(image, cv::noArray(), f.keypoints, f.descriptors);
  f.xy.reserve(f.keypoints.size());
  for (const cv::KeyPoint& k : f.keypoints)
    f.xy.push_back(camera_->undistort_normalized(Eigen::Vector2d(k.pt.x, k.pt.y)));
  return f;
}

VerifyResult GeometricVerifier::verify(const VerifyFrame& i, const VerifyFrame& j,
                                       const VerifyFrame& n) const {
  VerifyResult result;
  if (i.image.empty() || j.image.empty() || n.image.empty()) {
    result.reason = "geometry: image missing";
    return result;
  }
  if (std::string why = unusable_reason(j.image.size()); !why.empty()) {
    result.reason = why;
    return result;
  }
  return verify(detect(i.image), detect(j.image), j.T_w_b, detect(n.image), n.T_w_b);
}

VerifyResult GeometricVerifier::verify(const OrbFeatures& fi, const OrbFeatures& fj,
                                       const Eigen::Isometry3d& T_w_bj, const OrbFeatures& fn,
                                       const Eigen::Isometry3d& T_w_bn, const Eigen::Matrix3d* R_w_bi,
                                       const Veto& veto) const {
  VerifyResult result;
  if (std::string why = unusable_reason(fj.image_size); !why.empty()) {
    result.reason = why;
    return result;
  }
  const CameraModel& camera = *camera_;
  const Eigen::Isometry3d& T_b_c = camera.calibration().T_b_c;
  const Eigen::Isometry3d T_w_cj = T_w_bj * T_b_c;
  const Eigen::Isometry3d T_w_cn = T_w_bn * T_b_c;
  const Eigen::Isometry3d T_cn_cj = T_w_cn.inverse() * T_w_cj;
  const double baseline_m = T_cn_cj.translation().norm();
  if (!(baseline_m >= config_.min_baseline_m)) {
    result.reason = fmt::format("geometry: baseline {:.3f} m < {} m between j and its neighbour", baseline_m,
                                config_.min_baseline_m);
    return result;
  }
  const double f_px = camera.calibration().fx;
  const double threshold = config_.reprojection_px / f_px;  // in normalised coordinates
  const double min_cos = std::cos(config_.min_parallax_deg * kPi / 180.0);

  // Points of j triangulated with its neighbour, in camera j.
  std::vector<Eigen::Vector3d> p_cj(fj.keypoints.size(), Eigen::Vector3d::Constant(std::nan("")));
  const std::vector<int> jn = ratio_match_hamming(fj.descriptors, fn.descriptors, config_.ratio);
  const Eigen::Vector3d centre_n_in_j = T_cn_cj.inverse().translation();
  for (std::size_t a = 0; a < jn.size(); ++a) {
    if (jn[a] < 0) continue;
    const Eigen::Vector2d& x_j = fj.xy[a];
    const Eigen::Vector2d& x_n = fn.xy[static_cast<std::size_t>(jn[a])];
    const Eigen::Vector3d p = triangulate(x_j, x_n, T_cn_cj);
    if (!p.allFinite() || p.z() <= 0.0) continue;
    const Eigen::Vector3d p_n = T_cn_cj * p;
    if (p_n.z() <= 0.0) continue;
    const double cos_parallax = p.normalized().dot((p - centre_n_in_j).normalized());
    if (cos_parallax > min_cos) continue;
    if ((p.head<2>() / p.z() - x_j).norm() > threshold || (p_n.head<2>() / p_n.z() - x_n).norm() > threshold)
      continue;
    p_cj[a] = p;
    ++result.points;
  }
  // Frame i against j's triangulated points only (the ratio test among the candidates that can be used).
  std::vector<int> point_rows;
  for (std::size_t a = 0; a < p_cj.size(); ++a)
    if (p_cj[a].allFinite()) point_rows.push_back(static_cast<int>(a));
  cv::Mat point_descriptors(static_cast<int>(point_rows.size()), fj.descriptors.cols, fj.descriptors.type());
  for (std::size_t r = 0; r < point_rows.size(); ++r)
    fj.descriptors.row(point_rows[r]).copyTo(point_descriptors.row(static_cast<int>(r)));
  const std::vector<int> ij = ratio_match_hamming(fi.descriptors, point_descriptors, config_.ratio);
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (std::size_t a = 0; a < ij.size(); ++a) {
    if (ij[a] < 0) continue;
    const Eigen::Vector3d& p = p_cj[static_cast<std::size_t>(point_rows[static_cast<std::size_t>(ij[a])])];
    object.emplace_back(p.x(), p.y(), p.z());
    image.emplace_back(fi.xy[a].x(), fi.xy[a].y());
  }
  result.matches = static_cast<int>(object.size());
  if (result.matches < config_.min_inliers) {
    result.reason = fmt::format("geometry: {} matches with 3-D points < {} ({} points triangulated)",
                                result.matches, config_.min_inliers, result.points);
  } else {
    solve_pose(object, image, threshold, T_b_c, result);
  }
  const auto vetoed = [&](VerifyResult& r) {
    if (!r.verified || !veto) return false;
    std::string why = veto(r);
    if (why.empty()) return false;
    r.verified = false;
    r.reason = std::move(why);
    return true;
  };
  vetoed(result);
  if (result.verified || config_.track_pyramid_levels == 0 || fi.image.empty() || fj.image.empty() ||
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
  // Two starts for the tracking: where the odometry's rotation from j to i moves j's points, then where they
  // are. The odometry's relative rotation carries its heading drift from j to i (a few degrees after a long
  // loop: tens of pixels), the second start none: the place descriptor matched i to j because i sees the
  // place much as j did. The second runs only when the first does not verify the loop.
  std::string notes;
  const Eigen::Matrix3d* starts[] = {R_w_bi, nullptr};
  for (const Eigen::Matrix3d* start : starts) {
    const bool first = notes.empty();
    if (start == nullptr && R_w_bi == nullptr && !first) break;  // the same start again
    std::string note;
    VerifyResult tracked = track_from_j_and_n(sources, start, threshold, vetoed, note);
    if (tracked.verified) {
      tracked.points = result.points;
      if (!notes.empty()) tracked.reason += "; from the images' rotation, after" + notes;
      return tracked;
    }
    notes += (first ? "; tracked: " : "; tracked from the images' rotation: ") + note;
  }
  result.reason += notes;
  return result;
}

VerifyResult GeometricVerifier::track_from_j_and_n(const TrackSources& s, const Eigen::Matrix3d* R_w_bi,
                                                   double threshold,
                                                   const std::function<bool(VerifyResult&)>& vetoed,
                                                   std::string& note) const {
  const Eigen::Isometry3d& T_b_c = camera_->calibration().T_b_c;
  const Eigen::Isometry3d T_w_cn = s.T_w_cj * s.T_cn_cj.inverse();
  const Eigen::Vector3d centre_n_in_j = s.T_cn_cj.inverse().translation();
  const TrackedPose by_j = track_into_i(s.pyramid_j, s.pyramid_i, s.from_j, s.points_j, s.T_w_cj,
                                        centre_n_in_j, R_w_bi, threshold);
  if (!by_j.result.verified) {
    note = by_j.note;
    return by_j.result;
  }
  const TrackedPose by_n = track_into_i(s.pyramid_n, s.pyramid_i, s.from_n, s.points_n, T_w_cn,
                                        s.T_cn_cj.translation(), R_w_bi, threshold);
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
  tracked.reason =
      fmt::format("verified by tracking ({}; from j's neighbour {:.2f} m apart)", by_j.note, apart_m);
  return tracked;
}

GeometricVerifier::TrackedPose GeometricVerifier::track_into_i(
    const Pyramid& pyramid_src, const Pyramid& pyramid_i, std::vector<cv::Point2f> uv_src,
    const std::vector<Eigen::Vector3d>& p_csrc, const Eigen::Isometry3d& T_w_csrc,
    const Eigen::Vector3d& c_other, const Eigen::Matrix3d* R_w_bi, double threshold) const {
  const CameraModel& camera = *camera_;
  const Eigen::Isometry3d& T_b_c = camera.calibration().T_b_c;
  std::optional<Eigen::Matrix3d> R_ci_csrc;
  if (R_w_bi != nullptr) R_ci_csrc = (*R_w_bi * T_b_c.linear()).transpose() * T_w_csrc.linear();
  const std::vector<unsigned char> found =
      track_across_illumination(pyramid_src, pyramid_i, R_ci_csrc ? &*R_ci_csrc : nullptr, uv_src);
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
  }
  return out;
}

void GeometricVerifier::solve_pose(const std::vector<cv::Point3d>& object,
                                   const std::vector<cv::Point2d>& image, double threshold,
                                   const Eigen::Isometry3d& T_b_c, VerifyResult& result) const {
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  bool ok = false;
  // The minimal solver is AP3P (Ke & Roumeliotis 2017: 3 points and a 4th to choose among its solutions), the
  // usual one in PnP RANSAC: its samples of 4 points reach the 0.99 confidence in fewer iterations than
  // EPnP's 5 (72 against 145 at half inliers) and each costs a fraction of an EPnP solve. The pose is refined
  // on the inliers below, whichever solver found them (docs/loop-correction.md, the
  // measurement).
  try {
    ok = cv::solvePnPRansac(object, image, cv::Mat::eye(3, 3, CV_64F), cv::noArray(), rvec, tvec, false,
                            config_.ransac_iterations, static_cast<float>(threshold), 0.99, inliers,
                            cv::SOLVEPNP_AP3P);
  } catch (const cv::Exception& e) {
    result.reason = std::string("geometry: PnP failed: ") + e.what();
    return;
  }
  result.inliers = static_cast<int>(inliers.size());
  if (!ok || result.inliers < config_.min_inliers) {
    result.reason = fmt::format("geometry: {} inliers < {}", result.inliers, config_.min_inliers);
    return;
  }
  // Refine on the inliers (iterative, from the RANSAC solution).
  std::vector<cv::Point3d> object_in;
  std::vector<cv::Point2d> image_in;
  for (const int k : inliers) {
    object_in.push_back(object[static_cast<std::size_t>(k)]);
    image_in.push_back(image[static_cast<std::size_t>(k)]);
  }
  cv::solvePnP(object_in, image_in, cv::Mat::eye(3, 3, CV_64F), cv::noArray(), rvec, tvec, true,
               cv::SOLVEPNP_ITERATIVE);
  cv::Mat R_cv;
  cv::Rodrigues(rvec, R_cv);
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  cv::cv2eigen(R_cv, R);
  cv::cv2eigen(tvec, t);
  Eigen::Isometry3d T_ci_cj = Eigen::Isometry3d::Identity();
  T_ci_cj.linear() = R;
  T_ci_cj.translation() = t;
  if (!T_ci_cj.matrix().allFinite()) {
    result.reason = "geometry: PnP gave a non-finite pose";
    return;
  }
  result.T_j_i = T_b_c * T_ci_cj.inverse() * T_b_c.inverse();
  const double distance_m = result.T_j_i.translation().norm();
  if (distance_m > config_.max_translation_m) {
    result.reason =
        fmt::format("geometry: relative translation {:.1f} m > {} m", distance_m, config_.max_translation_m);
    return;
  }
  const double shrink = std::sqrt(static_cast<double>(config_.min_inliers) / result.inliers);
  result.cov.setZero();
  result.cov.topLeftCorner<3, 3>().diagonal().setConstant(std::pow(config_.sigma_position_m * shrink, 2));
  result.cov.bottomRightCorner<3, 3>().diagonal().setConstant(
      std::pow(config_.sigma_rotation_rad * shrink, 2));
  result.verified = true;
  result.reason = "verified";
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
    const Pyramid& pyramid_j, const Pyramid& pyramid_i, const Eigen::Matrix3d* R_ci_cj,
    std::vector<cv::Point2f>& points) const {
  std::vector<unsigned char> found(points.size(), 0);
  if (points.empty() || pyramid_j.empty() || pyramid_i.empty()) return found;
  const cv::Size window(config_.track_window_px, config_.track_window_px);
  const int levels = config_.track_pyramid_levels;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  // Start where the rotation moves a point (a far point moves with it), or where it is, forward; backward,
  // start where the inverse rotation moves the point found in i.
  const CameraModel& camera = *camera_;
  const auto rotated = [&](const std::vector<cv::Point2f>& from, const Eigen::Matrix3d& R) {
    std::vector<cv::Point2f> to = from;
    for (cv::Point2f& p : to) {
      const Eigen::Vector3d ray = R * camera.undistort_normalized(Eigen::Vector2d(p.x, p.y)).homogeneous();
      Eigen::Vector2d uv;
      if (ray.z() > 0.0 && camera.project(ray, &uv) && uv.allFinite())
        p = cv::Point2f(static_cast<float>(uv.x()), static_cast<float>(uv.y()));
    }
    return to;
  };
  std::vector<cv::Point2f> in_i = R_ci_cj != nullptr ? rotated(points, *R_ci_cj) : points;
  std::vector<unsigned char> forward_ok;
  std::vector<unsigned char> backward_ok;
  // cv::calcOpticalFlowPyrLK's tracking with exact integer window sums (core/klt.hpp).
  track_klt(pyramid_j, pyramid_i, points, in_i, forward_ok, window, levels, criteria, true);
  std::vector<cv::Point2f> back = R_ci_cj != nullptr ? rotated(in_i, R_ci_cj->transpose()) : in_i;
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
