#include "stages/ekf/vio_ekf.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <exception>
#include <opencv2/core/mat.hpp>

#include "core/error.hpp"
#include "core/geometry.hpp"

namespace loopgate {
namespace {

double pick(double override_value, double calibrated, double inflation, const char* key) {
  const double value = (override_value > 0.0 ? override_value : calibrated) * inflation;
  if (!(value > 0.0) || !std::isfinite(value)) {
    throw ConfigError(std::string("ekf.") + key +
                      ": the IMU calibration gives no value (imu0 sensor.yaml); set it in the ekf section");
  }
  return value;
}

Eigen::Isometry3d imu_pose_from_body(const Eigen::Isometry3d& T_w_b, const Eigen::Isometry3d& T_b_i) {
  return T_w_b * T_b_i;
}

}  // namespace

const char* init_method_name(InitMethod method) {
  switch (method) {
    case InitMethod::kStatic: return "static";
    case InitMethod::kDynamic: return "dynamic";
    case InitMethod::kGroundTruth: return "ground_truth";
  }
  return "?";
}

ImuNoise effective_imu_noise(const EkfConfig& config, const ImuCalibration& imu) {
  const double k = config.imu_noise_inflation;
  return ImuNoise{pick(config.gyro_noise_density, imu.gyro_noise_density, k, "gyro_noise_density"),
                  pick(config.gyro_random_walk, imu.gyro_random_walk, k, "gyro_random_walk"),
                  pick(config.accel_noise_density, imu.accel_noise_density, k, "accel_noise_density"),
                  pick(config.accel_random_walk, imu.accel_random_walk, k, "accel_random_walk")};
}

std::optional<GroundTruthState> ground_truth_state_at(const std::vector<GroundTruthState>& states,
                                                      Timestamp t_ns) {
  if (states.size() < 2 || t_ns < states.front().t_ns || t_ns > states.back().t_ns) return std::nullopt;
  const auto it = std::lower_bound(states.begin(), states.end(), t_ns,
                                   [](const GroundTruthState& s, Timestamp t) { return s.t_ns < t; });
  const std::size_t hi = std::max<std::size_t>(1, static_cast<std::size_t>(it - states.begin()));
  const std::size_t lo = hi - 1;
  const GroundTruthState& a = states[lo];
  const GroundTruthState& b = states[hi];
  const double span = static_cast<double>(b.t_ns - a.t_ns);
  const double f = span > 0.0 ? static_cast<double>(t_ns - a.t_ns) / span : 0.0;
  GroundTruthState out;
  out.t_ns = t_ns;
  out.T_w_b = interpolate_pose(StampedPose{a.t_ns, a.T_w_b}, StampedPose{b.t_ns, b.T_w_b}, t_ns);
  out.gyro_bias_radps = (1.0 - f) * a.gyro_bias_radps + f * b.gyro_bias_radps;
  out.accel_bias_mps2 = (1.0 - f) * a.accel_bias_mps2 + f * b.accel_bias_mps2;
  if (!a.v_w_mps.isZero(0.0) || !b.v_w_mps.isZero(0.0)) {
    out.v_w_mps = (1.0 - f) * a.v_w_mps + f * b.v_w_mps;
  } else {
    const std::size_t i0 = lo > 0 ? lo - 1 : lo;
    const std::size_t i1 = std::min(hi + 1, states.size() - 1);
    const double dt_s = ns_to_s(states[i1].t_ns - states[i0].t_ns);
    if (dt_s > 0.0) out.v_w_mps = (states[i1].T_w_b.translation() - states[i0].T_w_b.translation()) / dt_s;
  }
  return out;
}

VioEkf::VioEkf(const EkfConfig& config, const CameraCalibration& camera, const ImuCalibration& imu)
    : config_((config.validate(), config)),
      T_b_i_(imu.T_b_i),
      R_i_c_((imu.T_b_i.inverse() * camera.T_b_c).rotation()),
      focal_px_(0.5 * (camera.fx + camera.fy)),
      tracker_(config, camera),
      filter_(config, effective_imu_noise(config, imu), imu.T_b_i.inverse() * camera.T_b_c,
              0.5 * (camera.fx + camera.fy)),
      static_init_(config, effective_imu_noise(config, imu), 0.5 * (camera.fx + camera.fy)),
      dynamic_init_(config, imu.T_b_i.inverse() * camera.T_b_c, 0.5 * (camera.fx + camera.fy),
                    effective_imu_noise(config, imu)) {}

void VioEkf::initialize_from(const InitialState& init) {
  const ImuState& state = init.state;
  ImuMatrix P0 = ImuMatrix::Zero();
  const Eigen::Matrix3d R_w_i = state.q_w_i.toRotationMatrix();
  // World-frame attitude uncertainty expressed as the right (body) perturbation of the filter.
  P0.block<3, 3>(ImuErrorIndex::kTheta, ImuErrorIndex::kTheta) =
      R_w_i.transpose() * init.rot_cov_world * R_w_i;
  const Eigen::Matrix3d I3 = Eigen::Matrix3d::Identity();
  P0.block<3, 3>(ImuErrorIndex::kPos, ImuErrorIndex::kPos) = std::pow(config_.init_sigma_pos_m, 2) * I3;
  P0.block<3, 3>(ImuErrorIndex::kVel, ImuErrorIndex::kVel) = init.vel_cov_m2ps2;
  P0.block<3, 3>(ImuErrorIndex::kGyroBias, ImuErrorIndex::kGyroBias) = init.gyro_bias_cov;
  P0.block<3, 3>(ImuErrorIndex::kAccelBias, ImuErrorIndex::kAccelBias) =
      std::pow(config_.init_sigma_accel_bias_mps2, 2) * I3;
  if (init.joint_cov) {
    constexpr std::array<int, 4> kBlocks{ImuErrorIndex::kTheta, ImuErrorIndex::kVel, ImuErrorIndex::kGyroBias,
                                         ImuErrorIndex::kAccelBias};
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        P0.block<3, 3>(kBlocks[r], kBlocks[c]) = init.joint_cov->block<3, 3>(3 * r, 3 * c);
      }
    }
  }
  filter_.initialize(state, P0);
  few_feature_frames_ = 0;
  previous_anchored_.reset();
}

