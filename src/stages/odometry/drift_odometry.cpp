#include "stages/odometry/drift_odometry.hpp"

#include <cmath>

#include "core/geometry.hpp"

namespace loopgate {

DriftOdometry::DriftOdometry(const OdometryConfig& config, const Eigen::Vector3d& axis_w)
    : config_(config), axis_w_(axis_w.normalized()), rng_(static_cast<std::uint64_t>(config.seed)) {}

OdometryOutput DriftOdometry::process(const OdometryInput& input) {
  OdometryOutput out;
  out.pose.t_ns = input.t_ns;
  if (!input.T_w_b_true) {
    // No truth at this frame: hold the last estimate (never a made-up pose), report lost.
    out.pose.T_w_b = estimate_T_w_b_;
    out.pose.cov = last_cov_;
    out.pose.status = OdometryStatus::kLost;
    out.reason = "no ground truth at this frame";
    previous_tracked_ = false;
    return out;
  }
  const Eigen::Isometry3d& T_true = *input.T_w_b_true;
  if (!initialised_) {
    initialised_ = true;
    estimate_T_w_b_ = T_true;
  } else {
    const Eigen::Vector3d delta_p = T_true.translation() - last_true_T_w_b_.translation();
    const double d_m = delta_p.norm();
    const double sqrt_d = std::sqrt(d_m);
    distance_m_ += d_m;
    // Random walks.
    psi_rad_ += config_.drift_heading_sigma_rad_per_sqrt_m * sqrt_d * normal_(rng_);
    scale_ += config_.drift_scale_sigma_per_sqrt_m * sqrt_d * normal_(rng_);
    const Eigen::Vector3d noise_p(normal_(rng_), normal_(rng_), normal_(rng_));
    const Eigen::Matrix3d R_drift = Eigen::AngleAxisd(psi_rad_, axis_w_).toRotationMatrix();
    estimate_T_w_b_.translation() +=
        (1.0 + scale_) * (R_drift * delta_p) + config_.drift_position_sigma_m_per_sqrt_m * sqrt_d * noise_p;
    // Covariance of the same model, linearised.
    const double var_psi_step = std::pow(config_.drift_heading_sigma_rad_per_sqrt_m, 2) * d_m;
    const double var_s_step = std::pow(config_.drift_scale_sigma_per_sqrt_m, 2) * d_m;
    const double var_p_step = std::pow(config_.drift_position_sigma_m_per_sqrt_m, 2) * d_m;
    cov_(3, 3) += var_psi_step;
    cov_(4, 4) += var_s_step;
    Eigen::Matrix<double, 5, 5> F = Eigen::Matrix<double, 5, 5>::Identity();
    F.block<3, 1>(0, 3) = skew(axis_w_) * delta_p;
    F.block<3, 1>(0, 4) = delta_p;
    cov_ = F * cov_ * F.transpose();
    cov_.topLeftCorner<3, 3>() += var_p_step * Eigen::Matrix3d::Identity();
    cov_ = 0.5 * (cov_ + cov_.transpose());
    if (previous_tracked_) {
      // The step from the previous estimate, in its body frame: the common heading error cancels; what is
      // left is this step's heading increment (about the axis), the scale error on the step (its marginal:
      // the scale is a random walk, so steps far apart are correlated, which independent edges do not say)
      // and the position noise.
      const Eigen::Matrix3d R_a = last_true_T_w_b_.rotation().transpose();  // world -> previous body
      const Eigen::Vector3d step_a = R_a * delta_p;
      const Eigen::Vector3d turn_a = R_a * axis_w_.cross(delta_p);
      const Eigen::Vector3d axis_b = T_true.rotation().transpose() * axis_w_;
      PoseCov step = PoseCov::Zero();
      step.topLeftCorner<3, 3>() = var_p_step * Eigen::Matrix3d::Identity() +
                                   cov_(4, 4) * step_a * step_a.transpose() +
                                   var_psi_step * turn_a * turn_a.transpose();
      step.bottomRightCorner<3, 3>() = var_psi_step * axis_b * axis_b.transpose();
      out.step_cov = step;
    }
  }
  last_true_T_w_b_ = T_true;
  const Eigen::Matrix3d R_drift = Eigen::AngleAxisd(psi_rad_, axis_w_).toRotationMatrix();
  estimate_T_w_b_.linear() = R_drift * T_true.rotation();

  const Eigen::Vector3d axis_b = T_true.rotation().transpose() * axis_w_;
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Zero();
  cov.topLeftCorner<3, 3>() =
      cov_.topLeftCorner<3, 3>() + std::pow(config_.initial_sigma_m, 2) * Eigen::Matrix3d::Identity();
  cov.bottomRightCorner<3, 3>() = cov_(3, 3) * axis_b * axis_b.transpose() +
                                  std::pow(config_.initial_sigma_rad, 2) * Eigen::Matrix3d::Identity();
  cov.topRightCorner<3, 3>() = cov_.block<3, 1>(0, 3) * axis_b.transpose();
  cov.bottomLeftCorner<3, 3>() = cov.topRightCorner<3, 3>().transpose();
  last_cov_ = cov;

  out.pose.T_w_b = estimate_T_w_b_;
  out.pose.cov = cov;
  out.pose.status = OdometryStatus::kTracking;
  previous_tracked_ = true;
  return out;
}

}  // namespace loopgate
