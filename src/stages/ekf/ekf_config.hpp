// Configuration of the `ekf` odometry source (docs/ekf.md): an MSCKF visual-inertial filter with a KLT
// front end. Every tunable of src/stages/ekf lives here.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "core/enum_names.hpp"

namespace loopgate {

// How the filter starts (docs/ekf.md). auto: the static and the dynamic initialiser both look at every image
// and the first that succeeds starts the filter; static: only when the platform is still; dynamic: only by
// visual-inertial alignment while moving; ground_truth: pose, velocity and both IMU biases from the
// dataset's ground truth (experiments only: the one mode that reads ground truth).
enum class EkfInitMode { kAuto, kStatic, kDynamic, kGroundTruth };
// "standstill" is the old name of static, still accepted; printed and echoed as static.
inline constexpr EnumName<EkfInitMode> kEkfInitModeNames[] = {{EkfInitMode::kAuto, "auto"},
                                                              {EkfInitMode::kStatic, "static"},
                                                              {EkfInitMode::kDynamic, "dynamic"},
                                                              {EkfInitMode::kGroundTruth, "ground_truth"},
                                                              {EkfInitMode::kStatic, "standstill"}};
constexpr std::span<const EnumName<EkfInitMode>> enum_names(EkfInitMode) {
  return kEkfInitModeNames;
}

struct EkfConfig {
  // ---- state / window ----
  int window_size = 11;  // cloned poses kept in the sliding window
  // 2: every second image is cloned, the others only propagate: the window spans twice the baseline and
  // the filter updates half as often. On the rendered euroc-mh05 the ATE is about the same as with 1
  // (single runs 0.22-0.38 m either way), for half the filter time.
  int clone_every_n_frames = 2;
  EkfInitMode init_mode = EkfInitMode::kAuto;
  double gravity_mps2 = 9.81;
  // ---- front end (KLT) ----
  int max_features = 150;            // target number of tracked features
  double image_blur_sigma_px = 0.0;  // Gaussian smoothing before detection and KLT (0 = none)
  int grid_cols = 6;                 // re-detection grid
  int grid_rows = 4;
  double min_feature_distance_px = 15.0;
  // Re-detection runs in the grid cells below their share (max_features / cells); the other cells take
  // more than their share only when the set is still short by at least this many features.
  int redetect_min_missing = 10;
  // A cell that gave fewer corners than asked is searched again after this many images.
  int empty_cell_retry_frames = 5;
  double shi_tomasi_quality = 0.01;
  int shi_tomasi_block_size = 3;
  // A corner's response must also exceed this multiple of the median response of its grid cell (0 = off):
  // keeps the detector off the sensor noise of dark images.
  double corner_noise_factor = 8.0;
  int klt_window_px = 15;      // 21 costs twice the time for no better ATE on the rendered euroc-mh05
  int klt_pyramid_levels = 2;  // enough with the gyro prediction below
  int klt_max_iterations = 30;
  double klt_epsilon = 0.01;
  bool klt_predict_rotation = true;  // start the KLT search at the gyro-predicted position
  double fb_check_max_px = 1.0;      // forward-backward consistency threshold
  // Pyramid levels of the backward (check) flow; -1: klt_pyramid_levels (the former default). The backward
  // flow starts at the feature's previous position, where it ends when the forward track is right, so its
  // coarse levels have nothing to find: 0 cuts the KLT's time by about a quarter (README § Known
  // limitations).
  int klt_check_pyramid_levels = 0;
  double ransac_threshold_px = 1.0;  // on undistorted points expressed in pixels of the mean focal length
  double ransac_confidence = 0.99;
  int border_px = 5;
  // ---- measurement model / update ----
  // KLT localisation noise. 0.5 px gives about the same ATE on the rendered euroc-mh05; 1 px is kept because
  // an assumed noise below the real one makes the filter reject, then diverge (BM_EkfFilter showed it).
  double pixel_sigma_px = 1.0;
  double chi2_quantile = 0.95;  // upper quantile used for gating
  // First-estimate Jacobians: propagation and measurement Jacobians at the first (propagated) estimates,
  // meant to keep the unobservable yaw from gaining spurious information. Off: on the simulated
  // Monte-Carlo runs of tests/ekf_msckf_test.cpp it raised the position NEES (mean of 5 seed sets 5.2
  // instead of 4.0), and the ATE on the rendered euroc-mh05 showed no consistent gain.
  bool first_estimate_jacobians = false;
  int min_track_length = 3;     // observations needed to use a feature
  int max_update_features = 0;  // 0 = no limit
  double min_depth_m = 0.1;
  double max_depth_m = 60.0;
  double max_triangulation_cond = 1e4;  // rejects ill-conditioned (low parallax) features
  int triangulation_iterations = 10;
  double triangulation_max_reproj_sigma = 5.0;  // mean reprojection error in pixel sigmas
  // ---- zero-velocity update (standstill: the MSCKF has no parallax to work with) ----
  bool zupt_enabled = true;
  double zupt_max_disparity_px = 0.3;  // median feature motion between two images below this ...
  int zupt_min_features = 20;          // ... over at least this many features -> standstill
  double zupt_sigma_mps = 0.01;
  // ---- IMU noise: <= 0 keeps the value of the dataset's imu0 sensor.yaml ----
  double gyro_noise_density = 0.0;   // rad / s / sqrt(Hz)
  double gyro_random_walk = 0.0;     // rad / s^2 / sqrt(Hz)
  double accel_noise_density = 0.0;  // m / s^2 / sqrt(Hz)
  double accel_random_walk = 0.0;    // m / s^3 / sqrt(Hz)
  // Multiplies every noise density: the datasheet densities of the EuRoC ADIS16448 are optimistic on a
  // flying platform (vibration), and the rendered images follow the smoothed ground truth, not the
  // vibrating IMU. On the rendered euroc-mh05: 1 -> about twice the ATE of 3; 4 -> 0.42-0.45 m; 5-7 ->
  // 0.22-0.38 m (single runs scatter by +-0.07 m with any small change).
  double imu_noise_inflation = 5.0;
  // ---- initial uncertainty ----
  double init_sigma_rot_rad = 0.01;
  double init_sigma_pos_m = 0.01;
  double init_sigma_vel_mps = 0.05;
  double init_sigma_gyro_bias_radps = 0.01;
  double init_sigma_accel_bias_mps2 = 0.1;
  double init_sigma_yaw_rad = 0.001;  // static / dynamic start: yaw is unobservable, set to 0 with this sigma
  // ---- static initialisation (the platform is still; rotor vibration allowed) ----
  // The decision looks at the last static_window_s of IMU data, low-passed by two moving averages of
  // static_lowpass_s each (a triangular filter: vibration at 50-200 Hz is attenuated by more than 100x, the
  // platform's own motion is kept). "Still" when the spread of the low-passed accelerometer and gyro over the
  // window stays below static_excitation_sigmas times the spread white sensor noise alone would leave
  // after that filter (the effective noise densities, see imu_noise_inflation), and the feature motion
  // between images (median over the features, then over the window's images) stays below
  // static_max_disparity_px.
  double static_window_s = 1.0;
  double static_lowpass_s = 0.1;
  double static_excitation_sigmas = 3.0;
  double static_max_disparity_px = 0.5;
  // ---- failure of the start ----
  // A run whose filter has not started after this many seconds of data since the first image is a failed run
  // (it still writes its outputs), and so is one that tracks fewer than min_tracked_share of its frames from
  // the first start on.
  double max_init_s = 10.0;
  double min_tracked_share = 0.8;
  // ---- failure detection ----
  int lost_min_features = 10;           // fewer tracked features than this ...
  int lost_max_frames = 10;             // ... for this many consecutive frames -> lost
  double max_position_sigma_m = 100.0;  // beyond this the filter is declared diverged
  // ---- dynamic initialisation (visual-inertial alignment over a window of images while moving) ----
  double dynamic_init_window_s = 2.0;          // span of the window of images the alignment uses
  double dynamic_init_min_parallax_px = 10.0;  // median parallax of the SfM pair left after the best rotation
  int dynamic_init_min_features = 30;          // features seen in both images of the SfM pair
  double dynamic_init_min_accel_std_mps2 = 0.2;      // accelerometer variation over the window (excitation)
  double dynamic_init_max_gravity_error_mps2 = 1.0;  // | |g| - gravity_mps2 | of the unconstrained solve
  double dynamic_init_min_translation_m = 0.1;       // metric translation over the window, at least
  // The velocity the alignment finds must be known to this fraction of the speed (plus the velocity floor
  // below): a start at constant velocity leaves the scale unobservable and is refused, not guessed.
  double dynamic_init_max_speed_sigma_ratio = 0.1;
  double dynamic_init_min_sigma_tilt_rad = 0.01;  // floor of the roll/pitch sigma handed to the filter
  double dynamic_init_min_sigma_vel_mps = 0.05;   // floor of the velocity sigma
  double dynamic_init_min_sigma_gyro_bias_radps = 0.002;  // floor of the gyro bias sigma