bool VioEkf::try_initialize(const EkfFrameInput& input, const std::vector<FeatureObservation>& obs,
                            std::size_t frame) {
  std::optional<InitialState> init;
  if (config_.init_mode == EkfInitMode::kGroundTruth) {
    if (!input.ground_truth.has_value()) {
      init_status_ = "ground_truth: waiting for ground truth (none at this image's time)";
      return false;
    }
    const GroundTruthState& gt = *input.ground_truth;
    const Eigen::Isometry3d T_w_i = imu_pose_from_body(gt.T_w_b, T_b_i_);
    init.emplace();
    init->method = InitMethod::kGroundTruth;
    ImuState& state = init->state;
    state.t_ns = input.t_ns;
    state.q_w_i = Eigen::Quaterniond(T_w_i.rotation());
    state.p_w_m = T_w_i.translation();
    Eigen::Vector3d omega_i = Eigen::Vector3d::Zero();
    if (!input.imu.empty()) omega_i = input.imu.back().gyro_radps - gt.gyro_bias_radps;
    // Lever arm: v_i = v_b + R_w_b (w_b x p_b_i), w_b = R_b_i w_i.
    state.v_w_mps =
        gt.v_w_mps + gt.T_w_b.rotation() * ((T_b_i_.rotation() * omega_i).cross(T_b_i_.translation()));
    state.gyro_bias_radps = gt.gyro_bias_radps;
    state.accel_bias_mps2 = gt.accel_bias_mps2;
    state.omega_i_radps = omega_i;
    const Eigen::Matrix3d I3 = Eigen::Matrix3d::Identity();
    init->rot_cov_world = I3 * std::pow(config_.init_sigma_rot_rad, 2);
    init->vel_cov_m2ps2 = I3 * std::pow(config_.init_sigma_vel_mps, 2);
    init->gyro_bias_cov = I3 * std::pow(config_.init_sigma_gyro_bias_radps, 2);
    init->detail = "ground truth at the image's time (pose, velocity, both IMU biases)";
  } else {
    // auto: both initialisers see every image; a still start is taken first (it needs no motion), the
    // alignment when the platform moves.
    const InitFrame in{input.t_ns, input.imu, &obs};
    const bool use_static = config_.init_mode != EkfInitMode::kDynamic;
    const bool use_dynamic = config_.init_mode != EkfInitMode::kStatic;
    if (use_static) init = static_init_.add_frame(in);
    std::optional<InitialState> moving;
    if (use_dynamic) moving = dynamic_init_.add_frame(in);
    if (!init) init = std::move(moving);
    init_status_.clear();
    if (use_static) init_status_ = static_init_.status();
    if (use_dynamic)
      init_status_ += (init_status_.empty() ? "" : "; ") + ("dynamic: " + dynamic_init_.status());
  }
  if (!init) return false;
  init->frame = frame;
  init->state.t_ns = input.t_ns;
  if (init->method != InitMethod::kGroundTruth && !input.imu.empty()) {
    init->state.omega_i_radps = input.imu.back().gyro_radps - init->state.gyro_bias_radps;
  }
  initialize_from(*init);
  static_init_.reset();
  dynamic_init_.reset();
  ++starts_;
  const Eigen::Vector3d up_i = init->state.q_w_i.conjugate() * Eigen::Vector3d::UnitZ();
  spdlog::info(
      "ekf: started by the {} initialiser at image {} (t = {:.3f} s; start {}): up in the IMU frame [{:.4f} "
      "{:.4f} {:.4f}], velocity [{:.3f} {:.3f} {:.3f}] m/s, gyro bias [{:.5f} {:.5f} {:.5f}] rad/s, scale "
      "{:.3f}; {}",
      init_method_name(init->method), frame, ns_to_s(input.t_ns), starts_, up_i.x(), up_i.y(), up_i.z(),
      init->state.v_w_mps.x(), init->state.v_w_mps.y(), init->state.v_w_mps.z(),
      init->state.gyro_bias_radps.x(), init->state.gyro_bias_radps.y(), init->state.gyro_bias_radps.z(),
      init->scale, init->detail);
  initial_ = std::move(init);
  init_status_.clear();
  return true;
}

