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
#include <functional>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/camera_model.hpp"
#include "core/enum_names.hpp"
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
  // A loop (i, j) is verified only when its edge would tell the pose graph something the odometry does not
  // know. The odometry's covariance of T_j_i (its step covariances composed from j to i, as the graph's
  // odometry edges compose them) is trusted only over odometry a verified loop has checked: a loop no
  // verified loop covers is verified whatever its gain. Otherwise that covariance, scaled by what the
  // verified loops' innovations show, fused with the covering loop's edge covariance divided by the loops of
  // the revisit so far (they correct together) must shrink the largest position variance of T_j_i by at
  // least this fraction (loop_information_gain(), stages/posegraph). Below 10% the edges move the relative
  // position's sigma by under 5% (sqrt(0.9) = 0.95). A property of the covariances, not of a data set
  // (docs/loop-correction.md). 0: verify regardless.
  double min_information_gain = 0.1;
  int max_per_query = 0;               // loops verified per query frame (the first ones submitted)
  int skip_after_verified_frames = 0;  // skip (i, j) when (i', j') was verified with |i-i'|, |j-j'| <= N
  int skip_after_rejected_frames = 0;  // the same after a rejected (i', j')
  int feature_cache_frames = 64;       // ORB features kept per frame (detected once, reused)
  // When ORB's matches do not verify a loop across a change of illumination (day against night: the
  // descriptors of a lamp-lit, noisy image differ from the day's), j's triangulated points are tracked into
  // i by a pyramidal KLT on locally normalised images and PnP runs on those (track_across_illumination
  // below). A change of illumination: the two images' noise (noise_sigma()) differs by track_min_noise_ratio
  // or more (noise grows as the square root of the gain: 2 = a gain ratio of 4). 0 levels: no fallback.
  int track_pyramid_levels = 4;        // KLT pyramid levels: 4 follow ~100 px (a revisit's offset)
  int track_window_px = 15;            // KLT window
  double track_norm_sigma_px = 4.0;    // window (a Gaussian's sigma) of the local mean and deviation
  double track_fb_max_px = 1.0;        // forward-backward agreement j -> i -> j
  double track_min_noise_ratio = 2.0;  // the illumination change that calls for it (1: every rejection)

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
    v("min_information_gain", self.min_information_gain);
    v("max_per_query", self.max_per_query);
    v("skip_after_verified_frames", self.skip_after_verified_frames);
    v("skip_after_rejected_frames", self.skip_after_rejected_frames);
    v("feature_cache_frames", self.feature_cache_frames);
    v("track_pyramid_levels", self.track_pyramid_levels);
    v("track_window_px", self.track_window_px);
    v("track_norm_sigma_px", self.track_norm_sigma_px);
    v("track_fb_max_px", self.track_fb_max_px);
    v("track_min_noise_ratio", self.track_min_noise_ratio);
  }
  // Throws ConfigError naming verify.KEY and its bound.
  void validate() const;
};

// Why a loop was or was not verified, under a stable key (summary.json's loop_closure.rejected_by_reason and
// skipped_by_reason): verified, verified_by_tracking; rejected: no_calibration, image_too_small (the images
// are below verify.min_image_px), image_missing (missing or unreadable), no_odometry_pose, short_baseline (j
// and its neighbour too close to triangulate), too_few_features (too few matches with triangulated points at
// this image resolution), too_few_inliers, pnp_failed, translation_too_large, odometry_disagreement,
// illumination (ORB did not verify it and the tracking fallback across a change of illumination did not
// either); skipped: small_information_gain, skip_window, max_per_query; other (an unexpected exception).
enum class VerifyReason {
  kVerified,
  kVerifiedByTracking,
  kNoCalibration,
  kImageTooSmall,
  kImageMissing,
  kNoOdometryPose,
  kShortBaseline,
  kTooFewFeatures,
  kTooFewInliers,
  kPnpFailed,
  kTranslationTooLarge,
  kOdometryDisagreement,
  kIllumination,
  kSmallInformationGain,
  kSkipWindow,
  kMaxPerQuery,
  kOther,
};
inline constexpr EnumName<VerifyReason> kVerifyReasonNames[] = {
    {VerifyReason::kVerified, "verified"},
    {VerifyReason::kVerifiedByTracking, "verified_by_tracking"},
    {VerifyReason::kNoCalibration, "no_calibration"},
    {VerifyReason::kImageTooSmall, "image_too_small"},
    {VerifyReason::kImageMissing, "image_missing"},
    {VerifyReason::kNoOdometryPose, "no_odometry_pose"},
    {VerifyReason::kShortBaseline, "short_baseline"},
    {VerifyReason::kTooFewFeatures, "too_few_features"},
    {VerifyReason::kTooFewInliers, "too_few_inliers"},
    {VerifyReason::kPnpFailed, "pnp_failed"},
    {VerifyReason::kTranslationTooLarge, "translation_too_large"},
    {VerifyReason::kOdometryDisagreement, "odometry_disagreement"},
    {VerifyReason::kIllumination, "illumination"},
    {VerifyReason::kSmallInformationGain, "small_information_gain"},
    {VerifyReason::kSkipWindow, "skip_window"},
    {VerifyReason::kMaxPerQuery, "max_per_query"},
    {VerifyReason::kOther, "other"},
};
constexpr std::span<const EnumName<VerifyReason>> enum_names(VerifyReason) {
  return kVerifyReasonNames;
}