  // The keys, in order, for loading, printing and the JSON echo (Self is EkfConfig or const EkfConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("window_size", self.window_size);
    v("clone_every_n_frames", self.clone_every_n_frames);
    v("init_mode", self.init_mode);
    v("gravity_mps2", self.gravity_mps2);
    v("max_features", self.max_features);
    v("image_blur_sigma_px", self.image_blur_sigma_px);
    v("grid_cols", self.grid_cols);
    v("grid_rows", self.grid_rows);
    v("min_feature_distance_px", self.min_feature_distance_px);
    v("redetect_min_missing", self.redetect_min_missing);
    v("empty_cell_retry_frames", self.empty_cell_retry_frames);
    v("shi_tomasi_quality", self.shi_tomasi_quality);
    v("shi_tomasi_block_size", self.shi_tomasi_block_size);
    v("corner_noise_factor", self.corner_noise_factor);
    v("klt_window_px", self.klt_window_px);
    v("klt_pyramid_levels", self.klt_pyramid_levels);
    v("klt_max_iterations", self.klt_max_iterations);
    v("klt_epsilon", self.klt_epsilon);
    v("klt_predict_rotation", self.klt_predict_rotation);
    v("klt_check_pyramid_levels", self.klt_check_pyramid_levels);
    v("fb_check_max_px", self.fb_check_max_px);
    v("ransac_threshold_px", self.ransac_threshold_px);
    v("ransac_confidence", self.ransac_confidence);
    v("border_px", self.border_px);
    v("pixel_sigma_px", self.pixel_sigma_px);
    v("chi2_quantile", self.chi2_quantile);
    v("first_estimate_jacobians", self.first_estimate_jacobians);
    v("min_track_length", self.min_track_length);
    v("max_update_features", self.max_update_features);
    v("min_depth_m", self.min_depth_m);
    v("max_depth_m", self.max_depth_m);
    v("max_triangulation_cond", self.max_triangulation_cond);
    v("triangulation_iterations", self.triangulation_iterations);
    v("triangulation_max_reproj_sigma", self.triangulation_max_reproj_sigma);
    v("zupt_enabled", self.zupt_enabled);
    v("zupt_max_disparity_px", self.zupt_max_disparity_px);
    v("zupt_min_features", self.zupt_min_features);
    v("zupt_sigma_mps", self.zupt_sigma_mps);
    v("gyro_noise_density", self.gyro_noise_density);
    v("gyro_random_walk", self.gyro_random_walk);
    v("accel_noise_density", self.accel_noise_density);
    v("accel_random_walk", self.accel_random_walk);
    v("imu_noise_inflation", self.imu_noise_inflation);
    v("init_sigma_rot_rad", self.init_sigma_rot_rad);
    v("init_sigma_pos_m", self.init_sigma_pos_m);
    v("init_sigma_vel_mps", self.init_sigma_vel_mps);
    v("init_sigma_gyro_bias_radps", self.init_sigma_gyro_bias_radps);
    v("init_sigma_accel_bias_mps2", self.init_sigma_accel_bias_mps2);
    v("init_sigma_yaw_rad", self.init_sigma_yaw_rad);
    v("static_window_s", self.static_window_s);
    v("static_lowpass_s", self.static_lowpass_s);
    v("static_excitation_sigmas", self.static_excitation_sigmas);
    v("static_max_disparity_px", self.static_max_disparity_px);
    v("max_init_s", self.max_init_s);
    v("min_tracked_share", self.min_tracked_share);
    v("lost_min_features", self.lost_min_features);
    v("lost_max_frames", self.lost_max_frames);
    v("max_position_sigma_m", self.max_position_sigma_m);
    v("dynamic_init_window_s", self.dynamic_init_window_s);
    v("dynamic_init_min_parallax_px", self.dynamic_init_min_parallax_px);
    v("dynamic_init_min_features", self.dynamic_init_min_features);
    v("dynamic_init_min_accel_std_mps2", self.dynamic_init_min_accel_std_mps2);
    v("dynamic_init_max_gravity_error_mps2", self.dynamic_init_max_gravity_error_mps2);
    v("dynamic_init_min_translation_m", self.dynamic_init_min_translation_m);
    v("dynamic_init_max_speed_sigma_ratio", self.dynamic_init_max_speed_sigma_ratio);
    v("dynamic_init_min_sigma_tilt_rad", self.dynamic_init_min_sigma_tilt_rad);
    v("dynamic_init_min_sigma_vel_mps", self.dynamic_init_min_sigma_vel_mps);
    v("dynamic_init_min_sigma_gyro_bias_radps", self.dynamic_init_min_sigma_gyro_bias_radps);
  }
  // Throws ConfigError naming the key ("ekf.<key>") and what is allowed.
  void validate() const;
};

}  // namespace loopgate
