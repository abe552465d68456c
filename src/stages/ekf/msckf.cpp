#include "stages/ekf/msckf.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_set>

#include "core/geometry.hpp"

namespace loopgate {
namespace {

constexpr int kCloneDim = 6;
// Largest measurement dimension precomputed in the chi-square table (2 rows per clone of a full window).
int chi2_table_size(int window_size) {
  return 2 * (window_size + 1);
}

Eigen::Matrix<double, 2, 3> projection_jacobian(const Eigen::Vector3d& p_c) {
  const double inv_z = 1.0 / p_c.z();
  Eigen::Matrix<double, 2, 3> J;
  J << inv_z, 0.0, -p_c.x() * inv_z * inv_z, 0.0, inv_z, -p_c.y() * inv_z * inv_z;
  return J;
}

}  // namespace

Msckf::Msckf(const EkfConfig& config, const ImuNoise& noise, const Eigen::Isometry3d& T_i_c, double focal_px)
    : config_(config),
      propagator_(noise, config.gravity_mps2),
      R_i_c_(T_i_c.rotation()),
      p_i_c_(T_i_c.translation()),
      sigma_normalized_(config.pixel_sigma_px / focal_px),
      chi2_(config.chi2_quantile, chi2_table_size(config.window_size)) {}

void Msckf::initialize(const ImuState& state, const ImuMatrix& cov) {
  state_ = state;
  state_.q_w_i.normalize();
  fej_ = state_;
  P_ = cov;
  P_ = 0.5 * (P_ + P_.transpose()).eval();
  clones_.clear();
  features_.clear();
  initialized_ = true;
}

void Msckf::reset() {
  initialized_ = false;
  clones_.clear();
  features_.clear();
  P_.resize(0, 0);
}

void Msckf::propagate(std::span<const ImuSample> imu, Timestamp t_ns) {
  ImuMatrix Phi;
  ImuMatrix Q;
  const Timestamp t0_ns = state_.t_ns;
  if (!propagator_.propagate(imu, t_ns, &state_, &Phi, &Q)) {
    state_.t_ns = t_ns;  // nothing to integrate with: the state stays, time moves on
    fej_ = state_;
    return;
  }
  if (config_.first_estimate_jacobians) {
    // First-estimate Jacobians (Huang, Mourikis & Roumeliotis): the attitude columns of Phi in closed form
    // at the previous *propagated* state instead of the updated one, so that Phi maps the unobservable
    // directions (global position, yaw about gravity) of one linearisation point onto those of the next
    // and the filter gains no spurious yaw information. Right perturbation: dtheta_w = R dtheta.
    const double dt_s = ns_to_s(t_ns - t0_ns);
    const Eigen::Matrix3d R0 = fej_.q_w_i.toRotationMatrix();
    const Eigen::Matrix3d R1 = state_.q_w_i.toRotationMatrix();
    const Eigen::Vector3d& g = propagator_.gravity_w();
    using I = ImuErrorIndex;
    Phi.block<3, 3>(I::kTheta, I::kTheta) = R1.transpose() * R0;
    Phi.block<3, 3>(I::kVel, I::kTheta) = -skew(state_.v_w_mps - fej_.v_w_mps - g * dt_s) * R0;
    Phi.block<3, 3>(I::kPos, I::kTheta) =
        -skew(state_.p_w_m - fej_.p_w_m - fej_.v_w_mps * dt_s - 0.5 * g * dt_s * dt_s) * R0;
  }
  fej_ = state_;
  const Eigen::Index n = P_.rows();
  P_.topLeftCorner<kImuErrorDim, kImuErrorDim>() =
      Phi * P_.topLeftCorner<kImuErrorDim, kImuErrorDim>() * Phi.transpose() + Q;
  if (n > kImuErrorDim) {
    const Eigen::MatrixXd P_ic = Phi * P_.topRightCorner(kImuErrorDim, n - kImuErrorDim);
    P_.topRightCorner(kImuErrorDim, n - kImuErrorDim) = P_ic;
    P_.bottomLeftCorner(n - kImuErrorDim, kImuErrorDim) = P_ic.transpose();
  }
  P_ = 0.5 * (P_ + P_.transpose()).eval();
}

void Msckf::augment(std::uint64_t clone_id) {
  const Eigen::Index n = P_.rows();
  Eigen::MatrixXd P_new(n + kCloneDim, n + kCloneDim);
  P_new.topLeftCorner(n, n) = P_;
  // The clone error is [dtheta, dp] of the IMU state: rows 0..5.
  P_new.bottomLeftCorner(kCloneDim, n) = P_.topRows(kCloneDim);
  P_new.topRightCorner(n, kCloneDim) = P_.leftCols(kCloneDim);
  P_new.bottomRightCorner(kCloneDim, kCloneDim) = P_.topLeftCorner(kCloneDim, kCloneDim);
  P_ = std::move(P_new);
  clones_.push_back(PoseClone{clone_id, state_.t_ns, state_.q_w_i, state_.p_w_m, state_.q_w_i, state_.p_w_m});
}

void Msckf::marginalize_oldest() {
  if (clones_.empty()) return;
  const std::uint64_t oldest = clones_.front().id;
  const Eigen::Index n = P_.rows();
  const Eigen::Index start = kImuErrorDim;  // the oldest clone is the first one
  const Eigen::Index tail = n - start - kCloneDim;
  Eigen::MatrixXd P_new(n - kCloneDim, n - kCloneDim);
  P_new.topLeftCorner(start, start) = P_.topLeftCorner(start, start);
  P_new.topRightCorner(start, tail) = P_.topRightCorner(start, tail);
  P_new.bottomLeftCorner(tail, start) = P_.bottomLeftCorner(tail, start);
  P_new.bottomRightCorner(tail, tail) = P_.bottomRightCorner(tail, tail);
  P_ = std::move(P_new);
  clones_.pop_front();
  for (auto it = features_.begin(); it != features_.end();) {
    FeatureTrack& track = it->second;
    for (std::size_t k = 0; k < track.clone_ids.size();) {
      if (track.clone_ids[k] == oldest) {
        track.clone_ids.erase(track.clone_ids.begin() + static_cast<std::ptrdiff_t>(k));
        track.xy.erase(track.xy.begin() + static_cast<std::ptrdiff_t>(k));
      } else {
        ++k;
      }
    }
    it = track.clone_ids.empty() ? features_.erase(it) : std::next(it);
  }
}

int Msckf::clone_index(std::uint64_t clone_id) const {
  // Clone ids increase along the window.
  const auto it = std::lower_bound(clones_.begin(), clones_.end(), clone_id,
                                   [](const PoseClone& c, std::uint64_t id) { return c.id < id; });
  if (it == clones_.end() || it->id != clone_id) return -1;
  return static_cast<int>(it - clones_.begin());
}

MsckfUpdateStats Msckf::process_frame(Timestamp t_ns, std::span<const ImuSample> imu,
                                      const std::vector<FeatureObservation>& observations) {
  MsckfUpdateStats stats;
  if (!initialized_) return stats;
  propagate(imu, t_ns);
  const std::uint64_t clone_id = next_clone_id_++;
  augment(clone_id);

  std::unordered_set<std::uint64_t> current;
  current.reserve(observations.size());
  for (const FeatureObservation& obs : observations) {
    if (!current.insert(obs.id).second) continue;  // duplicate id in one frame: keep the first
    FeatureTrack& track = features_[obs.id];
    track.clone_ids.push_back(clone_id);
    track.xy.push_back(obs.xy);
  }

  const bool window_full = static_cast<int>(clones_.size()) > config_.window_size;
  const std::uint64_t oldest = clones_.front().id;
  std::vector<std::uint64_t> to_use;
  std::vector<std::uint64_t> to_drop;
  for (const auto& [id, track] : features_) {
    const bool long_enough = static_cast<int>(track.clone_ids.size()) >= config_.min_track_length;
    if (!current.contains(id)) {
      (long_enough ? to_use : to_drop).push_back(id);
    } else if (window_full && track.clone_ids.front() == oldest && long_enough) {
      to_use.push_back(id);
    }
  }
  // Deterministic order whatever the hash map does; the longest tracks first when the update is capped.
  std::sort(to_use.begin(), to_use.end(), [&](std::uint64_t a, std::uint64_t b) {
    const std::size_t la = features_[a].clone_ids.size();
    const std::size_t lb = features_[b].clone_ids.size();
    return la != lb ? la > lb : a < b;
  });
  if (config_.max_update_features > 0 && static_cast<int>(to_use.size()) > config_.max_update_features) {
    to_drop.insert(to_drop.end(), to_use.begin() + config_.max_update_features, to_use.end());
    to_use.resize(static_cast<std::size_t>(config_.max_update_features));
  }
  stats = update(to_use);
  for (std::uint64_t id : to_use) features_.erase(id);
  for (std::uint64_t id : to_drop) features_.erase(id);
  if (window_full) marginalize_oldest();
  return stats;
}

bool Msckf::triangulate(const FeatureTrack& track, Eigen::Vector3d* p_w_f) const {
  const std::size_t m = track.clone_ids.size();
  std::vector<Eigen::Matrix3d> R_w_c(m);
  std::vector<Eigen::Vector3d> p_w_c(m);
  for (std::size_t j = 0; j < m; ++j) {
    const int k = clone_index(track.clone_ids[j]);
    if (k < 0) return false;
    const Eigen::Matrix3d R_w_i = clones_[static_cast<std::size_t>(k)].q_w_i.toRotationMatrix();
    R_w_c[j] = R_w_i * R_i_c_;
    p_w_c[j] = clones_[static_cast<std::size_t>(k)].p_w_m + R_w_i * p_i_c_;
  }
  // Anchor: the first observation. Relative poses of the other cameras in the anchor frame.
  std::vector<Eigen::Matrix3d> R_cj_a(m);
  std::vector<Eigen::Vector3d> p_cj_a(m);
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (std::size_t j = 0; j < m; ++j) {
    const Eigen::Matrix3d R_a_cj = R_w_c[0].transpose() * R_w_c[j];
    const Eigen::Vector3d p_a_cj = R_w_c[0].transpose() * (p_w_c[j] - p_w_c[0]);
    R_cj_a[j] = R_a_cj.transpose();
    p_cj_a[j] = -R_a_cj.transpose() * p_a_cj;
    const Eigen::Vector3d bearing = (R_a_cj * track.xy[j].homogeneous()).normalized();
    const Eigen::Matrix3d N = Eigen::Matrix3d::Identity() - bearing * bearing.transpose();
    A += N;
    b += N * p_a_cj;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  const double ev_min = eig.eigenvalues()(0);
  const double ev_max = eig.eigenvalues()(2);
  if (!(ev_min > 0.0) || ev_max / ev_min > config_.max_triangulation_cond) return false;
  const Eigen::Vector3d p_a0 = A.ldlt().solve(b);
  if (!(p_a0.z() > config_.min_depth_m)) return false;

  // Gauss-Newton on the inverse-depth parameters (alpha, beta, rho) of the anchor frame.
  Eigen::Vector3d theta(p_a0.x() / p_a0.z(), p_a0.y() / p_a0.z(), 1.0 / p_a0.z());
  auto cost_of = [&](const Eigen::Vector3d& th, Eigen::Matrix3d* JtJ, Eigen::Vector3d* Jtr) {
    double cost = 0.0;
    if (JtJ != nullptr) {
      JtJ->setZero();
      Jtr->setZero();
    }
    for (std::size_t j = 0; j < m; ++j) {
      const Eigen::Vector3d h = R_cj_a[j] * Eigen::Vector3d(th.x(), th.y(), 1.0) + th.z() * p_cj_a[j];
      if (!(h.z() > 0.0)) return std::numeric_limits<double>::infinity();
      const Eigen::Vector2d e = track.xy[j] - h.head<2>() / h.z();
      cost += e.squaredNorm();
      if (JtJ != nullptr) {
        Eigen::Matrix3d dh;
        dh.col(0) = R_cj_a[j].col(0);
        dh.col(1) = R_cj_a[j].col(1);
        dh.col(2) = p_cj_a[j];
        const Eigen::Matrix<double, 2, 3> J = projection_jacobian(h) * dh;
        *JtJ += J.transpose() * J;
        *Jtr += J.transpose() * e;
      }
    }
    return cost;
  };
  Eigen::Matrix3d JtJ;
  Eigen::Vector3d Jtr;
  double cost = cost_of(theta, &JtJ, &Jtr);
  for (int it = 0; it < config_.triangulation_iterations && std::isfinite(cost); ++it) {
    const Eigen::Vector3d step = JtJ.ldlt().solve(Jtr);
    if (!step.allFinite()) break;
    const Eigen::Vector3d candidate = theta + step;
    Eigen::Matrix3d JtJ_c;
    Eigen::Vector3d Jtr_c;
    const double cost_c = cost_of(candidate, &JtJ_c, &Jtr_c);
    if (!(cost_c < cost)) break;
    const bool converged = cost - cost_c < 1e-12 * (1.0 + cost);
    theta = candidate;
    cost = cost_c;
    JtJ = JtJ_c;
    Jtr = Jtr_c;
    if (converged) break;
  }
  if (!std::isfinite(cost) || !(theta.z() > 0.0)) return false;
  const Eigen::Vector3d p_a = Eigen::Vector3d(theta.x(), theta.y(), 1.0) / theta.z();
  for (std::size_t j = 0; j < m; ++j) {
    const double depth = (R_cj_a[j] * p_a + p_cj_a[j]).z();
    if (depth < config_.min_depth_m || depth > config_.max_depth_m) return false;
  }
  const double rms_sigma = std::sqrt(cost / static_cast<double>(m)) / sigma_normalized_;
  if (rms_sigma > config_.triangulation_max_reproj_sigma) return false;
  *p_w_f = R_w_c[0] * p_a + p_w_c[0];
  return true;
}

bool Msckf::feature_jacobian(const FeatureTrack& track, const Eigen::Vector3d& p_w_f, Eigen::MatrixXd* H0,
                             Eigen::VectorXd* r0) const {
  const Eigen::Index m = static_cast<Eigen::Index>(track.clone_ids.size());
  const Eigen::Index clone_cols = kCloneDim * static_cast<Eigen::Index>(clones_.size());
  Eigen::MatrixXd H_x = Eigen::MatrixXd::Zero(2 * m, clone_cols);
  Eigen::MatrixXd H_f(2 * m, 3);
  Eigen::VectorXd r(2 * m);
  const Eigen::Matrix3d R_c_i = R_i_c_.transpose();
  for (Eigen::Index j = 0; j < m; ++j) {
    const int k = clone_index(track.clone_ids[static_cast<std::size_t>(j)]);
    if (k < 0) return false;
    const PoseClone& clone = clones_[static_cast<std::size_t>(k)];
    const Eigen::Matrix3d R_w_i = clone.q_w_i.toRotationMatrix();
    const Eigen::Vector3d p_c = R_c_i * (R_w_i.transpose() * (p_w_f - clone.p_w_m) - p_i_c_);
    if (!(p_c.z() > config_.min_depth_m)) return false;
    r.segment<2>(2 * j) = track.xy[static_cast<std::size_t>(j)] - p_c.head<2>() / p_c.z();
    // Residual at the current estimate; Jacobian at the clone's first estimate (FEJ) or the current one.
    const bool fej = config_.first_estimate_jacobians;
    const Eigen::Matrix3d R_lin = fej ? clone.q_w_i_fej.toRotationMatrix() : R_w_i;
    const Eigen::Vector3d p_i = R_lin.transpose() * (p_w_f - (fej ? clone.p_w_m_fej : clone.p_w_m));
    const Eigen::Vector3d p_c_lin = R_c_i * (p_i - p_i_c_);
    if (!(p_c_lin.z() > config_.min_depth_m)) return false;
    const Eigen::Matrix<double, 2, 3> Jp = projection_jacobian(p_c_lin) * R_c_i;
    const Eigen::Matrix<double, 2, 3> Jp_R = Jp * R_lin.transpose();
    const Eigen::Index col = kCloneDim * k;
    H_x.block<2, 3>(2 * j, col) = Jp * skew(p_i);
    H_x.block<2, 3>(2 * j, col + 3) = -Jp_R;
    H_f.block<2, 3>(2 * j, 0) = Jp_R;
  }
  // Left null space of H_f: the last 2m - 3 rows of Q^T, applied in place (Householder reflections).
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(H_f);
  const auto Qt = qr.householderQ().adjoint();
  H_x.applyOnTheLeft(Qt);
  r.applyOnTheLeft(Qt);
  *H0 = H_x.bottomRows(2 * m - 3);
  *r0 = r.tail(2 * m - 3);
  return true;
}

MsckfUpdateStats Msckf::update(const std::vector<std::uint64_t>& feature_ids) {
  MsckfUpdateStats stats;
  stats.candidate_features = static_cast<int>(feature_ids.size());
  if (feature_ids.empty()) return stats;
  const Eigen::Index clone_cols = kCloneDim * static_cast<Eigen::Index>(clones_.size());
  const double var = sigma_normalized_ * sigma_normalized_;
  // The measurements see the clones only: the chi-square test needs the clone block of P.
  const Eigen::MatrixXd P_cc = P_.bottomRightCorner(clone_cols, clone_cols);
  std::vector<Eigen::MatrixXd> blocks_H;
  std::vector<Eigen::VectorXd> blocks_r;
  Eigen::Index rows = 0;
  for (std::uint64_t id : feature_ids) {
    const FeatureTrack& track = features_.at(id);
    Eigen::Vector3d p_w_f;
    Eigen::MatrixXd H0;
    Eigen::VectorXd r0;
    if (!triangulate(track, &p_w_f) || !feature_jacobian(track, p_w_f, &H0, &r0)) {
      ++stats.rejected_triangulation;
      continue;
    }
    // Mahalanobis gate at the upper chi-square quantile.
    Eigen::MatrixXd S = H0 * P_cc.selfadjointView<Eigen::Upper>() * H0.transpose();
    S.diagonal().array() += var;
    const double gamma = r0.dot(S.llt().solve(r0));
    if (!std::isfinite(gamma) || gamma > chi2_.quantile(static_cast<int>(r0.size()))) {
      ++stats.rejected_chi2;
      continue;
    }
    rows += H0.rows();
    blocks_H.push_back(std::move(H0));
    blocks_r.push_back(std::move(r0));
    ++stats.used_features;
  }
  stats.rows = static_cast<int>(rows);
  if (rows == 0) return stats;
  Eigen::MatrixXd H(rows, clone_cols);
  Eigen::VectorXd r(rows);
  Eigen::Index row = 0;
  for (std::size_t i = 0; i < blocks_H.size(); ++i) {
    H.middleRows(row, blocks_H[i].rows()) = blocks_H[i];
    r.segment(row, blocks_r[i].size()) = blocks_r[i];
    row += blocks_H[i].rows();
  }
  if (rows > clone_cols) {
    // QR compression: H = Q [R; 0] -> use R and the first entries of Q^T r (noise stays isotropic).
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(H);
    r.applyOnTheLeft(qr.householderQ().adjoint());
    const Eigen::MatrixXd R = qr.matrixQR().topRows(clone_cols).triangularView<Eigen::Upper>();
    apply_update(kImuErrorDim, R, r.head(clone_cols), var);
  } else {
    apply_update(kImuErrorDim, H, r, var);
  }
  return stats;
}

void Msckf::zero_velocity_update(double sigma_mps) {
  if (!initialized_) return;
  apply_update(ImuErrorIndex::kVel, Eigen::Matrix3d::Identity(), -state_.v_w_mps, sigma_mps * sigma_mps);
}

void Msckf::apply_update(Eigen::Index col0, const Eigen::MatrixXd& H, const Eigen::VectorXd& r, double var) {
  // P H^T with H zero outside its columns: only those columns of P are needed.
  const Eigen::MatrixXd PHt = P_.middleCols(col0, H.cols()) * H.transpose();
  Eigen::MatrixXd S = H * PHt.middleRows(col0, H.cols());
  S.diagonal().array() += var;
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  // K = P H^T S^-1;  dx = K r;  P <- P - K S K^T = P - P H^T S^-1 H P (symmetrised).
  const Eigen::MatrixXd Kt = llt.solve(PHt.transpose());
  const Eigen::VectorXd dx = Kt.transpose() * r;
  P_.noalias() -= PHt * Kt;
  P_ = 0.5 * (P_ + P_.transpose()).eval();

  state_.apply_correction(dx.head<kImuErrorDim>());
  for (std::size_t k = 0; k < clones_.size(); ++k) {
    const Eigen::Index col = kImuErrorDim + kCloneDim * static_cast<Eigen::Index>(k);
    clones_[k].q_w_i = (clones_[k].q_w_i * so3_exp_quat(dx.segment<3>(col))).normalized();
    clones_[k].p_w_m += dx.segment<3>(col + 3);
  }
}

bool Msckf::healthy(std::string* reason) const {
  auto fail = [&](const char* why) {
    if (reason != nullptr) *reason = why;
    return false;
  };
  if (!initialized_) return fail("not initialised");
  if (!state_.q_w_i.coeffs().allFinite() || !state_.p_w_m.allFinite() || !state_.v_w_mps.allFinite() ||
      !state_.gyro_bias_radps.allFinite() || !state_.accel_bias_mps2.allFinite()) {
    return fail("state is not finite (NaN/inf)");
  }
  if (!P_.allFinite()) return fail("covariance is not finite (NaN/inf)");
  if ((P_.diagonal().array() <= 0.0).any()) return fail("covariance has a non-positive variance");
  // The full matrix is singular by construction right after cloning (clone = current pose), so the IMU
  // block and each clone block are checked.
  if (Eigen::LLT<ImuMatrix>(P_.topLeftCorner<kImuErrorDim, kImuErrorDim>()).info() != Eigen::Success) {
    return fail("IMU covariance is not positive definite");
  }
  for (std::size_t k = 0; k < clones_.size(); ++k) {
    const Eigen::Index col = kImuErrorDim + kCloneDim * static_cast<Eigen::Index>(k);
    const Eigen::Matrix<double, kCloneDim, kCloneDim> block = P_.block<kCloneDim, kCloneDim>(col, col);
    if (Eigen::LLT<Eigen::Matrix<double, kCloneDim, kCloneDim>>(block).info() != Eigen::Success) {
      return fail("clone covariance is not positive definite");
    }
  }
  return true;
}

PoseEstimate Msckf::pose_estimate(const Eigen::Isometry3d& T_b_i) const {
  PoseEstimate out;
  out.t_ns = state_.t_ns;
  const Eigen::Matrix3d R_w_i = state_.q_w_i.toRotationMatrix();
  Eigen::Isometry3d T_w_i = Eigen::Isometry3d::Identity();
  T_w_i.linear() = R_w_i;
  T_w_i.translation() = state_.p_w_m;
  const Eigen::Isometry3d T_i_b = T_b_i.inverse();
  out.T_w_b = T_w_i * T_i_b;
  const Eigen::Vector3d p_i_b = T_i_b.translation();
  out.v_w_mps = state_.v_w_mps + R_w_i * state_.omega_i_radps.cross(p_i_b);
  out.has_velocity = true;
  if (P_.rows() >= kImuErrorDim) {
    // [dp_b; dtheta_b] = J [dtheta; dp]:  dp_b = dp - R_w_i [p_i_b]x dtheta,  dtheta_b = R_b_i dtheta.
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Zero();
    J.block<3, 3>(0, 0) = -R_w_i * skew(p_i_b);
    J.block<3, 3>(0, 3) = Eigen::Matrix3d::Identity();
    J.block<3, 3>(3, 0) = T_i_b.rotation().transpose();
    const Eigen::Matrix<double, 6, 6> P_sub = P_.topLeftCorner<6, 6>();
    out.cov = J * P_sub * J.transpose();
  }
  out.status = OdometryStatus::kTracking;
  return out;
}

std::pair<Eigen::Isometry3d, PoseCov> Msckf::relative_pose(std::size_t index,
                                                           const Eigen::Isometry3d& T_b_i) const {
  const PoseClone& clone = clones_.at(index);
  const Eigen::Matrix3d R_r = clone.q_w_i.toRotationMatrix();
  const Eigen::Matrix3d R_i = state_.q_w_i.toRotationMatrix();
  // E = T_r_i between the two IMU poses, then B = X^-1 E X in body frames (X = T_i_b).
  const Eigen::Matrix3d R_E = R_r.transpose() * R_i;
  const Eigen::Vector3d p_E = R_r.transpose() * (state_.p_w_m - clone.p_w_m);
  const Eigen::Isometry3d T_i_b = T_b_i.inverse();
  const Eigen::Matrix3d R_X = T_i_b.rotation();
  const Eigen::Vector3d p_X = T_i_b.translation();
  Eigen::Isometry3d T_r_i = Eigen::Isometry3d::Identity();
  T_r_i.linear() = R_E;
  T_r_i.translation() = p_E;
  const Eigen::Isometry3d T_r_b = T_i_b.inverse() * T_r_i * T_i_b;
  // [dp_E; dtheta_E] = J_E [dtheta_r, dp_r, dtheta_i, dp_i] (right perturbations, world positions):
  //   dp_E = [p_E]x dtheta_r - R_r^T dp_r + R_r^T dp_i,  dtheta_E = -R_E^T dtheta_r + dtheta_i.
  Eigen::Matrix<double, 6, 12> J_E = Eigen::Matrix<double, 6, 12>::Zero();
  J_E.block<3, 3>(0, 0) = skew(p_E);
  J_E.block<3, 3>(0, 3) = -R_r.transpose();
  J_E.block<3, 3>(0, 9) = R_r.transpose();
  J_E.block<3, 3>(3, 0) = -R_E.transpose();
  J_E.block<3, 3>(3, 6).setIdentity();
  // In body frames: dp_B = R_X^T (dp_E - R_E [p_X]x dtheta_E), dtheta_B = R_X^T dtheta_E.
  PoseCov J_B = PoseCov::Zero();
  J_B.topLeftCorner<3, 3>() = R_X.transpose();
  J_B.topRightCorner<3, 3>() = -R_X.transpose() * R_E * skew(p_X);
  J_B.bottomRightCorner<3, 3>() = R_X.transpose();
  const Eigen::Index c = kImuErrorDim + kCloneDim * static_cast<Eigen::Index>(index);
  Eigen::Matrix<double, 12, 12> P_joint;
  P_joint.topLeftCorner<6, 6>() = P_.block<6, 6>(c, c);
  P_joint.topRightCorner<6, 6>() = P_.block<6, 6>(c, 0);
  P_joint.bottomLeftCorner<6, 6>() = P_.block<6, 6>(0, c);
  P_joint.bottomRightCorner<6, 6>() = P_.block<6, 6>(0, 0);
  const Eigen::Matrix<double, 6, 12> J = J_B * J_E;
  const PoseCov cov = J * P_joint * J.transpose();
  return {T_r_b, 0.5 * (cov + cov.transpose())};
}

}  // namespace loopgate
