#include "stages/ekf/static_initializer.hpp"

#include <spdlog/fmt/fmt.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.hpp"

namespace loopgate {
namespace {

struct Sample6 {
  Timestamp t_ns = 0;
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
};

// Moving average over the samples of the last `width_ns` (t - width, t]; the first output is the first sample
// whose average spans the whole width (earlier ones are dropped).
std::vector<Sample6> moving_average(const std::vector<Sample6>& in, Timestamp width_ns) {
  std::vector<Sample6> out;
  if (in.empty()) return out;
  Eigen::Vector3d sum_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d sum_g = Eigen::Vector3d::Zero();
  std::size_t lo = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    sum_a += in[i].accel;
    sum_g += in[i].gyro;
    while (in[lo].t_ns <= in[i].t_ns - width_ns) {
      sum_a -= in[lo].accel;
      sum_g -= in[lo].gyro;
      ++lo;
    }
    if (in[i].t_ns - in.front().t_ns < width_ns) continue;
    const auto n = static_cast<double>(i - lo + 1);
    out.push_back(Sample6{in[i].t_ns, sum_a / n, sum_g / n});
  }
  return out;
}

// Largest per-axis standard deviation.
double max_axis_std(const std::vector<Eigen::Vector3d>& values) {
  if (values.size() < 2) return -1.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : values) mean += v;
  mean /= static_cast<double>(values.size());
  Eigen::Vector3d var = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : values) var += (v - mean).cwiseAbs2();
  var /= static_cast<double>(values.size() - 1);
  return std::sqrt(var.maxCoeff());
}

// Median motion (px) between this image and the previous one of the features seen in both, or -1 when fewer
// than min_features are; keeps this image's features in previous_xy for the next.
double image_motion_px(const InitFrame& frame, double focal_px, int min_features,
                       std::unordered_map<std::uint64_t, Eigen::Vector2d>* previous_xy) {
  double disparity_px = -1.0;
  if (frame.observations == nullptr) return disparity_px;
  std::vector<double> d;
  for (const FeatureObservation& o : *frame.observations) {
    const auto it = previous_xy->find(o.id);
    if (it != previous_xy->end()) d.push_back((o.xy - it->second).norm() * focal_px);
  }
  if (static_cast<int>(d.size()) >= min_features) {
    const auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
    std::nth_element(d.begin(), mid, d.end());
    disparity_px = *mid;
  }
  previous_xy->clear();
  for (const FeatureObservation& o : *frame.observations) previous_xy->emplace(o.id, o.xy);
  return disparity_px;
}

}  // namespace

double StaticInitializer::lowpassed_noise_std(double density, double lowpass_s) {
  // Sampled at rate r, white noise has a per-sample std of density * sqrt(r); two moving averages of
  // N = lowpass_s * r samples each make a triangular filter whose squared weights sum to about 2 / (3 N).
  return density * std::sqrt(2.0 / (3.0 * lowpass_s));
}

StaticInitializer::StaticInitializer(const EkfConfig& config, const ImuNoise& noise, double focal_px)
    : config_((config.validate(), config)), noise_(noise), focal_px_(focal_px) {
  if (!(noise.accel_noise_density > 0.0) || !(noise.gyro_noise_density > 0.0)) {
    throw ConfigError(
        "ekf: the static initialiser needs the accelerometer and gyro noise densities (imu0 sensor.yaml or "
        "ekf.accel_noise_density / ekf.gyro_noise_density)");
  }
  if (!(focal_px > 0.0) || !std::isfinite(focal_px))
    throw ConfigError("ekf: the static initialiser needs a camera focal length > 0");
  reset();
}

void StaticInitializer::reset() {
  samples_.clear();
  images_.clear();
  previous_xy_.clear();
  last_ = StaticExcitation{};
  last_.accel_limit_mps2 = config_.static_excitation_sigmas *
                           lowpassed_noise_std(noise_.accel_noise_density, config_.static_lowpass_s);
  last_.gyro_limit_radps = config_.static_excitation_sigmas *
                           lowpassed_noise_std(noise_.gyro_noise_density, config_.static_lowpass_s);
  last_.disparity_limit_px = config_.static_max_disparity_px;
  status_ = "static: no image yet";
}