double VioEkf::median_disparity_px(const std::vector<FeatureObservation>& observations) const {
  std::vector<double> disparities;
  disparities.reserve(observations.size());
  for (const FeatureObservation& obs : observations) {
    const auto it = previous_xy_.find(obs.id);
    if (it != previous_xy_.end()) disparities.push_back((obs.xy - it->second).norm() * focal_px_);
  }
  if (static_cast<int>(disparities.size()) < config_.zupt_min_features) return -1.0;
  const auto mid = disparities.begin() + static_cast<std::ptrdiff_t>(disparities.size() / 2);
  std::nth_element(disparities.begin(), mid, disparities.end());
  return *mid;
}

EkfFrameOutput VioEkf::lost(std::size_t frame, const std::string& reason) {
  spdlog::warn("ekf: lost at frame {}: {}; re-initialising", frame, reason);
  filter_.reset();
  static_init_.reset();
  dynamic_init_.reset();
  previous_anchored_.reset();
  EkfFrameOutput out;
  if (last_good_.has_value()) out.pose = *last_good_;
  out.pose.status = OdometryStatus::kLost;
  out.reason = reason;
  return out;
}

std::optional<Eigen::Matrix3d> VioEkf::camera_rotation_since_previous(const EkfFrameInput& input) const {
  if (!previous_image_t_ns_.has_value() || input.imu.empty()) return std::nullopt;
  const Timestamp t0 = *previous_image_t_ns_;
  const Timestamp t1 = input.t_ns;
  if (t1 <= t0 || input.imu.front().t_ns > t0 || input.imu.back().t_ns < t1) return std::nullopt;
  const Eigen::Vector3d bias =
      filter_.initialized() ? filter_.state().gyro_bias_radps : Eigen::Vector3d::Zero().eval();
  // Midpoint rule between consecutive samples, clipped to [t0, t1].
  Eigen::Quaterniond q_prev_cur = Eigen::Quaterniond::Identity();
  for (std::size_t k = 0; k + 1 < input.imu.size(); ++k) {
    const ImuSample& a = input.imu[k];
    const ImuSample& b = input.imu[k + 1];
    const Timestamp lo = std::max(a.t_ns, t0);
    const Timestamp hi = std::min(b.t_ns, t1);
    if (hi <= lo) continue;
    const Eigen::Vector3d w = 0.5 * (a.gyro_radps + b.gyro_radps) - bias;
    q_prev_cur = q_prev_cur * so3_exp_quat(w * ns_to_s(hi - lo));
  }
  if (!q_prev_cur.coeffs().allFinite()) return std::nullopt;
  return (R_i_c_.transpose() * q_prev_cur.toRotationMatrix().transpose() * R_i_c_).eval();
}

