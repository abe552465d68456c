// The `drift` odometry source: ground truth corrupted by a seeded random walk, driven by the distance
// travelled d between frames (so the error grows with distance like visual odometry drift):
//   heading  psi_k = psi_{k-1} + N(0, sigma_psi^2 d)     (rotation about the world axis a)
//   scale    s_k   = s_{k-1}   + N(0, sigma_s^2 d)
//   position p^_k  = p^_{k-1} + (1 + s_k) Exp(psi_k a) (p_k - p_{k-1}) + N(0, sigma_p^2 d I)
//   attitude R^_k  = Exp(psi_k a) R_k
// The covariance propagates the same model linearised about the truth, with the state
// x = [dp (3), psi, s]: psi and s gain sigma^2 d, then dp_k = dp_{k-1} + (a x dp) psi_k + dp s_k + w.
// Position block = Cov(dp) + initial_sigma_m^2 I; rotation block (right perturbation of T_w_b) =
// var(psi) (R^T a)(R^T a)^T + initial_sigma_rad^2 I; cross terms from Cov(dp, psi). The step covariance
// (OdometryOutput::step_cov) is the relative pose's: position noise, the scale's marginal on the step and
// the heading increment.
#pragma once

#include <Eigen/Core>
#include <random>

#include "stages/odometry/odometry_source.hpp"

namespace loopgate {

class DriftOdometry : public OdometrySource {
 public:
  // `axis_w`: the heading axis in the world frame (normalised here).
  DriftOdometry(const OdometryConfig& config, const Eigen::Vector3d& axis_w);

  const char* name() const override { return "drift"; }
  bool needs_ground_truth() const override { return true; }
  OdometryOutput process(const OdometryInput& input) override;

  // The drift state (for tests): heading error (rad), scale error, 5x5 covariance of [dp, psi, s].
  double heading_error_rad() const { return psi_rad_; }
  double scale_error() const { return scale_; }
  const Eigen::Matrix<double, 5, 5>& drift_covariance() const { return cov_; }
  double distance_m() const { return distance_m_; }

 private:
  OdometryConfig config_;
  Eigen::Vector3d axis_w_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  bool initialised_ = false;
  bool previous_tracked_ = false;  // the previous frame had an estimate (its step covariance is known)
  Eigen::Isometry3d last_true_T_w_b_ = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d estimate_T_w_b_ = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> last_cov_ = Eigen::Matrix<double, 6, 6>::Zero();
  double psi_rad_ = 0;
  double scale_ = 0;
  double distance_m_ = 0;
  Eigen::Matrix<double, 5, 5> cov_ = Eigen::Matrix<double, 5, 5>::Zero();
};

}  // namespace loopgate
