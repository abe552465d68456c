// The `ekf` odometry source as a plain class (docs/ekf.md): KLT front end + MSCKF, started by
// the initialiser(s) of ekf.init_mode (from the sensors, or from ground truth for experiments), failure
// detection with re-initialisation by the same initialisers. One call per image, in order.
// To wrap it as an OdometrySource: feed OdometryInput::imu / ::image, and for init_mode ground_truth the
// state from ground_truth_state_at(dataset.ground_truth(), t_ns).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/types.hpp"
#include "stages/ekf/dynamic_initializer.hpp"
#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/feature_tracker.hpp"
#include "stages/ekf/initializer.hpp"
#include "stages/ekf/msckf.hpp"
#include "stages/ekf/static_initializer.hpp"

namespace cv {
class Mat;
}

namespace loopgate {

struct EkfFrameInput {
  Timestamp t_ns = 0;
  // IMU samples since the previous image (the sync node interpolates the first and last to the image times).
  std::span<const ImuSample> imu;
  const cv::Mat* image = nullptr;  // 8-bit grey image, tracked by the KLT front end
  // The same image prepared beforehand (prepare_image(), e.g. on another thread); used instead of `image`.
  const TrackerImage* prepared = nullptr;
  // Instead of an image: observations in undistorted normalised coordinates (simulation, tests).
  const std::vector<FeatureObservation>* observations = nullptr;
  std::optional<GroundTruthState> ground_truth;  // used by init_mode ground_truth
};

struct EkfFrameOutput {
  PoseEstimate pose;
  int tracked_features = 0;
  double position_sigma_m = 0;  // sqrt(trace of the position covariance)
  std::string reason;           // why the status is not tracking (empty when tracking)
  MsckfUpdateStats update;
  double median_disparity_px = -1;  // median feature motion since the previous image (-1: unknown)
  bool zero_velocity = false;       // a zero-velocity update was applied
  double tracking_ms = 0;           // wall time of the KLT front end for this image
  double filter_ms = 0;             // wall time of propagation + update
  // The covariance of this pose relative to the previous image's (T_prev_this; core/pose_covariance.hpp),
  // from the filter's joint covariance of this pose and the newest clone before it: exact (to first order)
  // when the previous image is that clone, the step between two poses relative to the same clone
  // (step_pose_cov) otherwise. nullopt on the first tracked image and after a loss.
  std::optional<PoseCov> step_cov;
};

// "static" | "dynamic" | "ground_truth": the initialiser's name, as ekf.init_mode writes it.
const char* init_method_name(InitMethod method);

// Noise used by the filter: config overrides (> 0) or the calibration, times config.imu_noise_inflation.
// Throws ConfigError naming the key when a density ends up zero.
ImuNoise effective_imu_noise(const EkfConfig& config, const ImuCalibration& imu);

// Ground-truth state at t_ns, interpolated between the two nearest states (pose: interpolate_pose of
// core/geometry.hpp; biases and velocity linear); when those carry
// no velocity (all zero, e.g. a TUM ground truth) it is taken from the positions by central difference.
// nullopt outside the time span or with fewer than two states.
std::optional<GroundTruthState> ground_truth_state_at(const std::vector<GroundTruthState>& states,
                                                      Timestamp t_ns);

class VioEkf {
 public:
  // Throws ConfigError for an invalid config or camera calibration.
  VioEkf(const EkfConfig& config, const CameraCalibration& camera, const ImuCalibration& imu);

  // Throws DataError for a bad image (see FeatureTracker::track); never for filter trouble (status lost).
  EkfFrameOutput process(const EkfFrameInput& input);
  // The tracker's per-image work that does not depend on earlier images (FeatureTracker::prepare): const and
  // thread-safe, so that it can run while process() runs on an earlier frame. Throws DataError for an image
  // the tracker cannot take.
  TrackerImage prepare_image(const cv::Mat& grey) const { return tracker_.prepare(grey); }

  const Msckf& filter() const { return filter_; }
  const FeatureTracker& tracker() const { return tracker_; }
  std::size_t frames_processed() const { return frame_; }
  // The state of the latest start (frame: index of the image among those given to process()); nullopt
  // before the first. starts(): how often the filter started (the first start and every restart after a
  // loss).
  const std::optional<InitialState>& initial_state() const { return initial_; }
  std::size_t starts() const { return starts_; }
  // While initialising: why not yet, from each initialiser that runs, with its numbers.
  const std::string& init_status() const { return init_status_; }
  const StaticInitializer& static_initializer() const { return static_init_; }
  const DynamicInitializer& dynamic_initializer() const { return dynamic_init_; }

 private:
  EkfFrameOutput update_filter(const EkfFrameInput& input, const std::vector<FeatureObservation>& obs,
                               double disparity_px, std::size_t frame);
  bool try_initialize(const EkfFrameInput& input, const std::vector<FeatureObservation>& obs,
                      std::size_t frame);
  void initialize_from(const InitialState& init);
  EkfFrameOutput lost(std::size_t frame, const std::string& reason);

  EkfConfig config_;
  Eigen::Isometry3d T_b_i_;
  Eigen::Matrix3d R_i_c_;  // camera -> IMU rotation
  double focal_px_;
  FeatureTracker tracker_;
  Msckf filter_;
  StaticInitializer static_init_;
  DynamicInitializer dynamic_init_;
  std::optional<InitialState> initial_;
  std::size_t starts_ = 0;
  std::string init_status_;
  double median_disparity_px(const std::vector<FeatureObservation>& observations) const;
  // Rotation of the camera from the previous image to this one from the gyro (bias from the filter when it
  // runs): R_cur_prev maps bearings of the previous camera frame into the current one. nullopt without a
  // previous image or IMU samples covering the interval.
  std::optional<Eigen::Matrix3d> camera_rotation_since_previous(const EkfFrameInput& input) const;

  std::unordered_map<std::uint64_t, Eigen::Vector2d> previous_xy_;
  std::size_t frame_ = 0;
  std::optional<Timestamp> previous_image_t_ns_;
  int few_feature_frames_ = 0;
  int frames_since_clone_ = 0;
  std::optional<PoseEstimate> last_good_;
  // The previous tracked image's pose relative to its anchor clone (step_cov).
  struct AnchoredPose {
    std::uint64_t clone_id = 0;
    Timestamp image_t_ns = 0;
    Eigen::Isometry3d T_r_b = Eigen::Isometry3d::Identity();
    PoseCov cov = PoseCov::Zero();
  };
  std::optional<AnchoredPose> previous_anchored_;
  std::optional<PoseCov> step_cov(Timestamp t_ns);
};

}  // namespace loopgate
