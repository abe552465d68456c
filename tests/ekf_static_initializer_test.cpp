// The static initialiser (src/stages/ekf/static_initializer.hpp) on synthetic IMU data with known gravity,
// gyro and accelerometer biases and rotor vibration (sinusoids of 50-150 Hz, 0.5-1 m/s2, plus white noise
// of the EuRoC ADIS16448 densities), on a sensor that never stops moving, on a still IMU whose images move
// (constant velocity), and on the real MH_05 IMU before take-off (skipped without ../shared/data).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "io/dataset.hpp"
#include "stages/ekf/static_initializer.hpp"
#include "stages/ekf/vio_ekf.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kImuRateHz = 200.0;
constexpr Timestamp kImageStepNs = 50'000'000;  // 20 Hz
constexpr double kFocalPx = 450.0;

// The EuRoC ADIS16448 densities (imu0 sensor.yaml).
ImuCalibration adis() {
  ImuCalibration imu;
  imu.gyro_noise_density = 1.6968e-4;
  imu.gyro_random_walk = 1.9393e-5;
  imu.accel_noise_density = 2.0e-3;
  imu.accel_random_walk = 3.0e-3;
  return imu;
}

struct Truth {
  Eigen::Matrix3d R_w_i = Eigen::Matrix3d::Identity();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d(0.012, -0.021, 0.015);
  Eigen::Vector3d accel_bias = Eigen::Vector3d(0.05, -0.04, 0.06);
};

// IMU samples at 200 Hz over [0, duration_s]. `motion(t)` gives the platform's own specific-force change
// (IMU frame, m/s2) and angular rate (rad/s) at t; gravity, biases, vibration and noise are added.
template <class Motion>
std::vector<ImuSample> make_imu(const Truth& truth, double duration_s, Motion motion, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> unit(0.0, 1.0);
  const ImuCalibration cal = adis();
  const double sigma_a = cal.accel_noise_density * std::sqrt(kImuRateHz);
  const double sigma_g = cal.gyro_noise_density * std::sqrt(kImuRateHz);
  // Rotor vibration: four sinusoids of 50-150 Hz, 0.5-1 m/s2 on each accelerometer axis (0.05 rad/s on the
  // gyro), phases drawn once.
  const double freq_hz[4] = {52.0, 78.5, 113.0, 147.0};
  const double amp_mps2[4] = {1.0, 0.7, 0.5, 0.8};
  Eigen::Matrix<double, 3, 4> phase;
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) phase(r, c) = angle(rng);
  const Eigen::Vector3d f_gravity_i = truth.R_w_i.transpose() * Eigen::Vector3d(0.0, 0.0, 9.81);
  std::vector<ImuSample> out;
  const int n = static_cast<int>(duration_s * kImuRateHz);
  for (int k = 0; k <= n; ++k) {
    const double t = k / kImuRateHz;
    Eigen::Vector3d vib = Eigen::Vector3d::Zero();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) vib(r) += amp_mps2[c] * std::sin(2.0 * kPi * freq_hz[c] * t + phase(r, c));
    const auto [f_motion, w_motion] = motion(t);
    ImuSample s;
    s.t_ns = static_cast<Timestamp>(std::llround(t * 1e9));
    s.accel_mps2 = f_gravity_i + f_motion + truth.accel_bias + vib +
                   sigma_a * Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
    s.gyro_radps =
        w_motion + truth.gyro_bias + 0.05 * vib + sigma_g * Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
    out.push_back(s);
  }
  return out;
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> still(double /*t*/) {
  return {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
}

// 60 features; each image moves them by shift_px (0: still) plus 0.05 px of localisation noise.
std::vector<FeatureObservation> features(int image, double shift_px, std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, 0.05 / kFocalPx);
  std::vector<FeatureObservation> obs;
  for (int i = 0; i < 60; ++i) {
    const Eigen::Vector2d base(0.04 * (i % 10) - 0.2, 0.05 * (i / 10) - 0.15);
    obs.push_back(
        FeatureObservation{static_cast<std::uint64_t>(i),
                           base + Eigen::Vector2d(image * shift_px / kFocalPx + noise(rng), noise(rng))});
  }
  return obs;
}

