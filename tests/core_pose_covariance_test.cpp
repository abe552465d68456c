#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <random>

#include "core/geometry.hpp"
#include "core/pose_covariance.hpp"

namespace loopgate {
namespace {

Eigen::Isometry3d make_pose(const Eigen::Vector3d& axis_angle, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(axis_angle.norm(), axis_angle.normalized()).toRotationMatrix();
  T.translation() = t;
  return T;
}

PoseCov random_cov(std::mt19937_64* rng, double sigma_p, double sigma_r) {
  std::normal_distribution<double> n01(0.0, 1.0);
  PoseCov L = PoseCov::Zero();
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c <= r; ++c) L(r, c) = n01(*rng);
  PoseCov scale = PoseCov::Zero();
  scale.diagonal() << Eigen::Vector3d::Constant(sigma_p), Eigen::Vector3d::Constant(sigma_r);
  return scale * (L * L.transpose() / 6.0 + PoseCov::Identity()) * scale;
}

// T_true = (t + dp, R Exp(dtheta)): the convention of pose_covariance.hpp.
Eigen::Isometry3d perturb(const Eigen::Isometry3d& T, const Eigen::Matrix<double, 6, 1>& d) {
  Eigen::Isometry3d out = T;
  out.translation() += d.head<3>();
  out.linear() = T.rotation() * so3_exp(d.tail<3>());
  return out;
}

Eigen::Matrix<double, 6, 1> error(const Eigen::Isometry3d& T_est, const Eigen::Isometry3d& T_true) {
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = T_true.translation() - T_est.translation();
  e.tail<3>() = so3_log(T_est.rotation().transpose() * T_true.rotation());
  return e;
}

TEST(PoseCovariance, ComposeMatchesMonteCarlo) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01(0.0, 1.0);
  const Eigen::Isometry3d T_a_b = make_pose({0.1, -0.3, 0.8}, {2.0, -1.0, 0.5});
  const Eigen::Isometry3d T_b_c = make_pose({-0.4, 0.2, 0.3}, {1.5, 3.0, -0.7});
  const PoseCov cov_ab = random_cov(&rng, 0.01, 0.002);
  const PoseCov cov_bc = random_cov(&rng, 0.02, 0.001);
  const Eigen::Matrix<double, 6, 6> L_ab = cov_ab.llt().matrixL();
  const Eigen::Matrix<double, 6, 6> L_bc = cov_bc.llt().matrixL();
  const Eigen::Isometry3d T_a_c = T_a_b * T_b_c;
  constexpr int kSamples = 40000;
  PoseCov empirical = PoseCov::Zero();
  for (int s = 0; s < kSamples; ++s) {
    Eigen::Matrix<double, 6, 1> z1, z2;
    for (int i = 0; i < 6; ++i) {
      z1(i) = n01(rng);
      z2(i) = n01(rng);
    }
    const Eigen::Isometry3d T_true = perturb(T_a_b, L_ab * z1) * perturb(T_b_c, L_bc * z2);
    const Eigen::Matrix<double, 6, 1> e = error(T_a_c, T_true);
    empirical += e * e.transpose() / kSamples;
  }
  const PoseCov predicted = compose_pose_cov(T_a_b, cov_ab, T_b_c, cov_bc);
  // Whitened: the empirical covariance in the predicted one's metric is the identity up to sampling noise
  // (about sqrt(2 / kSamples) per entry).
  const Eigen::Matrix<double, 6, 6> L = predicted.llt().matrixL();
  const PoseCov whitened =
      L.triangularView<Eigen::Lower>().solve(L.triangularView<Eigen::Lower>().solve(empirical).transpose());
  EXPECT_LT((whitened - PoseCov::Identity()).cwiseAbs().maxCoeff(), 0.04) << whitened;
}

TEST(PoseCovariance, StepInvertsCompose) {
  std::mt19937_64 rng(3);
  const Eigen::Isometry3d T_r_a = make_pose({0.2, 0.1, -0.5}, {4.0, 1.0, 0.2});
  const Eigen::Isometry3d T_a_b = make_pose({0.05, -0.02, 0.1}, {0.8, 0.1, 0.0});
  const PoseCov cov_ra = random_cov(&rng, 0.05, 0.003);
  const PoseCov step = random_cov(&rng, 0.01, 0.0005);
  const PoseCov cov_rb = compose_pose_cov(T_r_a, cov_ra, T_a_b, step);
  const PoseCov recovered = step_pose_cov(T_r_a, cov_ra, T_r_a * T_a_b, cov_rb);
  EXPECT_LT((recovered - step).cwiseAbs().maxCoeff(), 1e-12 + 1e-9 * step.cwiseAbs().maxCoeff());
  // Composed from the identity with zero covariance, the step is itself.
  EXPECT_TRUE(compose_pose_cov(Eigen::Isometry3d::Identity(), PoseCov::Zero(), T_a_b, step).isApprox(step));
}

TEST(PoseCovariance, StepIsNeverNegative) {
  // An update between a and b made T_r_b more certain than T_r_a: the step is projected on the PSD matrices.
  const Eigen::Isometry3d T_r_a = make_pose({0.0, 0.0, 0.1}, {1.0, 0.0, 0.0});
  const Eigen::Isometry3d T_r_b = make_pose({0.0, 0.0, 0.2}, {2.0, 0.0, 0.0});
  const PoseCov big = 0.01 * PoseCov::Identity();
  const PoseCov small = 0.001 * PoseCov::Identity();
  const PoseCov step = step_pose_cov(T_r_a, big, T_r_b, small);
  const Eigen::SelfAdjointEigenSolver<PoseCov> eig(step);
  EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-15);
  EXPECT_TRUE(step.isApprox(step.transpose()));
}

TEST(PoseCovariance, ProjectPsdKeepsThePositivePart) {
  PoseCov m = PoseCov::Zero();
  m.diagonal() << 4.0, -1.0, 2.0, 0.0, -3.0, 1.0;
  const PoseCov projected = project_psd(m);
  PoseCov expected = PoseCov::Zero();
  expected.diagonal() << 4.0, 0.0, 2.0, 0.0, 0.0, 1.0;
  EXPECT_LT((projected - expected).cwiseAbs().maxCoeff(), 1e-12);
  // And in a rotated basis: the same eigenvalues.
  Eigen::Matrix<double, 6, 6> Q = Eigen::Matrix<double, 6, 6>::Identity();
  Q.topLeftCorner<3, 3>() = make_pose({0.3, -0.7, 0.2}, Eigen::Vector3d::Zero()).rotation();
  Q.bottomRightCorner<3, 3>() = make_pose({-0.1, 0.5, 0.9}, Eigen::Vector3d::Zero()).rotation();
  const PoseCov rotated = project_psd(Q * m * Q.transpose());
  EXPECT_LT((rotated - Q * expected * Q.transpose()).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace loopgate