EkfFrameOutput VioEkf::process(const EkfFrameInput& input) {
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  std::vector<FeatureObservation> tracked;
  if (input.image != nullptr || input.prepared != nullptr) {
    const std::optional<Eigen::Matrix3d> R_cur_prev =
        config_.klt_predict_rotation ? camera_rotation_since_previous(input) : std::nullopt;
    const Eigen::Matrix3d* R = R_cur_prev.has_value() ? &*R_cur_prev : nullptr;
    if (input.prepared != nullptr) {
      tracker_.track(*input.prepared, R);
    } else {
      tracker_.track(*input.image, R);
    }
    previous_image_t_ns_ = input.t_ns;
    tracked = tracker_.observations();
  } else if (input.observations != nullptr) {
    tracked = *input.observations;
  }
  const auto t_tracked = Clock::now();
  const std::size_t frame = frame_++;
  const double disparity_px = median_disparity_px(tracked);
  previous_xy_.clear();
  for (const FeatureObservation& o : tracked) previous_xy_.emplace(o.id, o.xy);

  EkfFrameOutput out = update_filter(input, tracked, disparity_px, frame);
  out.tracked_features = static_cast<int>(tracked.size());
  out.median_disparity_px = disparity_px;
  out.tracking_ms = std::chrono::duration<double, std::milli>(t_tracked - t_start).count();
  out.filter_ms = std::chrono::duration<double, std::milli>(Clock::now() - t_tracked).count();
  return out;
}

EkfFrameOutput VioEkf::update_filter(const EkfFrameInput& input, const std::vector<FeatureObservation>& obs,
                                     double disparity_px, std::size_t frame) {
  EkfFrameOutput out;
  if (!filter_.initialized()) {
    if (!try_initialize(input, obs, frame)) {
      out.pose.t_ns = input.t_ns;
      out.pose.status = OdometryStatus::kInitialising;
      out.reason = "initialising: " + init_status_;
      return out;
    }
    // The first frame of the filter: no IMU interval yet, clone and start the tracks.
    out.update = filter_.process_frame(input.t_ns, {}, obs);
    frames_since_clone_ = 0;
  } else {
    try {
      // Only every clone_every_n_frames-th image becomes a clone (the others propagate): the same window
      // then spans a longer baseline. The tracker still runs on every image, so tracks survive.
      if (++frames_since_clone_ >= config_.clone_every_n_frames) {
        out.update = filter_.process_frame(input.t_ns, input.imu, obs);
        frames_since_clone_ = 0;
      } else {
        filter_.propagate(input.imu, input.t_ns);
      }
      out.zero_velocity =
          config_.zupt_enabled && disparity_px >= 0.0 && disparity_px < config_.zupt_max_disparity_px;
      if (out.zero_velocity) filter_.zero_velocity_update(config_.zupt_sigma_mps);
    } catch (const std::exception& e) {
      return lost(frame, std::string("filter exception: ") + e.what());
    }
  }
  std::string reason;
  if (!filter_.healthy(&reason)) return lost(frame, reason);
  out.pose = filter_.pose_estimate(T_b_i_);
  out.pose.t_ns = input.t_ns;
  out.position_sigma_m = std::sqrt(std::max(0.0, out.pose.position_cov_m2().trace()));
  if (!std::isfinite(out.position_sigma_m) || out.position_sigma_m > config_.max_position_sigma_m) {
    return lost(frame, "position sigma " + std::to_string(out.position_sigma_m) +
                           " m exceeds ekf.max_position_sigma_m");
  }
  const int feature_count = static_cast<int>(obs.size());
  few_feature_frames_ = feature_count < config_.lost_min_features ? few_feature_frames_ + 1 : 0;
  if (few_feature_frames_ >= config_.lost_max_frames) {
    return lost(frame, "only " + std::to_string(feature_count) + " tracked features for " +
                           std::to_string(few_feature_frames_) + " frames");
  }
  out.pose.status = OdometryStatus::kTracking;
  out.step_cov = step_cov(input.t_ns);
  last_good_ = out.pose;
  return out;
}

std::optional<PoseCov> VioEkf::step_cov(Timestamp t_ns) {
  // The anchor: the newest clone before this image (this image's own clone, if any, is the newest).
  const auto& clones = filter_.clones();
  std::optional<std::size_t> anchor;
  for (std::size_t k = clones.size(); k-- > 0;) {
    if (clones[k].t_ns < t_ns) {
      anchor = k;
      break;
    }
  }
  const std::optional<AnchoredPose> previous = previous_anchored_;
  previous_anchored_.reset();
  if (!anchor) return std::nullopt;
  auto [T_r_b, cov] = filter_.relative_pose(*anchor, T_b_i_);
  previous_anchored_ = AnchoredPose{clones[*anchor].id, t_ns, T_r_b, cov};
  if (!previous) return std::nullopt;
  if (clones[*anchor].t_ns == previous->image_t_ns) return cov;  // the previous image is the anchor
  if (clones[*anchor].id == previous->clone_id)
    return step_pose_cov(previous->T_r_b, previous->cov, T_r_b, cov);
  return std::nullopt;
}

}  // namespace loopgate
