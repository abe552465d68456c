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

std::optional<VerifyNote> GeometricVerifier::unusable_reason(const cv::Size& image_size) const {
  if (!camera_) return VerifyNote{VerifyReason::kNoCalibration, "geometry: no camera calibration"};
  if (image_size.width < config_.min_image_px || image_size.height < config_.min_image_px) {
    return VerifyNote{VerifyReason::kImageTooSmall,
                      fmt::format("geometry: image too small for features ({}x{} < {} px)", image_size.width,
                                  image_size.height, config_.min_image_px)};
  }
  return std::nullopt;
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
    result.key = VerifyReason::kImageMissing;
    result.reason = "geometry: image missing";
    return result;
  }
  if (std::optional<VerifyNote> why = unusable_reason(j.image.size())) {
    result.reject(std::move(*why));
    return result;
  }
  return verify(detect(i.image), detect(j.image), j.T_w_b, detect(n.image), n.T_w_b);
}

VerifyResult GeometricVerifier::verify(const OrbFeatures& fi, const OrbFeatures& fj,
                                       const Eigen::Isometry3d& T_w_bj, const OrbFeatures& fn,
                                       const Eigen::Isometry3d& T_w_bn, const Eigen::Isometry3d* T_w_bi,
                                       const Veto& veto) const {
  VerifyResult result;
  if (std::optional<VerifyNote> why = unusable_reason(fj.image_size)) {
    result.reject(std::move(*why));
    return result;
  }
  const CameraModel& camera = *camera_;
  const Eigen::Isometry3d& T_b_c = camera.calibration().T_b_c;
  const Eigen::Isometry3d T_w_cj = T_w_bj * T_b_c;
  const Eigen::Isometry3d T_w_cn = T_w_bn * T_b_c;
  const Eigen::Isometry3d T_cn_cj = T_w_cn.inverse() * T_w_cj;
  const double baseline_m = T_cn_cj.translation().norm();
  if (!(baseline_m >= config_.min_baseline_m)) {
    result.key = VerifyReason::kShortBaseline;
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
    result.key = VerifyReason::kTooFewFeatures;
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
    r.key = VerifyReason::kOdometryDisagreement;
    r.reason = std::move(why);
    return true;
  };
  vetoed(result);
  if (result.verified) return result;
  return track_fallback(fi, fj, fn, T_w_cj, T_cn_cj, p_cj, point_rows, jn, T_w_bi, threshold, vetoed, result);
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
    result.key = VerifyReason::kPnpFailed;
    result.reason = std::string("geometry: PnP failed: ") + e.what();
    return;
  }
  result.inliers = static_cast<int>(inliers.size());
  if (!ok || result.inliers < config_.min_inliers) {
    result.key = VerifyReason::kTooFewInliers;
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
    result.key = VerifyReason::kPnpFailed;
    result.reason = "geometry: PnP gave a non-finite pose";
    return;
  }
  result.T_j_i = T_b_c * T_ci_cj.inverse() * T_b_c.inverse();
  const double distance_m = result.T_j_i.translation().norm();
  if (distance_m > config_.max_translation_m) {
    result.key = VerifyReason::kTranslationTooLarge;
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
  result.key = VerifyReason::kVerified;
  result.reason = "verified";
}

}  // namespace loopgate
