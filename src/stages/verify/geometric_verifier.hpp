// Geometric verification of a loop closure (i, j), the VINS-Mono way for a monocular camera: ORB features
// of frame j and of its neighbour j + k are matched (ratio test) and triangulated with the two frames'
// odometry poses (the odometry is locally accurate, so this gives metric scale); frame i's ORB features are
// matched to j's triangulated ones and PnP RANSAC gives frame i's camera pose in j's odometry frame, hence
// the relative body pose T_j_i with its inlier count. Section "verify". No threads, no files.
//
// Covariance of T_j_i: a documented model, not the PnP Jacobian (whose scale would hide the dominant error,
// the triangulation's depth from a short odometry baseline): position sigma_position_m and rotation
// sigma_rotation_rad at min_inliers inliers, shrinking as sqrt(min_inliers / inliers).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/camera_model.hpp"
#include "core/types.hpp"

namespace loopgate {

struct VerifyConfig {
  bool enabled = false;          // off by default: runs without it are unchanged (configs turn it on)
  int features = 1000;           // ORB features per frame
  int orb_patch_px = 31;         // ORB patch size and edge threshold (OpenCV's 31; smaller for small images)
  int orb_fast_threshold = 20;   // FAST threshold of ORB (OpenCV's 20)
  double ratio = 0.8;            // Lowe ratio test (best / second best Hamming distance)
  int min_inliers = 25;          // PnP RANSAC inliers for a verified loop
  double reprojection_px = 3.0;  // PnP RANSAC inlier threshold and triangulation check, pixels
  int neighbour_offset_frames = 3;  // triangulate from j and j + k (k < 0: j - |k|)
  double min_baseline_m = 0.05;     // odometry distance between j and j + k below which no scale
  double min_parallax_deg = 1.0;    // triangulated points need this angle between the two rays
  int min_image_px = 80;            // frames narrower or lower than this are not verified
  int ransac_iterations = 200;
  double max_translation_m = 30.0;  // |t_j_i| above this is rejected (a revisit is near)
  double sigma_position_m = 0.3;    // T_j_i covariance at min_inliers (see above)
  double sigma_rotation_rad = 0.02;
  // A verified loop must agree with the odometry: where it puts frame i (T_w_bj T_j_i) may differ from the
  // odometry's position of i by at most sqrt(odometry_chi2) sigmas (odometry_disagreement() below). The
  // default is the chi-square quantile of 3 dof at 0.999 (16.27). 0: no such check.
  double odometry_chi2 = 16.27;
  // Which loops are verified (the loop closer; 0 = no limit / no skipping). A revisit gives one loop per
  // query frame; one verified edge every few frames is all the pose graph needs.
  // A loop (i, j) is verified only when the odometry's position sigma grew from j to i by at least
  // min_sigma_gain x sigma_position_m (sqrt(sigma_i^2 - sigma_j^2)): an edge no more certain than what the
  // odometry already knows corrects nothing (standing still, hovering). 0: verify regardless.
  double min_sigma_gain = 1.0;
  int max_per_query = 0;               // loops verified per query frame (the first ones submitted)
  int skip_after_verified_frames = 0;  // skip (i, j) when (i', j') was verified with |i-i'|, |j-j'| <= N
  int skip_after_rejected_frames = 0;  // the same after a rejected (i', j')
  int feature_cache_frames = 64;       // ORB features kept per frame (detected once, reused)

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("enabled", self.enabled);
    v("features", self.features);
    v("orb_patch_px", self.orb_patch_px);
    v("orb_fast_threshold", self.orb_fast_threshold);
    v("ratio", self.ratio);
    v("min_inliers", self.min_inliers);
    v("reprojection_px", self.reprojection_px);
    v("neighbour_offset_frames", self.neighbour_offset_frames);
    v("min_baseline_m", self.min_baseline_m);
    v("min_parallax_deg", self.min_parallax_deg);
    v("min_image_px", self.min_image_px);
    v("ransac_iterations", self.ransac_iterations);
    v("max_translation_m", self.max_translation_m);
    v("sigma_position_m", self.sigma_position_m);
    v("sigma_rotation_rad", self.sigma_rotation_rad);
    v("odometry_chi2", self.odometry_chi2);
    v("min_sigma_gain", self.min_sigma_gain);
    v("max_per_query", self.max_per_query);
    v("skip_after_verified_frames", self.skip_after_verified_frames);
    v("skip_after_rejected_frames", self.skip_after_rejected_frames);
    v("feature_cache_frames", self.feature_cache_frames);
  }
  // Throws ConfigError naming verify.KEY and its bound.
  void validate() const;
};