// A reason with its numbers, for loops_verified.csv and the log ("geometry: 12 inliers < 25"), and its key.
struct VerifyNote {
  VerifyReason key = VerifyReason::kOther;
  std::string text;
};

struct VerifyResult {
  bool verified = false;
  VerifyReason key = VerifyReason::kOther;  // the reason's key
  std::string reason;    // why not ("geometry: 12 inliers < 25"), or "verified" / "verified by tracking"
  bool tracked = false;  // verified by the tracking fallback (ORB's matches did not verify it)
  int matches = 0;       // i-to-j matches with a triangulated point
  int points = 0;        // points triangulated from j and j + k
  int inliers = 0;
  Eigen::Isometry3d T_j_i = Eigen::Isometry3d::Identity();                    // body i in body j
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Identity();  // (position, rotation)

  // Not verified, for this reason.
  void reject(VerifyNote note) {
    verified = false;
    key = note.key;
    reason = std::move(note.text);
  }
};

// A verified loop against the odometry: where the loop puts frame i (T_w_bj T_j_i) and where the odometry
// puts it (T_w_bi) are compared in units of sigma^2 = sigma_i^2 - sigma_j^2 + sigma_edge^2: the growth of the
// odometry's position sigma from j to i (the sigma of the largest eigenvalue, frames.csv's sigma_m) and the
// loop edge's position sigma (the largest of loop.cov's). The squared distance over sigma^2 must not exceed
// `chi2_bound`. Image geometry cannot reject a place that looks and is built the same as another one
// (aliasing); the odometry knows the two are far apart. This is the odometry check of Kimera-RPGO's PCM and
// RTAB-Map's RGBD/OptimizeMaxError, before the edge reaches the graph. Returns the rejection reason
// ("geometry: 41.30 m from the odometry's frame i, 23.1 sigma > 4.03"), empty when the loop agrees, and empty
// when the odometry cannot judge: a sigma that is not a finite number > 0 (no covariance), or sigma_i <
// sigma_j (it learnt where it is in between). The caller also leaves out loops whose odometry chain from j to
// i is broken (a lost frame, a re-initialisation).
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
  cv::Mat image;  // the grey image (shared, not copied): the tracking fallback's input
};

// The image the tracking fallback aligns: each pixel's deviation from its local mean over the local standard
// deviation (a window of about a Gaussian of `sigma_px`), after smoothing the image down to `noise_target`
// grey levels of noise (Immerkaer's estimate; 0: half a pixel); CV_8U, 128 + 32 x the normalised value.
// Smooth illumination (a lamp's fall-off, an exposure) cancels in the ratio: what remains is the local
// texture, as in SeqSLAM's patch normalisation. `noise`: the image's noise_sigma() when known (< 0: estimated
// here).
cv::Mat normalise_illumination(const cv::Mat& grey, double sigma_px, double noise_target,
                               double noise = -1.0);

