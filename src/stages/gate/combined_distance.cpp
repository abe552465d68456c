#include "stages/gate/combined_distance.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.hpp"

namespace loopgate {

double combined_distance(const Eigen::Vector3d& p_i_m, const Eigen::Matrix3d& P_i_m2,
                         const Eigen::Vector3d& p_j_m, const Eigen::Matrix3d& P_j_m2) {
  const Eigen::Vector3d dp_m = p_i_m - p_j_m;
  const Eigen::Matrix3d A_m2 = Eigen::Matrix3d::Identity() + P_i_m2 + P_j_m2;
  const Eigen::LLT<Eigen::Matrix3d> llt(A_m2);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::quiet_NaN();
  // dp^T A^-1 dp = |L^-1 dp|^2 with A = L L^T.
  const Eigen::Vector3d y = llt.matrixL().solve(dp_m);
  return std::sqrt(y.squaredNorm());
}

double max_eigenvalue_m2(const Eigen::Matrix3d& P_m2) {
  const Eigen::Matrix3d sym = 0.5 * (P_m2 + P_m2.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(sym, Eigen::EigenvaluesOnly);
  return solver.eigenvalues()(2);  // ascending order
}

double position_sigma_m(const Eigen::Matrix3d& P_m2, SigmaNorm sigma_norm) {
  switch (sigma_norm) {
    case SigmaNorm::kMaxEigen: return std::sqrt(std::max(0.0, max_eigenvalue_m2(P_m2)));
    case SigmaNorm::kTrace: return std::sqrt(std::max(0.0, P_m2.trace()));
  }
  throw ConfigError("gate.sigma_norm: not one of " + enum_choices(sigma_norm));
}

}  // namespace loopgate
