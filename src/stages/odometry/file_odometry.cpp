#include "stages/odometry/file_odometry.hpp"

#include <algorithm>
#include <stdexcept>

#include "core/geometry.hpp"

namespace loopgate {

StampedPose FileOdometry::FilePose::pose() const {
  StampedPose p{t_ns, Eigen::Isometry3d::Identity()};
  p.T_w_b.matrix().topRows<3>() = top_rows;
  return p;
}

FileOdometry::FileOdometry(const OdometryConfig& config, std::vector<StampedPose> poses) : config_(config) {
  if (poses.empty()) throw std::invalid_argument("FileOdometry: empty trajectory");
  poses_.reserve(poses.size());
  for (const StampedPose& p : poses) poses_.push_back({p.t_ns, p.T_w_b.matrix().topRows<3>()});
  cumulative_m_.resize(poses.size(), 0.0);
  for (std::size_t i = 1; i < poses.size(); ++i) {
    cumulative_m_[i] =
        cumulative_m_[i - 1] + (poses[i].T_w_b.translation() - poses[i - 1].T_w_b.translation()).norm();
  }
}

double FileOdometry::distance_at(Timestamp t_ns) const {
  if (t_ns <= poses_.front().t_ns) return 0.0;
  if (t_ns >= poses_.back().t_ns) return cumulative_m_.back();
  const auto it = std::upper_bound(poses_.begin(), poses_.end(), t_ns,
                                   [](Timestamp t, const FilePose& p) { return t < p.t_ns; });
  const std::size_t b = static_cast<std::size_t>(it - poses_.begin());
  const std::size_t a = b - 1;
  const double alpha =
      static_cast<double>(t_ns - poses_[a].t_ns) / static_cast<double>(poses_[b].t_ns - poses_[a].t_ns);
  return cumulative_m_[a] + alpha * (cumulative_m_[b] - cumulative_m_[a]);
}

OdometryOutput FileOdometry::process(const OdometryInput& input) {
  OdometryOutput out;
  const Timestamp t_ns = input.t_ns;
  out.pose.t_ns = t_ns;
  const auto max_gap_ns = static_cast<Timestamp>(config_.file_max_gap_s * 1e9);
  const auto it = std::upper_bound(poses_.begin(), poses_.end(), t_ns,
                                   [](Timestamp t, const FilePose& p) { return t < p.t_ns; });
  bool lost = false;
  if (it == poses_.begin() || it == poses_.end()) {
    // Outside the trajectory's span: the nearest end, lost unless it is the exact last pose.
    const StampedPose nearest = (it == poses_.begin() ? poses_.front() : poses_.back()).pose();
    out.pose.T_w_b = nearest.T_w_b;
    lost = nearest.t_ns != t_ns;
    if (lost) out.reason = "frame time outside the trajectory file's span";
  } else {
    const StampedPose a = (it - 1)->pose();
    const StampedPose b = it->pose();
    out.pose.T_w_b = interpolate_pose(a, b, t_ns);
    out.pose.v_w_mps = (b.T_w_b.translation() - a.T_w_b.translation()) / ns_to_s(b.t_ns - a.t_ns);
    out.pose.has_velocity = true;
    if (std::min(t_ns - a.t_ns, b.t_ns - t_ns) > max_gap_ns) {
      lost = true;
      out.reason = "trajectory file has no pose within file_max_gap_s of the frame";
    }
  }
  const double d_m = distance_at(t_ns);
  out.pose.cov.topLeftCorner<3, 3>() =
      (config_.file_sigma2_a_m2 + config_.file_sigma2_b_m2_per_m * d_m) * Eigen::Matrix3d::Identity();
  out.pose.cov.bottomRightCorner<3, 3>() =
      (config_.file_rot_sigma2_a_rad2 + config_.file_rot_sigma2_b_rad2_per_m * d_m) *
      Eigen::Matrix3d::Identity();
  out.pose.status = lost ? OdometryStatus::kLost : OdometryStatus::kTracking;
  // The model's variance grows by b per metre: the step's is b times the distance since the previous pose.
  if (!lost && previous_d_m_) {
    const double step_m = std::max(0.0, d_m - *previous_d_m_);
    PoseCov step = PoseCov::Zero();
    step.topLeftCorner<3, 3>().diagonal().setConstant(config_.file_sigma2_b_m2_per_m * step_m);
    step.bottomRightCorner<3, 3>().diagonal().setConstant(config_.file_rot_sigma2_b_rad2_per_m * step_m);
    out.step_cov = step;
  }
  previous_d_m_ = lost ? std::nullopt : std::optional<double>(d_m);
  return out;
}

}  // namespace loopgate