std::optional<InitialState> StaticInitializer::add_frame(const InitFrame& frame) {
  const std::size_t index = frames_++;
  for (const ImuSample& s : frame.imu) {
    if (!s.accel_mps2.allFinite() || !s.gyro_radps.allFinite()) continue;
    if (samples_.empty() || s.t_ns > samples_.back().t_ns) samples_.push_back(s);
  }
  const Timestamp window_ns = s_to_ns(config_.static_window_s);
  while (samples_.size() > 2 && samples_.back().t_ns - samples_[1].t_ns >= window_ns) samples_.pop_front();

  // Image motion since the previous image: median over the features seen in both.
  images_.push_back(
      ImageMotion{frame.t_ns, image_motion_px(frame, focal_px_, config_.zupt_min_features, &previous_xy_)});
  while (!images_.empty() && images_.front().t_ns < frame.t_ns - window_ns) images_.pop_front();

  last_.window_s = samples_.size() >= 2 ? ns_to_s(samples_.back().t_ns - samples_.front().t_ns) : 0.0;
  last_.accel_mps2 = last_.gyro_radps = last_.disparity_px = -1.0;
  if (samples_.size() < 2 || samples_.back().t_ns - samples_.front().t_ns < window_ns) {
    status_ = fmt::format("static: waiting for {:.2f} s of IMU data ({:.2f} s so far)",
                          config_.static_window_s, last_.window_s);
    return std::nullopt;
  }

  // Excitation: spread of the twice low-passed signal over the part of the window where it is defined.
  std::vector<Sample6> raw;
  raw.reserve(samples_.size());
  Eigen::Vector3d accel_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_mean = Eigen::Vector3d::Zero();
  for (const ImuSample& s : samples_) {
    raw.push_back(Sample6{s.t_ns, s.accel_mps2, s.gyro_radps});
    accel_mean += s.accel_mps2;
    gyro_mean += s.gyro_radps;
  }
  accel_mean /= static_cast<double>(samples_.size());
  gyro_mean /= static_cast<double>(samples_.size());
  const Timestamp lowpass_ns = s_to_ns(config_.static_lowpass_s);
  const std::vector<Sample6> low = moving_average(moving_average(raw, lowpass_ns), lowpass_ns);
  std::vector<Eigen::Vector3d> a;
  std::vector<Eigen::Vector3d> g;
  for (const Sample6& s : low) {
    a.push_back(s.accel);
    g.push_back(s.gyro);
  }
  last_.accel_mps2 = max_axis_std(a);
  last_.gyro_radps = max_axis_std(g);
  last_.gravity_mps2 = accel_mean.norm();
  // Image motion: the median over the window's images of their median feature motion, so that one jolt
  // (or one badly tracked image) does not veto a still window, while a steady motion shows in every image.
  std::vector<double> motions;
  for (const ImageMotion& m : images_)
    if (m.disparity_px >= 0.0) motions.push_back(m.disparity_px);
  const int images_known = static_cast<int>(motions.size());
  if (!motions.empty()) {
    const auto mid = motions.begin() + static_cast<std::ptrdiff_t>(motions.size() / 2);
    std::nth_element(motions.begin(), mid, motions.end());
    last_.disparity_px = *mid;
  }

  const std::string numbers = fmt::format(
      "low-passed accelerometer spread {:.4f} m/s2 (limit {:.4f}), gyro {:.5f} rad/s (limit {:.5f}), median "
      "image motion {} (limit {:.2f} px), specific force {:.3f} m/s2 over {:.2f} s",
      last_.accel_mps2, last_.accel_limit_mps2, last_.gyro_radps, last_.gyro_limit_radps,
      images_known > 0
          ? fmt::format("{:.2f} px", last_.disparity_px)
          : fmt::format("unknown (fewer than {} features tracked between images)", config_.zupt_min_features),
      last_.disparity_limit_px, last_.gravity_mps2, last_.window_s);
  std::vector<std::string> why;
  if (last_.accel_mps2 < 0.0 || last_.gyro_radps < 0.0) why.emplace_back("too few IMU samples to low-pass");
  if (last_.accel_mps2 > last_.accel_limit_mps2) why.emplace_back("accelerometer moving");
  if (last_.gyro_radps > last_.gyro_limit_radps) why.emplace_back("gyro turning");
  if (images_known == 0) why.emplace_back("no image motion measured");
  if (images_known > 0 && last_.disparity_px > last_.disparity_limit_px) why.emplace_back("image moving");
  // The mean specific force of a still platform is gravity; 10% off means an accelerating platform or a
  // badly scaled accelerometer.
  if (std::abs(last_.gravity_mps2 - config_.gravity_mps2) > 0.1 * config_.gravity_mps2)
    why.emplace_back("specific force is not gravity");
  if (!why.empty()) {
    std::string list;
    for (const std::string& w : why) list += (list.empty() ? "" : ", ") + w;
    status_ = "static: not still (" + list + "): " + numbers;
    return std::nullopt;
  }

  // R_w_i maps the mean specific force (up, in the IMU frame) onto +z; the yaw of the IMU x axis is zero.
  Eigen::Matrix3d R_w_i =
      Eigen::Quaterniond::FromTwoVectors(accel_mean, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const double yaw = std::atan2(R_w_i(1, 0), R_w_i(0, 0));
  R_w_i = Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R_w_i;

  InitialState init;
  init.method = InitMethod::kStatic;
  init.frame = index;
  init.state.t_ns = frame.t_ns;
  init.state.q_w_i = Eigen::Quaterniond(R_w_i);
  init.state.gyro_bias_radps = gyro_mean;
  init.state.omega_i_radps = Eigen::Vector3d::Zero();
  // Roll and pitch: an accelerometer bias of its prior sigma tilts the mean specific force by sigma / g.
  const double tilt_sigma =
      std::max(config_.init_sigma_rot_rad, config_.init_sigma_accel_bias_mps2 / config_.gravity_mps2);
  init.rot_cov_world = Eigen::Vector3d(tilt_sigma * tilt_sigma, tilt_sigma * tilt_sigma,
                                       config_.init_sigma_yaw_rad * config_.init_sigma_yaw_rad)
                           .asDiagonal();
  init.vel_cov_m2ps2 = Eigen::Matrix3d::Identity() * std::pow(config_.init_sigma_vel_mps, 2);
  // The mean of white noise over the window, plus what the low-passed signal still varied by.
  const double bias_var =
      std::pow(noise_.gyro_noise_density, 2) / last_.window_s + std::pow(last_.gyro_radps, 2);
  init.gyro_bias_cov = Eigen::Matrix3d::Identity() * bias_var;
  init.scale = 1.0;
  init.window_s = last_.window_s;
  init.detail = "still: " + numbers;
  status_ = "static: initialised at image " + std::to_string(index) + ": " + numbers;
  return init;
}

}  // namespace loopgate
