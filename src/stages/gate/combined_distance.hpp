// The combined Euclidean/Mahalanobis distance of the paper (eq. 8-9) and the gate threshold (eq. 10).
// docs/gating.md § The distance and the threshold.
#pragma once

#include <Eigen/Core>

#include "stages/gate/gate_config.hpp"

namespace loopgate {

// d = sqrt(dp^T (I + P_i + P_j)^-1 dp), dp = p_i - p_j, solved through a Cholesky (LLT) factorisation of
// I + P_i + P_j (never an explicit inverse). Positions in metres, covariances in m^2. The caller guarantees
// I + P_i + P_j is positive definite (PoseGate checks its input); returns NaN otherwise.
double combined_distance(const Eigen::Vector3d& p_i_m, const Eigen::Matrix3d& P_i_m2,
                         const Eigen::Vector3d& p_j_m, const Eigen::Matrix3d& P_j_m2);

// Largest eigenvalue of a symmetric 3 x 3 matrix (symmetrised first), in m^2.
double max_eigenvalue_m2(const Eigen::Matrix3d& P_m2);

// sigma_i of eq. 10: sqrt(lambda_max(P)) for max_eigen, sqrt(trace(P)) for trace (negative values from
// numerical noise count as 0).
double position_sigma_m(const Eigen::Matrix3d& P_m2, SigmaNorm sigma_norm);

// Threshold of eq. 10: confidence_scale * sigma_m + beta_m.
inline double gate_threshold_m(double sigma_m, double confidence_scale, double beta_m) {
  return confidence_scale * sigma_m + beta_m;
}

}  // namespace loopgate
