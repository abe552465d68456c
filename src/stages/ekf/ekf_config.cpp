#include "stages/ekf/ekf_config.hpp"

#include <cmath>

#include "core/error.hpp"

namespace loopgate {
namespace {

void require(bool ok, const char* key, const char* what) {
  if (!ok) throw ConfigError(std::string("ekf.") + key + ": " + what);
}

bool positive(double x) {
  return std::isfinite(x) && x > 0.0;
}
bool non_negative(double x) {
  return std::isfinite(x) && x >= 0.0;
}

}  // namespace

void EkfConfig::validate() const {
  require(window_size >= 3 && window_size <= 50, "window_size", "must be in [3, 50]");
  require(clone_every_n_frames >= 1 && clone_every_n_frames <= 10, "clone_every_n_frames",
          "must be in [1, 10]");
  require(positive(gravity_mps2), "gravity_mps2", "must be > 0");
  // Upper bounds on counts, windows and pixel sizes: what makes sense for a feature tracker, so that no value
  // makes a run hang or exhaust memory.
  require(max_features >= 8 && max_features <= 10'000, "max_features", "must be in [8, 10000]");
  require(grid_cols >= 1 && grid_cols <= 100, "grid_cols", "must be in [1, 100]");
  require(grid_rows >= 1 && grid_rows <= 100, "grid_rows", "must be in [1, 100]");
  require(positive(min_feature_distance_px) && min_feature_distance_px <= 1000, "min_feature_distance_px",
          "must be in (0, 1000] px");
  require(non_negative(image_blur_sigma_px) && image_blur_sigma_px <= 20, "image_blur_sigma_px",
          "must be in [0, 20] px (0 = no smoothing)");
  require(non_negative(corner_noise_factor), "corner_noise_factor", "must be >= 0 (0 = off)");
  require(empty_cell_retry_frames >= 0 && empty_cell_retry_frames <= 100'000, "empty_cell_retry_frames",
          "must be in [0, 100000] frames");
  require(redetect_min_missing >= 1 && redetect_min_missing <= 10'000, "redetect_min_missing",
          "must be in [1, 10000]");
  require(shi_tomasi_quality > 0.0 && shi_tomasi_quality < 1.0, "shi_tomasi_quality", "must be in (0, 1)");
  require(shi_tomasi_block_size >= 3 && shi_tomasi_block_size <= 31, "shi_tomasi_block_size",
          "must be in [3, 31] px");
  require(klt_window_px >= 5 && klt_window_px <= 101 && klt_window_px % 2 == 1, "klt_window_px",
          "must be odd and in [5, 101] px");
  require(klt_pyramid_levels >= 0 && klt_pyramid_levels <= 8, "klt_pyramid_levels", "must be in [0, 8]");
  require(klt_check_pyramid_levels >= -1 && klt_check_pyramid_levels <= klt_pyramid_levels,
          "klt_check_pyramid_levels", "must be in [-1, klt_pyramid_levels] (-1: klt_pyramid_levels)");
  require(klt_max_iterations >= 1 && klt_max_iterations <= 1000, "klt_max_iterations",
          "must be in [1, 1000]");
  require(positive(klt_epsilon), "klt_epsilon", "must be > 0");
  require(positive(fb_check_max_px), "fb_check_max_px", "must be > 0");
  require(positive(ransac_threshold_px), "ransac_threshold_px", "must be > 0");
  require(ransac_confidence > 0.0 && ransac_confidence < 1.0, "ransac_confidence", "must be in (0, 1)");
  require(border_px >= 0 && border_px <= 1000, "border_px", "must be in [0, 1000] px");
  require(positive(pixel_sigma_px), "pixel_sigma_px", "must be > 0");
  require(chi2_quantile > 0.5 && chi2_quantile < 1.0, "chi2_quantile",
          "must be in (0.5, 1) (the upper quantile, e.g. 0.95)");
  require(min_track_length >= 2 && min_track_length <= 1000, "min_track_length",
          "must be in [2, 1000] frames");
  require(max_update_features >= 0 && max_update_features <= 10'000, "max_update_features",
          "must be in [0, 10000] (0 = no limit)");
  require(positive(min_depth_m), "min_depth_m", "must be > 0");
  require(std::isfinite(max_depth_m) && max_depth_m > min_depth_m, "max_depth_m", "must be > min_depth_m");
  require(max_triangulation_cond > 1.0, "max_triangulation_cond", "must be > 1");
  require(triangulation_iterations >= 1 && triangulation_iterations <= 1000, "triangulation_iterations",
          "must be in [1, 1000]");
  require(positive(triangulation_max_reproj_sigma), "triangulation_max_reproj_sigma", "must be > 0");
  require(positive(zupt_max_disparity_px), "zupt_max_disparity_px", "must be > 0");
  require(zupt_min_features >= 1 && zupt_min_features <= 10'000, "zupt_min_features",
          "must be in [1, 10000]");
  require(positive(zupt_sigma_mps), "zupt_sigma_mps", "must be > 0");
  require(non_negative(gyro_noise_density), "gyro_noise_density", "must be >= 0 (0 = from imu0 sensor.yaml)");
  require(non_negative(gyro_random_walk), "gyro_random_walk", "must be >= 0 (0 = from imu0 sensor.yaml)");
  require(non_negative(accel_noise_density), "accel_noise_density",
          "must be >= 0 (0 = from imu0 sensor.yaml)");
  require(non_negative(accel_random_walk), "accel_random_walk", "must be >= 0 (0 = from imu0 sensor.yaml)");
  require(positive(imu_noise_inflation), "imu_noise_inflation", "must be > 0");
  require(positive(init_sigma_rot_rad), "init_sigma_rot_rad", "must be > 0");
  require(positive(init_sigma_pos_m), "init_sigma_pos_m", "must be > 0");
  require(positive(init_sigma_vel_mps), "init_sigma_vel_mps", "must be > 0");
  require(positive(init_sigma_gyro_bias_radps), "init_sigma_gyro_bias_radps", "must be > 0");
  require(positive(init_sigma_accel_bias_mps2), "init_sigma_accel_bias_mps2", "must be > 0");
  require(positive(init_sigma_yaw_rad), "init_sigma_yaw_rad", "must be > 0");
  require(positive(static_window_s) && static_window_s <= 60, "static_window_s", "must be in (0, 60] s");
  require(positive(static_lowpass_s) && 2.0 * static_lowpass_s < static_window_s, "static_lowpass_s",
          "must be > 0 and below half of static_window_s (two moving averages of it fit the window)");
  require(positive(static_excitation_sigmas), "static_excitation_sigmas", "must be > 0");
  require(positive(static_max_disparity_px), "static_max_disparity_px", "must be > 0");
  require(positive(max_init_s), "max_init_s", "must be > 0 s");
  require(min_tracked_share >= 0.0 && min_tracked_share <= 1.0, "min_tracked_share", "must be in [0, 1]");
  require(lost_min_features >= 0 && lost_min_features <= 10'000, "lost_min_features",
          "must be in [0, 10000]");
  require(lost_max_frames >= 1 && lost_max_frames <= 1'000'000, "lost_max_frames",
          "must be in [1, 1000000] frames");
  require(positive(max_position_sigma_m), "max_position_sigma_m", "must be > 0");
  require(dynamic_init_window_s >= 0.2 && dynamic_init_window_s <= 30, "dynamic_init_window_s",
          "must be in [0.2, 30] s");
  require(non_negative(dynamic_init_min_parallax_px), "dynamic_init_min_parallax_px", "must be >= 0");
  require(dynamic_init_min_features >= 8 && dynamic_init_min_features <= 10'000, "dynamic_init_min_features",
          "must be in [8, 10000] (the essential matrix needs at least 5, RANSAC more)");
  require(non_negative(dynamic_init_min_accel_std_mps2), "dynamic_init_min_accel_std_mps2", "must be >= 0");
  require(positive(dynamic_init_max_gravity_error_mps2), "dynamic_init_max_gravity_error_mps2",
          "must be > 0");
  require(non_negative(dynamic_init_min_translation_m), "dynamic_init_min_translation_m", "must be >= 0");
  require(positive(dynamic_init_max_speed_sigma_ratio) && dynamic_init_max_speed_sigma_ratio <= 10.0,
          "dynamic_init_max_speed_sigma_ratio", "must be in (0, 10]");
  require(positive(dynamic_init_min_sigma_tilt_rad), "dynamic_init_min_sigma_tilt_rad", "must be > 0");
  require(positive(dynamic_init_min_sigma_vel_mps), "dynamic_init_min_sigma_vel_mps", "must be > 0");
  require(positive(dynamic_init_min_sigma_gyro_bias_radps), "dynamic_init_min_sigma_gyro_bias_radps",
          "must be > 0");
}

}  // namespace loopgate
