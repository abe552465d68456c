#include "stages/ekf/imu_propagator.hpp"

#include "core/geometry.hpp"

namespace loopgate {

using I = ImuErrorIndex;

void ImuState::apply_correction(const Eigen::Matrix<double, kImuErrorDim, 1>& dx) {
  q_w_i = (q_w_i * so3_exp_quat(dx.segment<3>(I::kTheta))).normalized();
  p_w_m += dx.segment<3>(I::kPos);
  v_w_mps += dx.segment<3>(I::kVel);
  gyro_bias_radps += dx.segment<3>(I::kGyroBias);
  accel_bias_mps2 += dx.segment<3>(I::kAccelBias);
}

ImuPropagator::ImuPropagator(const ImuNoise& noise, double gravity_mps2)
    : noise_(noise), gravity_w_(0.0, 0.0, -gravity_mps2) {}

bool ImuPropagator::propagate(std::span<const ImuSample> samples, Timestamp t_end_ns, ImuState* state,
                              ImuMatrix* Phi, ImuMatrix* Q) const {
  Phi->setIdentity();
  Q->setZero();
  if (samples.empty()) return false;
  // Reading in force at the state time: the last sample at or before it, else the first one.
  std::size_t next = 0;
  while (next < samples.size() && samples[next].t_ns <= state->t_ns) ++next;
  ImuSample previous = next > 0 ? samples[next - 1] : samples[0];
  previous.t_ns = state->t_ns;
  for (; next < samples.size() && state->t_ns < t_end_ns; ++next) {
    ImuSample current = samples[next];
    if (current.t_ns > t_end_ns) {
      // Interpolate the reading to the end time.
      const double f =
          static_cast<double>(t_end_ns - previous.t_ns) / static_cast<double>(current.t_ns - previous.t_ns);
      current.gyro_radps = previous.gyro_radps + f * (current.gyro_radps - previous.gyro_radps);
      current.accel_mps2 = previous.accel_mps2 + f * (current.accel_mps2 - previous.accel_mps2);
      current.t_ns = t_end_ns;
    }
    const double dt_s = ns_to_s(current.t_ns - state->t_ns);
    if (dt_s > 0.0) step(previous, current, dt_s, state, Phi, Q);
    state->t_ns = current.t_ns;
    previous = current;
  }
  if (state->t_ns < t_end_ns) {
    ImuSample hold = previous;
    hold.t_ns = t_end_ns;
    step(previous, hold, ns_to_s(t_end_ns - state->t_ns), state, Phi, Q);
    state->t_ns = t_end_ns;
  }
  return true;
}

void ImuPropagator::step(const ImuSample& s0, const ImuSample& s1, double dt_s, ImuState* state,
                         ImuMatrix* Phi, ImuMatrix* Q) const {
  const Eigen::Vector3d w0 = s0.gyro_radps - state->gyro_bias_radps;
  const Eigen::Vector3d w1 = s1.gyro_radps - state->gyro_bias_radps;
  const Eigen::Vector3d a0 = s0.accel_mps2 - state->accel_bias_mps2;
  const Eigen::Vector3d a1 = s1.accel_mps2 - state->accel_bias_mps2;
  const Eigen::Vector3d w_mid = 0.5 * (w0 + w1);
  const Eigen::Vector3d a_mid = 0.5 * (a0 + a1);

  const Eigen::Matrix3d R0 = state->q_w_i.toRotationMatrix();
  const Eigen::Vector3d phi = w_mid * dt_s;
  const Eigen::Quaterniond dq = so3_exp_quat(phi);
  const Eigen::Quaterniond q1 = (state->q_w_i * dq).normalized();
  const Eigen::Matrix3d R1 = q1.toRotationMatrix();
  const Eigen::Vector3d acc_w0 = R0 * a0 + gravity_w_;
  const Eigen::Vector3d acc_w1 = R1 * a1 + gravity_w_;

  // Error-state transition over the step (first order, rotation block exact).
  const Eigen::Matrix3d R_mid = (state->q_w_i * so3_exp_quat(0.5 * phi)).toRotationMatrix();
  const Eigen::Matrix3d Ra_skew = R_mid * skew(a_mid);
  ImuMatrix F = ImuMatrix::Identity();
  F.block<3, 3>(I::kTheta, I::kTheta) = dq.toRotationMatrix().transpose();
  F.block<3, 3>(I::kTheta, I::kGyroBias) = -so3_right_jacobian(phi) * dt_s;
  F.block<3, 3>(I::kPos, I::kTheta) = -0.5 * Ra_skew * dt_s * dt_s;
  F.block<3, 3>(I::kPos, I::kVel) = Eigen::Matrix3d::Identity() * dt_s;
  F.block<3, 3>(I::kPos, I::kAccelBias) = -0.5 * R_mid * dt_s * dt_s;
  F.block<3, 3>(I::kVel, I::kTheta) = -Ra_skew * dt_s;
  F.block<3, 3>(I::kVel, I::kAccelBias) = -R_mid * dt_s;
  // A gyro-bias error tilts the attitude within the step already (second-order terms).
  F.block<3, 3>(I::kVel, I::kGyroBias) = 0.5 * Ra_skew * dt_s * dt_s;
  F.block<3, 3>(I::kPos, I::kGyroBias) = Ra_skew * dt_s * dt_s * dt_s / 6.0;

  // Discrete process noise from the continuous densities.
  const double sg2 = noise_.gyro_noise_density * noise_.gyro_noise_density;
  const double sa2 = noise_.accel_noise_density * noise_.accel_noise_density;
  const double swg2 = noise_.gyro_random_walk * noise_.gyro_random_walk;
  const double swa2 = noise_.accel_random_walk * noise_.accel_random_walk;
  ImuMatrix Qd = ImuMatrix::Zero();
  const Eigen::Matrix3d I3 = Eigen::Matrix3d::Identity();
  Qd.block<3, 3>(I::kTheta, I::kTheta) = sg2 * dt_s * I3;
  Qd.block<3, 3>(I::kVel, I::kVel) = sa2 * dt_s * I3;
  Qd.block<3, 3>(I::kPos, I::kPos) = sa2 * dt_s * dt_s * dt_s / 3.0 * I3;
  Qd.block<3, 3>(I::kPos, I::kVel) = sa2 * dt_s * dt_s / 2.0 * I3;
  Qd.block<3, 3>(I::kVel, I::kPos) = sa2 * dt_s * dt_s / 2.0 * I3;
  Qd.block<3, 3>(I::kGyroBias, I::kGyroBias) = swg2 * dt_s * I3;
  Qd.block<3, 3>(I::kAccelBias, I::kAccelBias) = swa2 * dt_s * I3;

  *Phi = F * (*Phi);
  *Q = F * (*Q) * F.transpose() + Qd;

  state->p_w_m += state->v_w_mps * dt_s + dt_s * dt_s * (acc_w0 / 3.0 + acc_w1 / 6.0);
  state->v_w_mps += 0.5 * (acc_w0 + acc_w1) * dt_s;
  state->q_w_i = q1;
  state->omega_i_radps = w1;
}

}  // namespace loopgate
