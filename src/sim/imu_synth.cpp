#include "sim/imu_synth.hpp"

#include <cmath>
#include <numbers>

#include "core/error.hpp"

namespace loopgate::sim {

void ImuSynthConfig::validate() const {
  if (!(rate_hz > 0.0 && rate_hz <= 100'000.0)) throw ConfigError("imu.rate_hz: must be in (0, 100000] Hz");
  if (!(gravity_mps2 >= 0.0)) throw ConfigError("imu.gravity_mps2 must be >= 0");
  if (!(initial_gyro_bias_sigma_radps >= 0.0) || !(initial_accel_bias_sigma_mps2 >= 0.0)) {
    throw ConfigError("imu.initial_*_bias_sigma must be >= 0");
  }
}

std::uint64_t GaussianRng::next_u64() {
  std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

double GaussianRng::next() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  constexpr double kTwoPow53 = 9007199254740992.0;
  // u1 in (0, 1], u2 in [0, 1)
  const double u1 = (static_cast<double>(next_u64() >> 11) + 1.0) / kTwoPow53;
  const double u2 = static_cast<double>(next_u64() >> 11) / kTwoPow53;
  const double radius = std::sqrt(-2.0 * std::log(u1));
  const double angle = 2.0 * std::numbers::pi * u2;
  spare_ = radius * std::sin(angle);
  has_spare_ = true;
  return radius * std::cos(angle);
}

ImuSample ideal_imu_sample(const TrajectoryState& state, const Eigen::Vector3d& up_w, double gravity_mps2) {
  const Eigen::Vector3d g_w = -gravity_mps2 * up_w.normalized();
  ImuSample sample;
  sample.t_ns = state.t_ns;
  sample.gyro_radps = state.omega_b_radps;
  sample.accel_mps2 = state.T_w_b.linear().transpose() * (state.a_w_mps2 - g_w);
  return sample;
}

SyntheticImu synthesize_imu(const SplineTrajectory& trajectory, const Eigen::Vector3d& up_w,
                            const ImuCalibration& calibration, const ImuSynthConfig& config,
                            std::uint64_t seed, Timestamp t_begin_ns, Timestamp t_end_ns) {
  config.validate();
  if (!calibration.T_b_i.isApprox(Eigen::Isometry3d::Identity(), 1e-12)) {
    throw ConfigError("imu synthesis: the IMU frame must be the body frame (T_b_i = identity)");
  }
  const double period_s = 1.0 / config.rate_hz;
  const double sqrt_rate = std::sqrt(config.rate_hz);
  const double gyro_sigma = calibration.gyro_noise_density * sqrt_rate;
  const double accel_sigma = calibration.accel_noise_density * sqrt_rate;
  const double gyro_bias_step = calibration.gyro_random_walk / sqrt_rate;
  const double accel_bias_step = calibration.accel_random_walk / sqrt_rate;

  GaussianRng rng(seed);
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  if (config.add_noise) {
    b_g = config.initial_gyro_bias_sigma_radps * rng.next3();
    b_a = config.initial_accel_bias_sigma_mps2 * rng.next3();
  }

  SyntheticImu out;
  for (std::int64_t k = 0;; ++k) {
    const Timestamp t_ns = t_begin_ns + s_to_ns(static_cast<double>(k) * period_s);
    if (t_ns > t_end_ns) break;
    ImuSample sample = ideal_imu_sample(trajectory.evaluate(t_ns), up_w, config.gravity_mps2);
    if (config.add_noise) {
      if (k > 0) {
        b_g += gyro_bias_step * rng.next3();
        b_a += accel_bias_step * rng.next3();
      }
      sample.gyro_radps += b_g + gyro_sigma * rng.next3();
      sample.accel_mps2 += b_a + accel_sigma * rng.next3();
    }
    out.samples.push_back(sample);
    out.gyro_bias_radps.push_back(b_g);
    out.accel_bias_mps2.push_back(b_a);
  }
  return out;
}

}  // namespace loopgate::sim
