#include "eval/trajectory_metrics.hpp"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/error.hpp"
#include "core/geometry.hpp"

namespace loopgate {

namespace {

void check_pairs(const std::vector<Eigen::Vector3d>& p_est, const std::vector<Eigen::Vector3d>& p_gt) {
  if (p_est.size() != p_gt.size()) throw std::invalid_argument("trajectory alignment: sizes differ");
  if (p_est.empty()) throw std::invalid_argument("trajectory alignment: no position pairs");
}

Eigen::Vector3d mean_of(const std::vector<Eigen::Vector3d>& p) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& x : p) sum += x;
  return sum / static_cast<double>(p.size());
}

}  // namespace

void AteConfig::validate() const {
  if (max_dt_ns < 0) throw ConfigError("ate.max_dt_ns: must be >= 0");
}

Eigen::Isometry3d align_se3(const std::vector<Eigen::Vector3d>& p_est,
                            const std::vector<Eigen::Vector3d>& p_gt) {
  check_pairs(p_est, p_gt);
  const Eigen::Vector3d mu_est = mean_of(p_est);
  const Eigen::Vector3d mu_gt = mean_of(p_gt);
  Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();  // cross-covariance gt x est
  for (std::size_t k = 0; k < p_est.size(); ++k) sigma += (p_gt[k] - mu_gt) * (p_est[k] - mu_est).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d S = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) S(2, 2) = -1.0;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = svd.matrixU() * S * svd.matrixV().transpose();
  T.translation() = mu_gt - T.linear() * mu_est;
  return T;
}

Eigen::Isometry3d align_position_yaw(const std::vector<Eigen::Vector3d>& p_est,
                                     const std::vector<Eigen::Vector3d>& p_gt, const Eigen::Vector3d& up) {
  check_pairs(p_est, p_gt);
  const Eigen::Vector3d u = up.normalized();
  const Eigen::Vector3d mu_est = mean_of(p_est);
  const Eigen::Vector3d mu_gt = mean_of(p_gt);
  // Maximise sum b . R(yaw) a over the components perpendicular to up: yaw = atan2(sum u.(a x b), sum a.b).
  double s = 0.0, c = 0.0;
  for (std::size_t k = 0; k < p_est.size(); ++k) {
    Eigen::Vector3d a = p_est[k] - mu_est;
    Eigen::Vector3d b = p_gt[k] - mu_gt;
    a -= u * u.dot(a);
    b -= u * u.dot(b);
    s += u.dot(a.cross(b));
    c += a.dot(b);
  }
  const double yaw = (s == 0.0 && c == 0.0) ? 0.0 : std::atan2(s, c);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, u).toRotationMatrix();
  T.translation() = mu_gt - T.linear() * mu_est;
  return T;
}

AteResult compute_ate(const std::vector<Eigen::Vector3d>& p_est, const std::vector<Eigen::Vector3d>& p_gt,
                      const AteConfig& config) {
  config.validate();
  check_pairs(p_est, p_gt);
  AteResult result;
  if (config.alignment == AteAlignment::kSe3) {
    result.T_gt_est = align_se3(p_est, p_gt);
  } else if (config.alignment == AteAlignment::kPosyaw) {
    result.T_gt_est = align_position_yaw(p_est, p_gt, config.up());
  }
  double sum2 = 0.0, sum = 0.0;
  for (std::size_t k = 0; k < p_est.size(); ++k) {
    const double e = (result.T_gt_est * p_est[k] - p_gt[k]).norm();
    sum2 += e * e;
    sum += e;
    result.max_m = std::max(result.max_m, e);
    if (k > 0) result.path_length_m += (p_gt[k] - p_gt[k - 1]).norm();
  }
  const auto n = static_cast<double>(p_est.size());
  result.count = p_est.size();
  result.rmse_m = std::sqrt(sum2 / n);
  result.mean_m = sum / n;
  result.final_error_m = (result.T_gt_est * p_est.back() - p_gt.back()).norm();
  constexpr double kPer100m = 100.0;
  result.drift_per_100m =
      result.path_length_m > 0.0 ? result.final_error_m / result.path_length_m * kPer100m : 0.0;
  return result;
}

std::vector<std::pair<std::size_t, std::size_t>> associate_by_time(
    const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& ground_truth,
    std::int64_t max_dt_ns) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  std::size_t g = 0;
  for (std::size_t e = 0; e < estimate.size() && !ground_truth.empty(); ++e) {
    const Timestamp t = estimate[e].t_ns;
    while (g + 1 < ground_truth.size() && ground_truth[g + 1].t_ns <= t) ++g;
    std::size_t best = g;
    if (g + 1 < ground_truth.size() &&
        std::llabs(ground_truth[g + 1].t_ns - t) < std::llabs(ground_truth[g].t_ns - t)) {
      best = g + 1;
    }
    if (std::llabs(ground_truth[best].t_ns - t) <= max_dt_ns) pairs.emplace_back(e, best);
  }
  return pairs;
}

}  // namespace loopgate
