// IMU synthesis from a fitted trajectory: angular rate and specific force in the IMU (= body) frame at a
// fixed rate, plus EuRoC-style white noise and bias random walk, seeded and deterministic.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/types.hpp"
#include "sim/trajectory.hpp"

namespace loopgate::sim {

struct ImuSynthConfig {
  double rate_hz = 200.0;
  double gravity_mps2 = 9.81;
  bool add_noise = true;  // white noise + bias random walk from the ImuCalibration
  // Initial biases drawn once per run (zero-mean Gaussian, per axis).
  double initial_gyro_bias_sigma_radps = 0.0;
  double initial_accel_bias_sigma_mps2 = 0.0;

  // The keys, in order, for loading, printing and the JSON echo (Self is ImuSynthConfig or const
  // ImuSynthConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("rate_hz", self.rate_hz);
    v("gravity_mps2", self.gravity_mps2);
    v("add_noise", self.add_noise);
    v("initial_gyro_bias_sigma_radps", self.initial_gyro_bias_sigma_radps);
    v("initial_accel_bias_sigma_mps2", self.initial_accel_bias_sigma_mps2);
  }
  void validate() const;  // throws ConfigError
};

struct SyntheticImu {
  std::vector<ImuSample> samples;                // measured (noisy when add_noise)
  std::vector<Eigen::Vector3d> gyro_bias_radps;  // true bias at each sample
  std::vector<Eigen::Vector3d> accel_bias_mps2;  // true bias at each sample
};

// Noise-free IMU reading of a trajectory state: omega_b and a_b = R_w_b^T (a_w - g_w), g_w = -g * up_w.
ImuSample ideal_imu_sample(const TrajectoryState& state, const Eigen::Vector3d& up_w, double gravity_mps2);

// Samples at t_begin_ns + k / rate_hz for every such time <= t_end_ns. The IMU frame must coincide with
// the body frame (calibration.T_b_i identity; throws ConfigError otherwise). Noise per EuRoC convention:
// discrete white sigma = density * sqrt(rate), bias step sigma = random_walk / sqrt(rate).
SyntheticImu synthesize_imu(const SplineTrajectory& trajectory, const Eigen::Vector3d& up_w,
                            const ImuCalibration& calibration, const ImuSynthConfig& config,
                            std::uint64_t seed, Timestamp t_begin_ns, Timestamp t_end_ns);

// Deterministic standard-normal generator (splitmix64 + Box-Muller): same seed, same numbers on every
// platform with the same libm.
class GaussianRng {
 public:
  explicit GaussianRng(std::uint64_t seed) : state_(seed) {}
  double next();
  Eigen::Vector3d next3() {
    const double x = next();
    const double y = next();
    const double z = next();
    return {x, y, z};
  }
  std::uint64_t next_u64();

 private:
  std::uint64_t state_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace loopgate::sim
