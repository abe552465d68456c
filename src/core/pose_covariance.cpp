#include "core/pose_covariance.hpp"

#include <Eigen/Eigenvalues>

#include "core/geometry.hpp"

namespace loopgate {

namespace {

// d(T_a_c) = A d(T_a_b) + B d(T_b_c) to first order:
//   dp_ac = dp_ab - R_ab [p_bc]x dtheta_ab + R_ab dp_bc,  dtheta_ac = R_bc^T dtheta_ab + dtheta_bc.
void compose_jacobians(const Eigen::Isometry3d& T_a_b, const Eigen::Isometry3d& T_b_c, PoseCov* A,
                       PoseCov* B) {
  const Eigen::Matrix3d R_ab = T_a_b.rotation();
  const Eigen::Matrix3d R_bc = T_b_c.rotation();
  A->setZero();
  A->topLeftCorner<3, 3>().setIdentity();
  A->topRightCorner<3, 3>() = -R_ab * skew(T_b_c.translation());
  A->bottomRightCorner<3, 3>() = R_bc.transpose();
  B->setZero();
  B->topLeftCorner<3, 3>() = R_ab;
  B->bottomRightCorner<3, 3>().setIdentity();
}

}  // namespace

PoseCov compose_pose_cov(const Eigen::Isometry3d& T_a_b, const PoseCov& cov_ab,
                         const Eigen::Isometry3d& T_b_c, const PoseCov& cov_bc) {
  PoseCov A, B;
  compose_jacobians(T_a_b, T_b_c, &A, &B);
  const PoseCov out = A * cov_ab * A.transpose() + B * cov_bc * B.transpose();
  return 0.5 * (out + out.transpose());
}

PoseCov step_pose_cov(const Eigen::Isometry3d& T_r_a, const PoseCov& cov_ra, const Eigen::Isometry3d& T_r_b,
                      const PoseCov& cov_rb) {
  const Eigen::Isometry3d T_a_b = T_r_a.inverse() * T_r_b;
  PoseCov A, B;
  compose_jacobians(T_r_a, T_a_b, &A, &B);
  // B is block-diagonal with a rotation and the identity: B^-1 = B^T.
  return project_psd(B.transpose() * (cov_rb - A * cov_ra * A.transpose()) * B);
}

PoseCov project_psd(const PoseCov& m) {
  const Eigen::SelfAdjointEigenSolver<PoseCov> eig(0.5 * (m + m.transpose()));
  const Eigen::Matrix<double, 6, 1> values = eig.eigenvalues().cwiseMax(0.0);
  return eig.eigenvectors() * values.asDiagonal() * eig.eigenvectors().transpose();
}

}  // namespace loopgate
