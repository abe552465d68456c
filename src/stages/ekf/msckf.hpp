// The MSCKF filter (docs/ekf.md): IMU error state + a sliding window of cloned IMU poses,
// fed with feature observations in undistorted normalised camera coordinates. No images here: the KLT
// front end (FeatureTracker) or a simulation produces the observations, so the filter can be tested alone.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <deque>
#include <span>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/pose_covariance.hpp"
#include "core/types.hpp"
#include "stages/ekf/chi_square.hpp"
#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/imu_propagator.hpp"

namespace loopgate {

// One observation of a feature in the current image: undistorted normalised coordinates (x/z, y/z).
struct FeatureObservation {
  std::uint64_t id = 0;
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
};

// A cloned IMU pose of the window. Error state: [dtheta (right), dp]. The first estimate (the pose when
// cloned, before any update) is kept for first-estimate Jacobians (config.first_estimate_jacobians).
struct PoseClone {
  std::uint64_t id = 0;
  Timestamp t_ns = 0;
  Eigen::Quaterniond q_w_i = Eigen::Quaterniond::Identity();
  Eigen::Vector3d p_w_m = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_w_i_fej = Eigen::Quaterniond::Identity();
  Eigen::Vector3d p_w_m_fej = Eigen::Vector3d::Zero();
};

struct MsckfUpdateStats {
  int candidate_features = 0;
  int used_features = 0;
  int rejected_triangulation = 0;
  int rejected_chi2 = 0;
  int rows = 0;  // measurement rows after null-space projection (before QR compression)
};

class Msckf {
 public:
  // `T_i_c`: camera -> IMU. The filter uses config.window_size, the update and triangulation keys, and
  // pixel_sigma_px / focal_px as the observation noise in normalised coordinates.
  Msckf(const EkfConfig& config, const ImuNoise& noise, const Eigen::Isometry3d& T_i_c, double focal_px);

  // (Re)starts the filter at `state` with the 15 x 15 covariance `cov` (empty window, no features).
  void initialize(const ImuState& state, const ImuMatrix& cov);
  void reset();
  bool initialized() const { return initialized_; }

  // Propagates to t_ns with `imu`, clones the pose, adds `observations`, updates with the features whose
  // track ended or spans the whole window, and marginalises the oldest clone when the window is full.
  MsckfUpdateStats process_frame(Timestamp t_ns, std::span<const ImuSample> imu,
                                 const std::vector<FeatureObservation>& observations);

  // Zero-velocity pseudo-measurement v_w = 0 with standard deviation sigma_mps (standstill).
  void zero_velocity_update(double sigma_mps);

  // Propagation only (state and covariance), e.g. between frames; no clone.
  void propagate(std::span<const ImuSample> imu, Timestamp t_ns);

  const ImuState& state() const { return state_; }
  const Eigen::MatrixXd& covariance() const { return P_; }
  const std::deque<PoseClone>& clones() const { return clones_; }
  std::size_t feature_count() const { return features_.size(); }

  // False when the state or covariance is not finite or not positive definite (reason set).
  bool healthy(std::string* reason) const;

  // Pose of the body frame (T_b_i: IMU -> body) with the 6 x 6 covariance [position, rotation (right)].
  PoseEstimate pose_estimate(const Eigen::Isometry3d& T_b_i) const;

  // The body pose now relative to the body pose of clone `index` of clones() (T_r_b), and its covariance
  // from the joint covariance of the two (core/pose_covariance.hpp's convention: position in r's body frame,
  // rotation a right perturbation in the current body frame).
  std::pair<Eigen::Isometry3d, PoseCov> relative_pose(std::size_t index,
                                                      const Eigen::Isometry3d& T_b_i) const;

 private:
  struct FeatureTrack {
    std::vector<std::uint64_t> clone_ids;
    std::vector<Eigen::Vector2d> xy;
  };

  void augment(std::uint64_t clone_id);
  void marginalize_oldest();
  MsckfUpdateStats update(const std::vector<std::uint64_t>& feature_ids);
  bool triangulate(const FeatureTrack& track, Eigen::Vector3d* p_w_f) const;
  // Null-space projected Jacobian and residual of one feature; false when a depth is not positive. The
  // Jacobian is w.r.t. the clone part of the state only (the IMU state does not enter the measurement):
  // H0 has 6 * clones_.size() columns, clone k at columns 6k.
  bool feature_jacobian(const FeatureTrack& track, const Eigen::Vector3d& p_w_f, Eigen::MatrixXd* H0,
                        Eigen::VectorXd* r0) const;
  // EKF update with a Jacobian that is zero outside the columns [col0, col0 + H.cols()) of the state.
  void apply_update(Eigen::Index col0, const Eigen::MatrixXd& H, const Eigen::VectorXd& r, double variance);
  int clone_index(std::uint64_t clone_id) const;

  EkfConfig config_;
  ImuPropagator propagator_;
  Eigen::Matrix3d R_i_c_;
  Eigen::Vector3d p_i_c_;
  double sigma_normalized_;
  ChiSquareTable chi2_;

  bool initialized_ = false;
  ImuState state_;
  ImuState fej_;  // the IMU state as last propagated (before the update): linearisation point of Phi
  Eigen::MatrixXd P_;
  std::deque<PoseClone> clones_;
  std::unordered_map<std::uint64_t, FeatureTrack> features_;
  std::uint64_t next_clone_id_ = 0;
};

}  // namespace loopgate
