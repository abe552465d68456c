// IMU state and its propagation for the MSCKF (docs/ekf.md).
//
// Error state (15): [dtheta (right perturbation of R_w_i: R = R_hat Exp(dtheta)), dp_w, dv_w, dbg, dba].
// Noise densities follow the EuRoC (Kalibr) continuous-time convention.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <span>

#include "core/types.hpp"

namespace loopgate {

constexpr int kImuErrorDim = 15;
using ImuMatrix = Eigen::Matrix<double, kImuErrorDim, kImuErrorDim>;

// Indices of the blocks of the 15-dim IMU error state.
struct ImuErrorIndex {
  static constexpr int kTheta = 0;
  static constexpr int kPos = 3;
  static constexpr int kVel = 6;
  static constexpr int kGyroBias = 9;
  static constexpr int kAccelBias = 12;
};

struct ImuState {
  Timestamp t_ns = 0;
  Eigen::Quaterniond q_w_i = Eigen::Quaterniond::Identity();
  Eigen::Vector3d p_w_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d v_w_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d omega_i_radps =
      Eigen::Vector3d::Zero();  // last bias-corrected angular rate (not estimated)

  // Applies an error-state correction [dtheta, dp, dv, dbg, dba].
  void apply_correction(const Eigen::Matrix<double, kImuErrorDim, 1>& dx);
};

struct ImuNoise {
  double gyro_noise_density = 0;   // rad / s / sqrt(Hz)
  double gyro_random_walk = 0;     // rad / s^2 / sqrt(Hz)
  double accel_noise_density = 0;  // m / s^2 / sqrt(Hz)
  double accel_random_walk = 0;    // m / s^3 / sqrt(Hz)
};

// Propagates the nominal state and accumulates the transition matrix Phi and the process noise Q of the
// error state over a run of samples, so that P_new = Phi P Phi^T + Q.
class ImuPropagator {
 public:
  ImuPropagator(const ImuNoise& noise, double gravity_mps2);

  // Propagates `state` from state->t_ns to t_end_ns using `samples` (time-ordered). Samples at or before
  // the state time provide the starting reading; if the samples do not reach t_end_ns the last reading is
  // held. Integration is midpoint in rotation and trapezoidal in velocity between consecutive readings.
  // Returns false (state untouched) when there is no sample at all.
  bool propagate(std::span<const ImuSample> samples, Timestamp t_end_ns, ImuState* state, ImuMatrix* Phi,
                 ImuMatrix* Q) const;

  const Eigen::Vector3d& gravity_w() const { return gravity_w_; }

 private:
  void step(const ImuSample& s0, const ImuSample& s1, double dt_s, ImuState* state, ImuMatrix* Phi,
            ImuMatrix* Q) const;

  ImuNoise noise_;
  Eigen::Vector3d gravity_w_;
};

}  // namespace loopgate
