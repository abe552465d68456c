#include "stages/odometry/ekf_odometry.hpp"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <exception>
#include <numbers>
#include <opencv2/core/mat.hpp>
#include <span>
#include <utility>

#include "core/error.hpp"

namespace loopgate {

EkfOdometry::EkfOdometry(const EkfConfig& config, const CameraCalibration& camera, const ImuCalibration& imu,
                         std::vector<GroundTruthState> ground_truth, const Eigen::Vector3d& up_w)
    : config_(config),
      ekf_(config, camera, imu),
      ground_truth_(std::move(ground_truth)),
      R_f_w_(Eigen::Quaterniond::FromTwoVectors(up_w.normalized(), Eigen::Vector3d::UnitZ())
                 .toRotationMatrix()) {
  for (GroundTruthState& s : ground_truth_) {
    s.T_w_b.linear() = R_f_w_ * s.T_w_b.linear();
    s.T_w_b.translation() = R_f_w_ * s.T_w_b.translation();
    s.v_w_mps = R_f_w_ * s.v_w_mps;
  }
  if (config_.init_mode == EkfInitMode::kGroundTruth && ground_truth_.size() < 2) {
    throw ConfigError(
        "ekf.init_mode: 'ground_truth' needs a dataset with ground truth (at least two states); "
        "use auto (the default) to start from the sensors");
  }
}

OdometryOutput EkfOdometry::lost(const OdometryInput& input, const std::string& reason) {
  OdometryOutput out;
  if (last_pose_.has_value()) out.pose = *last_pose_;
  out.pose.t_ns = input.t_ns;
  out.pose.status = OdometryStatus::kLost;
  out.reason = reason;
  out.tracked_features = 0;
  return out;
}

namespace {

struct EkfPreparedImage final : PreparedImage {
  TrackerImage tracker;
};

}  // namespace

std::shared_ptr<const PreparedImage> EkfOdometry::prepare(const cv::Mat& image) const {
  try {
    auto prepared = std::make_shared<EkfPreparedImage>();
    prepared->tracker = ekf_.prepare_image(image);
    return prepared;
  } catch (const std::exception&) {
    return nullptr;  // process() tracks the image itself and reports why the frame is lost
  }
}

OdometryOutput EkfOdometry::process(const OdometryInput& input) {
  OdometryOutput out = track(input);
  count(input, out);
  return out;
}

void EkfOdometry::count(const OdometryInput& input, const OdometryOutput& out) {
  if (!first_t_ns_) first_t_ns_ = input.t_ns;
  ++start_.frames_seen;
  start_.data_s = ns_to_s(input.t_ns - *first_t_ns_);
  start_.starts = ekf_.starts();
  const auto& init = ekf_.initial_state();
  if (init && !start_.started) {
    start_.started = true;
    start_.frame = input.frame;
    start_.t_ns = input.t_ns;
    start_.after_first_s = ns_to_s(input.t_ns - *first_t_ns_);
    start_.method = init_method_name(init->method);
    start_.up_i = init->state.q_w_i.conjugate() * Eigen::Vector3d::UnitZ();
    const Eigen::Matrix3d R = init->state.q_w_i.toRotationMatrix();
    start_.roll_deg = std::atan2(R(2, 1), R(2, 2)) * 180.0 / std::numbers::pi;
    start_.pitch_deg = std::asin(std::clamp(-R(2, 0), -1.0, 1.0)) * 180.0 / std::numbers::pi;
    start_.v_w_mps = init->state.v_w_mps;
    start_.gyro_bias_radps = init->state.gyro_bias_radps;
    start_.accel_bias_mps2 = init->state.accel_bias_mps2;
    start_.scale = init->scale;
    start_.window_s = init->window_s;
    start_.detail = init->detail;
    start_.status.clear();
  }
  if (init) start_.method = init_method_name(init->method);
  if (!start_.started) {
    start_.status = ekf_.init_status();
    if (!warned_late_ && start_.data_s > config_.max_init_s) {
      warned_late_ = true;
      spdlog::error("ekf: not started after {:.2f} s of data (ekf.max_init_s = {} s); {}", start_.data_s,
                    config_.max_init_s, start_.status);
    }
    return;
  }
  ++start_.frames_since_start;
  if (out.pose.status == OdometryStatus::kTracking) ++start_.frames_tracking;
}

OdometryOutput EkfOdometry::track(const OdometryInput& input) {
  // IMU of this frame, after the samples of earlier frames that did not reach the filter.
  std::vector<ImuSample> imu = pending_imu_;
  if (input.imu != nullptr) {
    for (const ImuSample& s : *input.imu) {
      if (imu.empty() || s.t_ns > imu.back().t_ns) imu.push_back(s);
    }
  }
  if (input.image == nullptr) {
    pending_imu_ = std::move(imu);
    return lost(input, "no image for this frame (the ekf source tracks images)");
  }
  EkfFrameInput in;
  in.t_ns = input.t_ns;
  in.imu = std::span<const ImuSample>(imu);
  in.image = input.image;
  if (const auto* prepared = dynamic_cast<const EkfPreparedImage*>(input.prepared))
    in.prepared = &prepared->tracker;
  if (config_.init_mode == EkfInitMode::kGroundTruth)
    in.ground_truth = ground_truth_state_at(ground_truth_, input.t_ns);
  EkfFrameOutput result;
  try {
    result = ekf_.process(in);
  } catch (const std::exception& e) {
    // A bad image (wrong size, empty) or anything the filter did not catch: this frame is lost.
    spdlog::warn("ekf: frame {} lost: {}", input.frame, e.what());
    pending_imu_ = std::move(imu);
    return lost(input, e.what());
  }
  pending_imu_.clear();
  spdlog::debug(
      "ekf: frame {} {} features {} disparity {:.2f} px zupt {} update: candidates {} used {} rejected "
      "triangulation {} chi2 {}; sigma {:.3f} m; track {:.2f} ms filter {:.2f} ms",
      input.frame, to_string(result.pose.status), result.tracked_features, result.median_disparity_px,
      result.zero_velocity, result.update.candidate_features, result.update.used_features,
      result.update.rejected_triangulation, result.update.rejected_chi2, result.position_sigma_m,
      result.tracking_ms, result.filter_ms);
  OdometryOutput out;
  out.pose = result.pose;
  // Back to the dataset world: position and velocity rotate, the attitude error (right perturbation, in
  // the body frame) does not.
  const Eigen::Matrix3d R_w_f = R_f_w_.transpose();
  out.pose.T_w_b.linear() = R_w_f * result.pose.T_w_b.linear();
  out.pose.T_w_b.translation() = R_w_f * result.pose.T_w_b.translation();
  out.pose.v_w_mps = R_w_f * result.pose.v_w_mps;
  out.pose.cov.topLeftCorner<3, 3>() = R_w_f * result.pose.cov.topLeftCorner<3, 3>() * R_f_w_;
  out.pose.cov.topRightCorner<3, 3>() = R_w_f * result.pose.cov.topRightCorner<3, 3>();
  out.pose.cov.bottomLeftCorner<3, 3>() = result.pose.cov.bottomLeftCorner<3, 3>() * R_f_w_;
  out.pose.t_ns = input.t_ns;  // a lost frame carries the last good pose: stamp it with this frame
  out.reason = result.reason;
  out.tracked_features = result.tracked_features;
  out.step_cov = result.step_cov;  // body-to-body: the same in the dataset world
  if (out.pose.status == OdometryStatus::kTracking) last_pose_ = out.pose;
  last_ = std::move(result);
  return out;
}

}  // namespace loopgate