// Immerkaer's (1996) estimate of the standard deviation of white noise in a grey image, in grey levels.
double noise_sigma(const cv::Mat& grey);

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

  // The odometry's check of a pose the images verified (odometry_disagreement()): a reason to reject it
  // (key odometry_disagreement), or empty.
  using Veto = std::function<std::string(const VerifyResult&)>;

  // The same from features detected beforehand (detect()): i's features, j's and n's with their poses.
  // `T_w_bi`, the odometry's pose of frame i when known, starts the tracking fallback where that pose sees
  // j's triangulated points (the odometry's relative pose drifts little over a revisit; the images measure
  // what it drifted).
  // `veto` judges each pose the images verify, ORB's then the fallback's: across a change of illumination
  // ORB's matches can give a wrong pose with many inliers, which the odometry rejects and tracking corrects.
  VerifyResult verify(const OrbFeatures& i, const OrbFeatures& j, const Eigen::Isometry3d& T_w_bj,
                      const OrbFeatures& n, const Eigen::Isometry3d& T_w_bn,
                      const Eigen::Isometry3d* T_w_bi = nullptr, const Veto& veto = {}) const;

  // ORB features of a grey image (none without a calibration or for an empty image).
  OrbFeatures detect(const cv::Mat& image) const;

  // The reason when no loop can be verified at all (no calibration, images too small), else nullopt.
  std::optional<VerifyNote> unusable_reason(const cv::Size& image_size) const;

  const VerifyConfig& config() const { return config_; }

 private:
  // The pose of i from points of a source frame (j or its neighbour) tracked into i: `uv_src` their pixels
  // in the source image, `p_csrc` their positions in its camera, `c_other` the centre of the camera they were
  // triangulated with (in the source camera). result.T_j_i is the source body's T_src_i; note says how many
  // points tracked and inliers, and the position sigma their geometry gives (pnp_position_sigma_m).
  struct TrackedPose {
    VerifyResult result;
    std::string note;
  };
  using Pyramid = std::vector<cv::Mat>;
  TrackedPose track_into_i(const Pyramid& pyramid_src, const Pyramid& pyramid_i,
                           std::vector<cv::Point2f> uv_src, const std::vector<Eigen::Vector3d>& p_csrc,
                           const Eigen::Isometry3d& T_w_csrc, const Eigen::Vector3d& c_other,
                           const Eigen::Isometry3d* T_w_bi, double threshold) const;
  // What the tracking fallback tracks: j's triangulated points (their pixels in j and in its neighbour n,
  // their positions in camera j and in camera n) and the three images' normalised pyramids.
  struct TrackSources {
    Pyramid pyramid_i, pyramid_j, pyramid_n;
    std::vector<cv::Point2f> from_j, from_n;
    std::vector<Eigen::Vector3d> points_j, points_n;
    Eigen::Isometry3d T_w_cj = Eigen::Isometry3d::Identity();
    Eigen::Isometry3d T_cn_cj = Eigen::Isometry3d::Identity();
  };
  // The tracking fallback from one start (T_w_bi: the odometry's pose of i, or nullptr: j's points
  // where they are): i's pose tracked from j, confirmed from n, then `vetoed` (the odometry check). Verified,
  // or not with `note` saying why.
  VerifyResult track_from_j_and_n(const TrackSources& sources, const Eigen::Isometry3d* T_w_bi,
                                  double threshold, const std::function<bool(VerifyResult&)>& vetoed,
                                  std::string& note) const;
  // The fallback when ORB's matches did not verify the loop (`result`, returned with the tracking's notes
  // when the fallback does not verify it either): across a change of illumination (the noise ratio of i and
  // j), j's triangulated points `p_cj` (rows `point_rows` of j's features, `jn` their matches in n) tracked
  // into i, from the two starts of track_from_j_and_n().
  VerifyResult track_fallback(const OrbFeatures& fi, const OrbFeatures& fj, const OrbFeatures& fn,
                              const Eigen::Isometry3d& T_w_cj, const Eigen::Isometry3d& T_cn_cj,
                              const std::vector<Eigen::Vector3d>& p_cj, const std::vector<int>& point_rows,
                              const std::vector<int>& jn, const Eigen::Isometry3d* T_w_bi, double threshold,
                              const std::function<bool(VerifyResult&)>& vetoed, VerifyResult result) const;
  // The KLT pyramid of normalise_illumination(grey) smoothed from its `noise` to `noise_target`.
  Pyramid normalised_pyramid(const cv::Mat& grey, double noise, double noise_target) const;
  // PnP RANSAC on the correspondences, refined on its inliers: fills `result` (verified, or the reason).
  void solve_pose(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& image,
                  double threshold, const Eigen::Isometry3d& T_b_c, VerifyResult& result) const;
  // `points` of image j tracked into image i on their normalised_pyramid()s, forward from `start_i` (the
  // predicted positions in i) and back from each point moved by what the forward track corrected of its
  // prediction: where a point is found both ways, points[k] becomes its position in i and found[k] is 1.
  std::vector<unsigned char> track_across_illumination(const Pyramid& pyramid_j, const Pyramid& pyramid_i,
                                                       const std::vector<cv::Point2f>& start_i,
                                                       std::vector<cv::Point2f>& points) const;

  VerifyConfig config_;
  std::optional<CameraModel> camera_;
};

}  // namespace loopgate
