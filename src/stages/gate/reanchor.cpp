#include "stages/gate/reanchor.hpp"

#include <Eigen/Eigenvalues>

namespace loopgate {

Eigen::Matrix3d psd_part(const Eigen::Matrix3d& P_m2, double tolerance_m2, bool& clamped) {
  const Eigen::Matrix3d sym_m2 = 0.5 * (P_m2 + P_m2.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sym_m2);
  const Eigen::Vector3d values_m2 = eig.eigenvalues();
  clamped = values_m2.minCoeff() < -tolerance_m2;
  if (values_m2.minCoeff() >= 0.0) return sym_m2;
  const Eigen::Matrix3d& V = eig.eigenvectors();
  const Eigen::Matrix3d out_m2 = V * values_m2.cwiseMax(0.0).asDiagonal() * V.transpose();
  return 0.5 * (out_m2 + out_m2.transpose());
}

ReanchoredPose reanchor(const LoopAnchor& anchor, const Eigen::Isometry3d& T_w_i_odo,
                        const Eigen::Matrix3d& P_i_odo_m2) {
  constexpr double kClampToleranceM2 = 1e-12;
  const Eigen::Isometry3d T_c = anchor.T_w_r * anchor.T_r_q * anchor.T_w_q_odo.inverse();
  const Eigen::Matrix3d R_c = T_c.rotation();
  const Eigen::Matrix3d R_w_r = anchor.T_w_r.rotation();
  ReanchoredPose out;
  out.T_w_i = T_c * T_w_i_odo;
  const Eigen::Matrix3d growth_m2 =
      psd_part(P_i_odo_m2 - anchor.P_q_odo_m2, kClampToleranceM2, out.growth_clamped);
  const Eigen::Matrix3d P_m2 =
      anchor.P_r_m2 + R_w_r * anchor.P_loop_r_m2 * R_w_r.transpose() + R_c * growth_m2 * R_c.transpose();
  out.P_m2 = 0.5 * (P_m2 + P_m2.transpose());
  return out;
}

}  // namespace loopgate