struct VerifyResult {
  bool verified = false;
  std::string reason;  // why not ("geometry: 12 inliers < 25"), or "verified"
  int matches = 0;     // i-to-j matches with a triangulated point
  int points = 0;      // points triangulated from j and j + k
  int inliers = 0;
  Eigen::Isometry3d T_j_i = Eigen::Isometry3d::Identity();                    // body i in body j
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Identity();  // (position, rotation)
};

// A verified loop against the odometry: where the loop puts frame i (T_w_bj T_j_i) and where the odometry
// puts it (T_w_bi) are compared in units of sigma^2 = sigma_i^2 - sigma_j^2 + sigma_edge^2: the growth of the
// odometry's position sigma from j to i (the sigma of the largest eigenvalue, frames.csv's sigma_m, as
// verify.min_sigma_gain uses it) and the loop edge's position sigma (the largest of loop.cov's). The
// squared distance over sigma^2 must not exceed `chi2_bound`. Image geometry cannot reject a place that
// looks and is built the same as another one (aliasing); the odometry knows the two are far apart. This is
// the odometry check of Kimera-RPGO's PCM and RTAB-Map's RGBD/OptimizeMaxError, before the edge reaches the
// graph. Returns the rejection reason ("geometry: 41.30 m from the odometry's frame i, 23.1 sigma > 4.03"),
// empty when the loop agrees, and empty when the odometry cannot judge: a sigma that is not a finite number
// > 0 (no covariance), or sigma_i < sigma_j (it learnt where it is in between). The caller also leaves out
// loops whose odometry chain from j to i is broken (a lost frame, a re-initialisation).
std::string odometry_disagreement(const Eigen::Isometry3d& T_w_bi, const Eigen::Isometry3d& T_w_bj,
                                  const VerifyResult& loop, double sigma_i_m, double sigma_j_m,
                                  double chi2_bound);

// What the verifier needs of one frame: its grey image and its odometry pose.
struct VerifyFrame {
  cv::Mat image;
  Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
};

// ORB features of one frame (detected once per frame, cacheable).
struct OrbFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  std::vector<Eigen::Vector2d> xy;  // undistorted normalised coordinates
  cv::Size image_size;
};

// Query row -> train row of the Hamming nearest neighbour passing Lowe's ratio test (best < ratio x second
// best), -1 where none: the matches cv::BFMatcher(NORM_HAMMING).knnMatch(k = 2) gives with that test (a tie
// for the best fails it either way), without the distance matrix and the sort. Rows of CV_8U of equal width.
std::vector<int> ratio_match_hamming(const cv::Mat& query, const cv::Mat& train, double ratio);

class GeometricVerifier {
 public:
  // `camera`: nullopt when the dataset has no calibration (every loop is then rejected with that reason).
  GeometricVerifier(const VerifyConfig& config, const std::optional<CameraCalibration>& camera);

  // Loop (i, j): frame i, frame j and j's neighbour n = j + neighbour_offset_frames. Never throws on bad
  // input: the result says why it is not verified.
  VerifyResult verify(const VerifyFrame& i, const VerifyFrame& j, const VerifyFrame& n) const;

  // The same from features detected beforehand (detect()): i's features, j's and n's with their poses.
  VerifyResult verify(const OrbFeatures& i, const OrbFeatures& j, const Eigen::Isometry3d& T_w_bj,
                      const OrbFeatures& n, const Eigen::Isometry3d& T_w_bn) const;

  // ORB features of a grey image (none without a calibration or for an empty image).
  OrbFeatures detect(const cv::Mat& image) const;

  // A reason when no loop can be verified at all (no calibration, images too small), else empty.
  std::string unusable_reason(const cv::Size& image_size) const;

  const VerifyConfig& config() const { return config_; }

 private:
  VerifyConfig config_;
  std::optional<CameraModel> camera_;
};

}  // namespace loopgate
