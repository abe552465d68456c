#include "pipeline/outputs/run_metrics.hpp"

#include <cmath>
#include <exception>
#include <string>

#include "core/geometry.hpp"
#include "eval/trajectory_metrics.hpp"
#include "io/dataset.hpp"
#include "pipeline/odometry_factory.hpp"
#include "stages/ekf/vio_ekf.hpp"

namespace loopgate {

namespace {
constexpr std::size_t kMinPairs = 3;  // alignment needs three non-collinear pairs

// The alignment applied to the estimate, row-major 3x4 [R | t] (the plots draw the aligned trajectories).
std::vector<std::vector<double>> matrix_rows(const Eigen::Isometry3d& T) {
  std::vector<std::vector<double>> rows;
  for (int r = 0; r < 3; ++r) rows.push_back({T(r, 0), T(r, 1), T(r, 2), T(r, 3)});
  return rows;
}

// The gravity axis of the world: from the IMU and the ground truth when there is an IMU (z for EuRoC,
// y for KITTI camera-frame worlds), else the world axis nearest the normal of the best-fit plane of the
// ground-truth positions (real KITTI).
WorldAxis gravity_axis(const Dataset& dataset, const std::vector<Eigen::Vector3d>& p_gt) {
  const auto up_w = world_up_axis_from_imu(dataset);
  return static_cast<WorldAxis>(dominant_axis(up_w ? *up_w : plane_normal(p_gt)));
}
}  // namespace

nlohmann::json trajectory_accuracy_json(const std::vector<StampedPose>& tracked_poses,
                                        const Dataset& dataset) {
  if (!dataset.has_ground_truth()) return {{"available", false}, {"why", "the dataset has no ground truth"}};
  std::vector<Eigen::Vector3d> p_est;
  std::vector<Eigen::Vector3d> p_gt;
  for (const StampedPose& pose : tracked_poses) {
    const auto gt = ground_truth_state_at(dataset.ground_truth(), pose.t_ns);
    if (!gt) continue;
    p_est.push_back(pose.T_w_b.translation());
    p_gt.push_back(gt->T_w_b.translation());
  }
  if (p_est.size() < kMinPairs) {
    return {{"available", false},
            {"why", std::to_string(p_est.size()) + " tracking poses inside the ground-truth time span"}};
  }
  AteConfig posyaw;
  posyaw.alignment = AteAlignment::kPosyaw;
  AteConfig se3;
  se3.alignment = AteAlignment::kSe3;
  AteResult ate;
  AteResult ate_se3;
  try {
    posyaw.up_axis = gravity_axis(dataset, p_gt);
    ate_se3 = compute_ate(p_est, p_gt, se3);
    // An estimate in a world of its own (the ekf started from the sensors: +z up) may have its up along
    // another axis than the ground truth (-y for KITTI camera-frame worlds): the axis of the estimate that
    // the full alignment turns onto the ground truth's up is turned onto it first, then only a yaw about
    // up is fitted.
    const Eigen::Vector3d up_gt = posyaw.up();
    const Eigen::Vector3d up_est = nearest_signed_axis(ate_se3.T_gt_est.linear().transpose() * up_gt);
    if (up_est.isApprox(up_gt)) {
      ate = compute_ate(p_est, p_gt, posyaw);
    } else {
      const Eigen::Isometry3d T_turn(Eigen::Quaterniond::FromTwoVectors(up_est, up_gt));
      std::vector<Eigen::Vector3d> p_turned;
      p_turned.reserve(p_est.size());
      for (const Eigen::Vector3d& p : p_est) p_turned.push_back(T_turn * p);
      ate = compute_ate(p_turned, p_gt, posyaw);
      ate.T_gt_est = ate.T_gt_est * T_turn;
    }
  } catch (const std::exception& e) {
    return {{"available", false}, {"why", std::string("alignment failed: ") + e.what()}};
  }
  return {{"available", true},
          {"poses", "odometry poses with status tracking"},
          {"alignment", "posyaw"},
          {"up_axis", std::string(enum_name(posyaw.up_axis))},
          {"pairs", ate.count},
          {"rmse_m", ate.rmse_m},
          {"mean_m", ate.mean_m},
          {"max_m", ate.max_m},
          {"path_length_m", ate.path_length_m},
          {"final_error_m", ate.final_error_m},
          {"drift_per_100m", ate.drift_per_100m},
          {"se3_rmse_m", ate_se3.rmse_m},
          {"T_gt_est", matrix_rows(ate.T_gt_est)}};
}

}  // namespace loopgate