struct Outcome {
  std::optional<InitialState> init;
  double t_s = -1;  // time of the image where it succeeded
  std::string status;
};

// Feeds the samples image by image (20 Hz) until the initialiser succeeds or the data end.
Outcome feed(StaticInitializer& initializer, const std::vector<ImuSample>& imu, double shift_px) {
  std::mt19937 rng(7);
  Outcome out;
  std::size_t next = 0;
  for (int image = 0;; ++image) {
    const Timestamp t_ns = image * kImageStepNs;
    if (t_ns > imu.back().t_ns) break;
    const std::size_t begin = next;
    while (next < imu.size() && imu[next].t_ns <= t_ns) ++next;
    const std::vector<FeatureObservation> obs = features(image, shift_px, rng);
    InitFrame frame;
    frame.t_ns = t_ns;
    frame.imu = std::span<const ImuSample>(imu.data() + begin, next - begin);
    frame.observations = &obs;
    out.init = initializer.add_frame(frame);
    out.status = initializer.status();
    if (out.init) {
      out.t_s = ns_to_s(t_ns);
      break;
    }
  }
  return out;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / kPi;
}

TEST(EkfStaticInitializer, LowpassedNoiseMatchesWhiteNoiseThroughTheFilter) {
  // Two moving averages of 0.1 s on white noise of density 0.01: std 0.01 * sqrt(2 / 0.3) = 0.0258.
  EXPECT_NEAR(StaticInitializer::lowpassed_noise_std(0.01, 0.1), 0.0258, 1e-4);
}

