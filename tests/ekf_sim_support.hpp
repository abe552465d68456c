// Analytic synthetic motion for the ekf tests: a circle of radius 3 m with a vertical sinusoid; body
// orientation R_w_i = Rz(psi(t)) Rx(phi(t)) so that angular rate and specific force are known exactly.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "core/types.hpp"

namespace loopgate::ekf_test {

struct CircleMotion {
  double radius_m = 3.0;
  double omega_radps = 0.5;  // yaw rate and angular speed on the circle
  double z_amp_m = 0.5;
  double z_freq_radps = 0.9;
  double roll_amp_rad = 0.15;
  double roll_freq_radps = 1.3;
  double gravity_mps2 = 9.81;

  Eigen::Vector3d position(double t) const {
    return {radius_m * std::cos(omega_radps * t), radius_m * std::sin(omega_radps * t),
            z_amp_m * std::sin(z_freq_radps * t)};
  }
  Eigen::Vector3d velocity(double t) const {
    return {-radius_m * omega_radps * std::sin(omega_radps * t),
            radius_m * omega_radps * std::cos(omega_radps * t),
            z_amp_m * z_freq_radps * std::cos(z_freq_radps * t)};
  }
  Eigen::Vector3d acceleration(double t) const {
    const double w2 = omega_radps * omega_radps;
    return {-radius_m * w2 * std::cos(omega_radps * t), -radius_m * w2 * std::sin(omega_radps * t),
            -z_amp_m * z_freq_radps * z_freq_radps * std::sin(z_freq_radps * t)};
  }
  double yaw(double t) const { return omega_radps * t; }
  double roll(double t) const { return roll_amp_rad * std::sin(roll_freq_radps * t); }
  double roll_rate(double t) const { return roll_amp_rad * roll_freq_radps * std::cos(roll_freq_radps * t); }

  Eigen::Matrix3d rotation(double t) const {
    return (Eigen::AngleAxisd(yaw(t), Eigen::Vector3d::UnitZ()) *
            Eigen::AngleAxisd(roll(t), Eigen::Vector3d::UnitX()))
        .toRotationMatrix();
  }
  // Body angular rate: Rx(phi)^T psi_dot e_z + phi_dot e_x.
  Eigen::Vector3d gyro(double t) const {
    const Eigen::Matrix3d Rx = Eigen::AngleAxisd(roll(t), Eigen::Vector3d::UnitX()).toRotationMatrix();
    return Rx.transpose() * Eigen::Vector3d(0.0, 0.0, omega_radps) + Eigen::Vector3d(roll_rate(t), 0.0, 0.0);
  }
  // Specific force in the body frame: R^T (a - g) with g = (0, 0, -gravity).
  Eigen::Vector3d accel(double t) const {
    return rotation(t).transpose() * (acceleration(t) + Eigen::Vector3d(0.0, 0.0, gravity_mps2));
  }
  Eigen::Isometry3d pose(double t) const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = rotation(t);
    T.translation() = position(t);
    return T;
  }
};

struct ImuNoiseSim {
  double gyro_noise_density = 0;
  double gyro_random_walk = 0;
  double accel_noise_density = 0;
  double accel_random_walk = 0;
};

// IMU samples at `rate_hz` on [t0, t1] (inclusive ends), with white noise and random-walk biases
// (continuous-time densities, discretised at the sample rate). Biases evolve in *gyro_bias / *accel_bias.
inline std::vector<ImuSample> make_imu(const CircleMotion& motion, double t0_s, double t1_s, double rate_hz,
                                       const ImuNoiseSim& noise, std::mt19937_64* rng,
                                       Eigen::Vector3d* gyro_bias, Eigen::Vector3d* accel_bias) {
  std::normal_distribution<double> n01(0.0, 1.0);
  auto randn3 = [&]() { return Eigen::Vector3d(n01(*rng), n01(*rng), n01(*rng)); };
  const double dt = 1.0 / rate_hz;
  std::vector<ImuSample> out;
  const auto count = static_cast<long>(std::llround((t1_s - t0_s) * rate_hz));
  for (long k = 0; k <= count; ++k) {
    const double t = t0_s + static_cast<double>(k) * dt;
    ImuSample s;
    s.t_ns = s_to_ns(t);
    s.gyro_radps = motion.gyro(t) + *gyro_bias + noise.gyro_noise_density / std::sqrt(dt) * randn3();
    s.accel_mps2 = motion.accel(t) + *accel_bias + noise.accel_noise_density / std::sqrt(dt) * randn3();
    *gyro_bias += noise.gyro_random_walk * std::sqrt(dt) * randn3();
    *accel_bias += noise.accel_random_walk * std::sqrt(dt) * randn3();
    out.push_back(s);
  }
  return out;
}

}  // namespace loopgate::ekf_test
