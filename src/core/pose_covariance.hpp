// Covariances of relative poses, for odometry edges that carry the odometry's own uncertainty.
//
// Convention (the pose graph's residual, stages/posegraph): the error of a relative pose T_a_b is
// [dp; dtheta], dp the position error in a's frame, dtheta a right perturbation (in b's frame):
// T_a_b(true) = (t + dp, R Exp(dtheta)).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace loopgate {

using PoseCov = Eigen::Matrix<double, 6, 6>;

// The covariance of T_a_c = T_a_b T_b_c for independent errors of T_a_b (cov_ab) and T_b_c (cov_bc).
PoseCov compose_pose_cov(const Eigen::Isometry3d& T_a_b, const PoseCov& cov_ab,
                         const Eigen::Isometry3d& T_b_c, const PoseCov& cov_bc);

// The inverse of compose_pose_cov: given the covariances of T_r_a and T_r_b relative to one anchor r (b after
// a), the covariance of the step T_a_b that composes with T_r_a to give cov_rb, projected on the positive
// semi-definite matrices (negative eigenvalues set to 0: an update between a and b may have made T_r_b more
// certain than T_r_a plus a step can explain).
PoseCov step_pose_cov(const Eigen::Isometry3d& T_r_a, const PoseCov& cov_ra, const Eigen::Isometry3d& T_r_b,
                      const PoseCov& cov_rb);

// Symmetric part of `m` with its negative eigenvalues set to 0.
PoseCov project_psd(const PoseCov& m);

}  // namespace loopgate
