// The static initialiser of the ekf odometry (docs/ekf.md § How the filter starts): starts the filter when
// the platform is still, also while its rotors spin. "Still" is judged from the data of the last
// static_window_s: the accelerometer and gyro, low-passed by two moving averages of static_lowpass_s (rotor
// vibration at 50-200 Hz averages out, a motion of the platform does not), must not vary by more than
// static_excitation_sigmas times what white sensor noise alone leaves after that filter, and the tracked
// features must not move between images (the median over the window's images of their median feature
// motion below static_max_disparity_px). Then gravity is the
// mean specific force of the window (roll and pitch; yaw set to zero), the gyro bias the mean angular rate,
// the velocity zero; the accelerometer bias is left to the filter.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>

#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/imu_propagator.hpp"
#include "stages/ekf/initializer.hpp"

namespace loopgate {

// The numbers behind the last decision (NaN / -1 where not measured yet).
struct StaticExcitation {
  double window_s = 0.0;          // seconds of IMU data in the window
  double accel_mps2 = -1.0;       // largest per-axis spread (std) of the low-passed accelerometer
  double accel_limit_mps2 = 0.0;  // its threshold
  double gyro_radps = -1.0;       // the same for the gyro
  double gyro_limit_radps = 0.0;
  double disparity_px = -1.0;  // median over the window's images of their median feature motion (-1: none)
  double disparity_limit_px = 0.0;
  double gravity_mps2 = 0.0;  // norm of the mean specific force
};

class StaticInitializer {
 public:
  // `noise`: the filter's IMU noise densities (effective_imu_noise: sensor.yaml times imu_noise_inflation);
  // `focal_px`: the mean focal length, to express feature motion in pixels. Throws ConfigError for an
  // invalid config or a noise density <= 0.
  StaticInitializer(const EkfConfig& config, const ImuNoise& noise, double focal_px);

  // One image. The initial state when the last static_window_s were still, else nullopt (status() says why).
  std::optional<InitialState> add_frame(const InitFrame& frame);
  // Why it has not initialised yet, with the numbers ("static: ..."), or what it found.
  const std::string& status() const { return status_; }
  const StaticExcitation& excitation() const { return last_; }
  // Forgets every sample and image (before a re-initialisation).
  void reset();

  // Spread (std) that white noise of continuous density `density` keeps after two moving averages of
  // `lowpass_s` each: density * sqrt(2 / (3 lowpass_s)), whatever the sample rate.
  static double lowpassed_noise_std(double density, double lowpass_s);

 private:
  EkfConfig config_;
  ImuNoise noise_;
  double focal_px_;
  std::deque<ImuSample> samples_;
  struct ImageMotion {
    Timestamp t_ns = 0;
    double disparity_px = -1.0;  // median feature motion since the previous image (-1: unknown)
  };
  std::deque<ImageMotion> images_;
  std::unordered_map<std::uint64_t, Eigen::Vector2d> previous_xy_;
  std::size_t frames_ = 0;
  StaticExcitation last_;
  std::string status_ = "static: no image yet";
};

}  // namespace loopgate
