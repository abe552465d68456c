// Feedback of a verified loop closure into the pose gate (docs/gating.md § Gate feedback):
// VINS-Mono's relocalisation. A verified loop (query q, reference r) with relative body pose T_r_q says where
// frame q was in the map around r. A later frame i is re-anchored to the map through it,
//
//   T_w_i' = T_w_r * T_r_q * T_w_q(odo)^-1 * T_w_i(odo)          (T_c = T_w_r T_r_q T_w_q(odo)^-1: odometry
//                                                                  world -> map world at the loop)
//   P_i'   = P_r + R_w_r P_loop R_w_r^T + R_c [P_i(odo) - P_q(odo)]_+ R_c^T
//
// P_r is r's position covariance as the gate used it (the map), P_loop the loop's position covariance in r's
// body frame (verify's sigma model), and [P_i - P_q]_+ the odometry's covariance growth since q, projected on
// the positive semi-definite matrices (eigenvalues below 0 set to 0). The difference is a growth only where
// the covariance grew in every direction: a filter's (EKF) may shrink along an axis, and the drift source's
// is absolute, its heading error's lever arm turning with the route; a negative eigenvalue would make P_i'
// smaller than P_r + P_loop. The lever arm of r's heading error over q -> i is not modelled. No
// threads, no files.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace loopgate {

// What re-anchoring needs of the loop and of its two frames.
struct LoopAnchor {
  Eigen::Isometry3d T_w_q_odo = Eigen::Isometry3d::Identity();  // query q, the odometry's pose
  Eigen::Matrix3d P_q_odo_m2 = Eigen::Matrix3d::Zero();         // its position covariance
  Eigen::Isometry3d T_w_r = Eigen::Isometry3d::Identity();      // reference r as the gate used it (the map)
  Eigen::Matrix3d P_r_m2 = Eigen::Matrix3d::Zero();             // its position covariance as the gate used it
  Eigen::Isometry3d T_r_q = Eigen::Isometry3d::Identity();      // the verified loop: body q in body r
  Eigen::Matrix3d P_loop_r_m2 = Eigen::Matrix3d::Zero();        // its position covariance, in r's body frame
};

struct ReanchoredPose {
  Eigen::Isometry3d T_w_i = Eigen::Isometry3d::Identity();
  Eigen::Matrix3d P_m2 = Eigen::Matrix3d::Zero();  // symmetric, positive semi-definite
  bool growth_clamped = false;  // P_i - P_q had a negative eigenvalue (below -1e-12 m^2), set to 0
};

// Frame i's odometry pose (T_w_i_odo, position covariance P_i_odo_m2) re-anchored through `anchor`.
ReanchoredPose reanchor(const LoopAnchor& anchor, const Eigen::Isometry3d& T_w_i_odo,
                        const Eigen::Matrix3d& P_i_odo_m2);

// The symmetric part of P with negative eigenvalues set to 0 (the nearest PSD matrix in the Frobenius norm);
// `clamped` is set when an eigenvalue was below -tolerance_m2.
Eigen::Matrix3d psd_part(const Eigen::Matrix3d& P_m2, double tolerance_m2, bool& clamped);

}  // namespace loopgate