TEST(EkfStaticInitializer, VibratingStillStartFindsGravityAndGyroBias) {
  Truth truth;
  truth.R_w_i =
      (Eigen::AngleAxisd(0.9, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.15, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(-0.25, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  const EkfConfig config;
  const std::vector<ImuSample> imu = make_imu(truth, 5.0, still, 1);
  // The raw accelerometer spread is that of a vibrating platform (about 1 m/s2 per axis).
  double raw = 0.0;
  for (std::size_t k = 0; k < 200; ++k) raw += std::pow(imu[k].accel_mps2.x() - imu[0].accel_mps2.x(), 2);
  EXPECT_GT(std::sqrt(raw / 200.0), 0.5);

  StaticInitializer initializer(config, effective_imu_noise(config, adis()), kFocalPx);
  const Outcome out = feed(initializer, imu, 0.0);
  ASSERT_TRUE(out.init.has_value()) << out.status;
  EXPECT_LE(out.t_s, 2.0) << out.status;
  EXPECT_EQ(out.init->method, InitMethod::kStatic);
  const Eigen::Vector3d up_est = out.init->state.q_w_i.conjugate() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d up_true = truth.R_w_i.transpose() * Eigen::Vector3d::UnitZ();
  // The accelerometer bias (0.09 m/s2) tilts the mean specific force by about 0.5 degrees.
  EXPECT_LT(angle_deg(up_est, up_true), 1.0);
  EXPECT_LT((out.init->state.gyro_bias_radps - truth.gyro_bias).norm(), 2e-3);
  EXPECT_TRUE(out.init->state.v_w_mps.isZero());
  EXPECT_TRUE(out.init->state.accel_bias_mps2.isZero());  // left to the filter
  // Yaw zero: the IMU x axis has no world y component.
  const Eigen::Matrix3d R = out.init->state.q_w_i.toRotationMatrix();
  EXPECT_NEAR(R(1, 0), 0.0, 1e-9);
  EXPECT_NE(out.init->detail.find("limit"), std::string::npos);
  std::printf("static start at %.2f s: %s\n", out.t_s, out.init->detail.c_str());
}

TEST(EkfStaticInitializer, SensorThatNeverStopsDoesNotStartAndSaysWhy) {
  const Truth truth;
  const EkfConfig config;
  // A hovering drone: slow swaying of 0.4 m/s2 at 0.7 Hz and a turn rate of 0.1 rad/s at 0.4 Hz.
  const auto sway = [](double t) {
    return std::pair<Eigen::Vector3d, Eigen::Vector3d>{
        Eigen::Vector3d(0.4 * std::sin(2 * kPi * 0.7 * t), 0.3 * std::cos(2 * kPi * 0.5 * t), 0.0),
        Eigen::Vector3d(0.0, 0.0, 0.1 * std::sin(2 * kPi * 0.4 * t))};
  };
  const std::vector<ImuSample> imu = make_imu(truth, 10.0, sway, 2);
  StaticInitializer initializer(config, effective_imu_noise(config, adis()), kFocalPx);
  const Outcome out = feed(initializer, imu, 2.0);
  EXPECT_FALSE(out.init.has_value()) << out.status;
  EXPECT_NE(out.status.find("static: not still"), std::string::npos) << out.status;
  EXPECT_NE(out.status.find("accelerometer moving"), std::string::npos) << out.status;
  EXPECT_NE(out.status.find("gyro turning"), std::string::npos) << out.status;
  EXPECT_NE(out.status.find("image moving"), std::string::npos) << out.status;
  EXPECT_GT(initializer.excitation().accel_mps2, initializer.excitation().accel_limit_mps2);
  EXPECT_GT(initializer.excitation().gyro_radps, initializer.excitation().gyro_limit_radps);
}

// At constant velocity the IMU cannot tell motion from rest: the image motion does.
TEST(EkfStaticInitializer, StillImuWithMovingImagesDoesNotStart) {
  const Truth truth;
  const EkfConfig config;
  const std::vector<ImuSample> imu = make_imu(truth, 5.0, still, 3);
  StaticInitializer initializer(config, effective_imu_noise(config, adis()), kFocalPx);
  const Outcome out = feed(initializer, imu, 1.5);
  EXPECT_FALSE(out.init.has_value()) << out.status;
  EXPECT_NE(out.status.find("image moving"), std::string::npos) << out.status;
  EXPECT_EQ(out.status.find("accelerometer moving"), std::string::npos) << out.status;
  // After reset() it starts again from nothing.
  initializer.reset();
  EXPECT_NE(initializer.status().find("no image"), std::string::npos);
}

// The real MH_05 IMU: the rotors spin while the drone stands (raw accelerometer spread up to 0.1 m/s2 in
// the first seconds, 0.5-1 m/s2 once they spin up); MH_05 here has no images, so still synthetic features
// stand in for them. The rule fires within 2 s and gravity agrees with the ground truth.
TEST(EkfStaticInitializer, RealMh05ImuBeforeTakeOff) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/MH_05_difficult");
  const auto dataset = open_dataset(testing::shared_data_dir() / "euroc/MH_05_difficult");
  ASSERT_TRUE(dataset->imu_calibration().has_value());
  std::vector<ImuSample> imu = dataset->imu_samples();
  ASSERT_GT(imu.size(), 1000u);
  const Timestamp t0 = imu.front().t_ns;
  for (ImuSample& s : imu) s.t_ns -= t0;
  imu.resize(std::min<std::size_t>(imu.size(), 600));  // the first 3 s
  const EkfConfig config;
  StaticInitializer initializer(config, effective_imu_noise(config, *dataset->imu_calibration()), kFocalPx);
  const Outcome out = feed(initializer, imu, 0.0);
  ASSERT_TRUE(out.init.has_value()) << out.status;
  EXPECT_LE(out.t_s, 2.0);
  // The ground truth begins 1.4 s after the IMU, while the drone still stands: compare there at the latest.
  ASSERT_FALSE(dataset->ground_truth().empty());
  const Timestamp t_gt = std::max(t0 + s_to_ns(out.t_s), dataset->ground_truth().front().t_ns);
  const auto gt = ground_truth_state_at(dataset->ground_truth(), t_gt);
  ASSERT_TRUE(gt.has_value());
  const Eigen::Matrix3d R_w_i = gt->T_w_b.rotation() * dataset->imu_calibration()->T_b_i.rotation();
  const Eigen::Vector3d up_true = R_w_i.transpose() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d up_est = out.init->state.q_w_i.conjugate() * Eigen::Vector3d::UnitZ();
  EXPECT_LT(angle_deg(up_est, up_true), 2.0);
  std::printf("MH_05 static start at %.2f s, gravity %.2f deg from the truth: %s\n", out.t_s,
              angle_deg(up_est, up_true), out.init->detail.c_str());
}

}  // namespace
}  // namespace loopgate
