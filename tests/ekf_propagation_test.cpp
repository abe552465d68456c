#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <random>

#include "core/geometry.hpp"
#include "ekf_sim_support.hpp"
#include "stages/ekf/imu_propagator.hpp"

namespace loopgate {
namespace {

using ekf_test::CircleMotion;

ImuState truth_state(const CircleMotion& motion, double t) {
  ImuState s;
  s.t_ns = s_to_ns(t);
  s.q_w_i = Eigen::Quaterniond(motion.rotation(t));
  s.p_w_m = motion.position(t);
  s.v_w_mps = motion.velocity(t);
  return s;
}

ImuNoise euroc_noise() {
  return ImuNoise{1.6968e-04, 1.9393e-05, 2.0e-3, 3.0e-3};
}

TEST(EkfPropagation, NoiseFreeImuFollowsTheTruth) {
  const CircleMotion motion;
  std::mt19937_64 rng(1);
  Eigen::Vector3d bg = Eigen::Vector3d::Zero();
  Eigen::Vector3d ba = Eigen::Vector3d::Zero();
  const auto imu = ekf_test::make_imu(motion, 0.0, 10.0, 200.0, {}, &rng, &bg, &ba);
  const ImuPropagator propagator(euroc_noise(), motion.gravity_mps2);
  ImuState state = truth_state(motion, 0.0);
  ImuMatrix Phi;
  ImuMatrix Q;
  // Frame by frame at 20 Hz, as the filter does.
  for (int frame = 1; frame <= 200; ++frame) {
    const Timestamp t_ns = s_to_ns(0.05 * frame);
    ASSERT_TRUE(propagator.propagate(imu, t_ns, &state, &Phi, &Q));
    ASSERT_EQ(state.t_ns, t_ns);
  }
  const double t = 10.0;
  const double pos_err = (state.p_w_m - motion.position(t)).norm();
  const double vel_err = (state.v_w_mps - motion.velocity(t)).norm();
  const double rot_err = so3_log(state.q_w_i.toRotationMatrix().transpose() * motion.rotation(t)).norm();
  EXPECT_LT(pos_err, 0.01) << "position error after 10 s of noise-free IMU";
  EXPECT_LT(vel_err, 0.005);
  EXPECT_LT(rot_err, 1e-4);
  // The motion really moved (not a trivial pass): 10 s at 1.5 m/s on the circle.
  EXPECT_GT((motion.position(t) - motion.position(0.0)).norm(), 2.0);
}

TEST(EkfPropagation, CovarianceGrows) {
  const CircleMotion motion;
  std::mt19937_64 rng(2);
  Eigen::Vector3d bg = Eigen::Vector3d::Zero();
  Eigen::Vector3d ba = Eigen::Vector3d::Zero();
  const auto imu = ekf_test::make_imu(motion, 0.0, 5.0, 200.0, {}, &rng, &bg, &ba);
  const ImuPropagator propagator(euroc_noise(), motion.gravity_mps2);
  ImuState state = truth_state(motion, 0.0);
  ImuMatrix P = ImuMatrix::Identity() * 1e-6;
  double previous_pos_var = P.block<3, 3>(3, 3).trace();
  double previous_rot_var = P.block<3, 3>(0, 0).trace();
  for (int frame = 1; frame <= 50; ++frame) {
    ImuMatrix Phi;
    ImuMatrix Q;
    ASSERT_TRUE(propagator.propagate(imu, s_to_ns(0.1 * frame), &state, &Phi, &Q));
    P = Phi * P * Phi.transpose() + Q;
    const double pos_var = P.block<3, 3>(3, 3).trace();
    const double rot_var = P.block<3, 3>(0, 0).trace();
    EXPECT_GT(pos_var, previous_pos_var);
    EXPECT_GT(rot_var, previous_rot_var);
    previous_pos_var = pos_var;
    previous_rot_var = rot_var;
  }
  EXPECT_TRUE((P - P.transpose()).cwiseAbs().maxCoeff() < 1e-12);
  Eigen::SelfAdjointEigenSolver<ImuMatrix> eig(P);
  EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
  EXPECT_GT(previous_pos_var, 100 * 3e-6);
}

// Phi must predict how a small error at the start maps to the end (numerical Jacobian check).
TEST(EkfPropagation, TransitionMatchesNumericalJacobian) {
  const CircleMotion motion;
  std::mt19937_64 rng(3);
  Eigen::Vector3d bg = Eigen::Vector3d::Zero();
  Eigen::Vector3d ba = Eigen::Vector3d::Zero();
  const auto imu = ekf_test::make_imu(motion, 0.0, 0.5, 200.0, {}, &rng, &bg, &ba);
  const ImuPropagator propagator(euroc_noise(), motion.gravity_mps2);
  const ImuState start = truth_state(motion, 0.0);
  const Timestamp t_end = s_to_ns(0.2);
  ImuState nominal = start;
  ImuMatrix Phi;
  ImuMatrix Q;
  ASSERT_TRUE(propagator.propagate(imu, t_end, &nominal, &Phi, &Q));
  const double eps = 1e-6;
  for (int i = 0; i < kImuErrorDim; ++i) {
    Eigen::Matrix<double, kImuErrorDim, 1> dx = Eigen::Matrix<double, kImuErrorDim, 1>::Zero();
    dx(i) = eps;
    ImuState perturbed = start;
    perturbed.apply_correction(dx);
    ImuMatrix unused_phi;
    ImuMatrix unused_q;
    ASSERT_TRUE(propagator.propagate(imu, t_end, &perturbed, &unused_phi, &unused_q));
    Eigen::Matrix<double, kImuErrorDim, 1> d_end;
    d_end.segment<3>(0) =
        so3_log(nominal.q_w_i.toRotationMatrix().transpose() * perturbed.q_w_i.toRotationMatrix());
    d_end.segment<3>(3) = perturbed.p_w_m - nominal.p_w_m;
    d_end.segment<3>(6) = perturbed.v_w_mps - nominal.v_w_mps;
    d_end.segment<3>(9) = perturbed.gyro_bias_radps - nominal.gyro_bias_radps;
    d_end.segment<3>(12) = perturbed.accel_bias_mps2 - nominal.accel_bias_mps2;
    const Eigen::Matrix<double, kImuErrorDim, 1> numeric = d_end / eps;
    EXPECT_LT((numeric - Phi.col(i)).norm(), 2e-3 * (1.0 + Phi.col(i).norm())) << "column " << i << "\n"
                                                                               << numeric.transpose() << "\n"
                                                                               << Phi.col(i).transpose();
  }
}

TEST(EkfPropagation, SplittingTheIntervalGivesTheSameState) {
  const CircleMotion motion;
  std::mt19937_64 rng(4);
  Eigen::Vector3d bg = Eigen::Vector3d::Zero();
  Eigen::Vector3d ba = Eigen::Vector3d::Zero();
  const auto imu = ekf_test::make_imu(motion, 0.0, 1.0, 200.0, {}, &rng, &bg, &ba);
  const ImuPropagator propagator(euroc_noise(), motion.gravity_mps2);
  ImuState a = truth_state(motion, 0.0);
  ImuState b = a;
  ImuMatrix Phi;
  ImuMatrix Q;
  ASSERT_TRUE(propagator.propagate(imu, s_to_ns(0.8), &a, &Phi, &Q));
  ASSERT_TRUE(propagator.propagate(imu, s_to_ns(0.3), &b, &Phi, &Q));
  ASSERT_TRUE(propagator.propagate(imu, s_to_ns(0.8), &b, &Phi, &Q));
  EXPECT_LT((a.p_w_m - b.p_w_m).norm(), 1e-9);
  EXPECT_LT((a.v_w_mps - b.v_w_mps).norm(), 1e-9);
  EXPECT_FALSE(propagator.propagate({}, s_to_ns(0.9), &a, &Phi, &Q));
}

}  // namespace
}  // namespace loopgate
