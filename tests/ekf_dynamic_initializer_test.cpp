// DynamicInitializer on synthetic data: a smooth 3-D motion (a circle with a vertical sinusoid and a rolling
// body), an IMU at 200 Hz with white noise, vibration, a gyro bias and an accelerometer bias, and landmarks
// on a cylinder seen by a camera at 20 Hz as noisy normalised coordinates with stable ids.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "ekf_sim_support.hpp"
#include "stages/ekf/dynamic_initializer.hpp"

namespace loopgate {
namespace {

using ekf_test::CircleMotion;

constexpr double kFocalPx = 460.0;

Eigen::Isometry3d camera_in_imu() {
  // The camera looks along the body x axis (radially outwards on the circle).
  Eigen::Matrix3d R_b_c;
  R_b_c.col(0) = Eigen::Vector3d(0, -1, 0);
  R_b_c.col(1) = Eigen::Vector3d(0, 0, -1);
  R_b_c.col(2) = Eigen::Vector3d(1, 0, 0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R_b_c;
  T.translation() = Eigen::Vector3d(0.05, 0.02, -0.01);
  return T;
}

struct Scenario {
  CircleMotion motion;
  double t0_s = 1.0;
  double duration_s = 6.0;
  Eigen::Vector3d gyro_bias = Eigen::Vector3d(0.01, -0.02, 0.015);
  Eigen::Vector3d accel_bias = Eigen::Vector3d(0.05, -0.08, 0.06);
  double vibration_mps2 = 0.2;  // per axis, 37 Hz
  double pixel_noise_px = 0.5;
  // Of the white-noise densities in simulate() (10x the EuRoC ADIS16448): 0.3 is 3x EuRoC. The start in
  // motion passes up to 5x; at 10x, over the 2 s window, the scale comes out about 7% off (the IMU noise
  // integrated over the window, which the alignment takes as exact, is what is left).
  double imu_noise_scale = 0.3;
  bool features = true;
  // Before this time (from t0_s) each image keeps only every tenth landmark: a stretch of too few features
  // for the structure from motion, as on small images where tracks end early.
  double textured_from_s = 0.0;
  // Flips the sign of gravity in the IMU data only (a corrupted input the truth does not follow).
  bool flip_gravity_in_imu = false;
};

struct Data {
  std::vector<ImuSample> imu;
  std::vector<Timestamp> image_t_ns;
  std::vector<std::vector<FeatureObservation>> observations;
};

Data simulate(const Scenario& sc) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01(0.0, 1.0);
  Data d;
  const double rate_hz = 200.0;
  const double dt = 1.0 / rate_hz;
  const double gyro_nd = 0.0017 * sc.imu_noise_scale;  // rad/s/sqrt(Hz), 10x the EuRoC ADIS16448
  const double accel_nd = 0.02 * sc.imu_noise_scale;   // m/s^2/sqrt(Hz)
  const auto count = static_cast<long>(std::llround(sc.duration_s * rate_hz));
  for (long k = 0; k <= count; ++k) {
    const double t = sc.t0_s + static_cast<double>(k) * dt;
    ImuSample s;
    s.t_ns = s_to_ns(t);
    const double vib = std::sin(2.0 * std::numbers::pi * 37.0 * t);
    Eigen::Vector3d f = sc.motion.accel(t);
    if (sc.flip_gravity_in_imu) {
      f = sc.motion.rotation(t).transpose() *
          (sc.motion.acceleration(t) - Eigen::Vector3d(0, 0, sc.motion.gravity_mps2));
    }
    s.gyro_radps = sc.motion.gyro(t) + sc.gyro_bias + 0.01 * vib * Eigen::Vector3d(1, -1, 1) +
                   gyro_nd / std::sqrt(dt) * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    s.accel_mps2 = f + sc.accel_bias + sc.vibration_mps2 * vib * Eigen::Vector3d(1, 1, -1) +
                   accel_nd / std::sqrt(dt) * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    d.imu.push_back(s);
  }
  // Landmarks between 5 and 12 m from the circle's centre.
  std::uniform_real_distribution<double> angle(-std::numbers::pi, std::numbers::pi);
  std::uniform_real_distribution<double> height(-3.0, 3.0);
  std::uniform_real_distribution<double> radius(5.0, 12.0);
  std::vector<Eigen::Vector3d> landmarks;
  for (int i = 0; i < 1500; ++i) {
    const double a = angle(rng);
    const double r = radius(rng);
    landmarks.emplace_back(r * std::cos(a), r * std::sin(a), height(rng));
  }
  const Eigen::Isometry3d T_i_c = camera_in_imu();
  const auto images = static_cast<long>(std::floor(sc.duration_s * 20.0));
  for (long k = 1; k < images; ++k) {  // the first image after the first IMU sample
    const double t = sc.t0_s + static_cast<double>(k) / 20.0;
    d.image_t_ns.push_back(s_to_ns(t));
    const Eigen::Isometry3d T_c_w = (sc.motion.pose(t) * T_i_c).inverse();
    std::vector<FeatureObservation> obs;
    if (sc.features) {
      for (std::size_t i = 0; i < landmarks.size(); ++i) {
        if (t - sc.t0_s < sc.textured_from_s && i % 10 != 0) continue;
        const Eigen::Vector3d p = T_c_w * landmarks[i];
        if (p.z() < 0.5) continue;
        const Eigen::Vector2d xy = p.head<2>() / p.z();
        if (std::abs(xy.x()) > 0.82 || std::abs(xy.y()) > 0.52) continue;  // EuRoC-like field of view
        FeatureObservation o;
        o.id = i;
        o.xy = xy + sc.pixel_noise_px / kFocalPx * Eigen::Vector2d(n01(rng), n01(rng));
        obs.push_back(o);
      }
    }
    d.observations.push_back(std::move(obs));
  }
  return d;
}

struct RunResult {
  std::optional<InitialState> state;
  std::string status;
};

RunResult run(const Data& d, const EkfConfig& config) {
  DynamicInitializer init(config, camera_in_imu(), kFocalPx);
  std::size_t next_imu = 0;
  for (std::size_t k = 0; k < d.image_t_ns.size(); ++k) {
    const std::size_t first = next_imu;
    while (next_imu < d.imu.size() && d.imu[next_imu].t_ns <= d.image_t_ns[k]) ++next_imu;
    InitFrame f;
    f.t_ns = d.image_t_ns[k];
    f.imu = std::span<const ImuSample>(d.imu).subspan(first, next_imu - first);
    f.observations = &d.observations[k];
    std::optional<InitialState> s = init.add_frame(f);
    if (s) return {s, init.status()};
  }
  return {std::nullopt, init.status()};
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

// A start in motion with everything a real sensor adds: 0.5 px feature noise, vibration, and both biases.
TEST(EkfDynamicInitializer, StartInMotionFindsGravityVelocityBiasAndScale) {
  const Scenario sc;
  const Data d = simulate(sc);
  const EkfConfig config;
  const RunResult r = run(d, config);
  ASSERT_TRUE(r.state.has_value()) << r.status;
  const InitialState& s = *r.state;
  EXPECT_EQ(s.method, InitMethod::kDynamic);
  const double t = ns_to_s(s.state.t_ns);
  EXPECT_LE(t - sc.t0_s, 5.0) << s.detail;
  EXPECT_EQ(s.state.t_ns, d.image_t_ns[s.frame]);

  // Gravity in the IMU frame at that time: the world has +z up in both.
  const Eigen::Matrix3d R_true = sc.motion.rotation(t);
  const Eigen::Matrix3d R_est = s.state.q_w_i.toRotationMatrix();
  EXPECT_LT(
      angle_deg(R_est.transpose() * Eigen::Vector3d::UnitZ(), R_true.transpose() * Eigen::Vector3d::UnitZ()),
      2.0)
      << s.detail;
  // The yaw of the output IMU pose is zero.
  EXPECT_NEAR(std::atan2(R_est(1, 0), R_est(0, 0)), 0.0, 1e-9);
  EXPECT_TRUE(s.state.p_w_m.isZero());
  // Velocity, compared in the IMU frame (the world yaw is arbitrary).
  const Eigen::Vector3d v_true_b = R_true.transpose() * sc.motion.velocity(t);
  const Eigen::Vector3d v_est_b = R_est.transpose() * s.state.v_w_mps;
  EXPECT_LT((v_est_b - v_true_b).norm(), 0.1)
      << "true " << v_true_b.transpose() << " est " << v_est_b.transpose() << " | " << s.detail;
  EXPECT_LT((v_est_b - v_true_b).norm() / v_true_b.norm(), 0.07);
  // Gyro bias (the vibration adds no mean).
  EXPECT_LT((s.state.gyro_bias_radps - sc.gyro_bias).norm(), 0.004)
      << s.state.gyro_bias_radps.transpose() << " | " << s.detail;
  // The accelerometer bias: estimated under its prior, so pulled towards zero, never away from the truth.
  EXPECT_LT((s.state.accel_bias_mps2 - sc.accel_bias).norm(), sc.accel_bias.norm())
      << s.state.accel_bias_mps2.transpose() << " | " << s.detail;
  // Scale: the metric translation of the camera over the window.
  const Eigen::Isometry3d T_i_c = camera_in_imu();
  const double true_translation =
      ((sc.motion.pose(t) * T_i_c).translation() - (sc.motion.pose(t - s.window_s) * T_i_c).translation())
          .norm();
  EXPECT_NEAR(s.scale / true_translation, 1.0, 0.05) << s.detail;
  // Covariances: positive definite and not absurd.
  EXPECT_GT(s.rot_cov_world.diagonal().minCoeff(), 0.0);
  EXPECT_LT(s.vel_cov_m2ps2.diagonal().maxCoeff(), 1.0);
  EXPECT_GT(s.gyro_bias_cov.diagonal().minCoeff(), 0.0);
  // The joint covariance the filter starts from: symmetric positive definite, and the true error of the
  // start [tilt, velocity, gyro bias, accelerometer bias] lies within it (Mahalanobis distance below the
  // 99.9% point of chi-square with 12 degrees of freedom, 32.9): a start neither wrong nor over-confident.
  ASSERT_TRUE(s.joint_cov.has_value());
  const Eigen::Matrix<double, 12, 12>& P = *s.joint_cov;
  EXPECT_TRUE(P.isApprox(P.transpose()));
  const Eigen::LLT<Eigen::Matrix<double, 12, 12>> llt(P);
  ASSERT_EQ(llt.info(), Eigen::Success);
  Eigen::Matrix<double, 12, 1> err;
  // R_est = R_true Exp(theta): Exp(theta) turns the estimated up (IMU frame) onto the true one.
  const Eigen::AngleAxisd theta(Eigen::Quaterniond::FromTwoVectors(
      R_est.transpose() * Eigen::Vector3d::UnitZ(), R_true.transpose() * Eigen::Vector3d::UnitZ()));
  err.segment<3>(0) = theta.angle() * theta.axis();
  err.segment<3>(3) = R_est * (v_est_b - v_true_b);
  err.segment<3>(6) = s.state.gyro_bias_radps - sc.gyro_bias;
  err.segment<3>(9) = s.state.accel_bias_mps2 - sc.accel_bias;
  EXPECT_LT(err.dot(llt.solve(err)), 32.9) << "error " << err.transpose() << " | " << s.detail;
  EXPECT_FALSE(s.detail.empty());
}

TEST(EkfDynamicInitializer, CorruptedGravitySignDoesNotGiveTheTrueAttitude) {
  // The same motion with gravity flipped in the accelerometer: whatever the initialiser does, it must not
  // report the true tilt (the comparisons of the test above can fail).
  Scenario sc;
  sc.flip_gravity_in_imu = true;
  const Data d = simulate(sc);
  const RunResult r = run(d, EkfConfig{});
  if (!r.state) SUCCEED() << r.status;
  if (r.state) {
    const double t = ns_to_s(r.state->state.t_ns);
    const Eigen::Matrix3d R_est = r.state->state.q_w_i.toRotationMatrix();
    EXPECT_GT(angle_deg(R_est.transpose() * Eigen::Vector3d::UnitZ(),
                        sc.motion.rotation(t).transpose() * Eigen::Vector3d::UnitZ()),
              90.0);
  }
}

TEST(EkfDynamicInitializer, StaticSensorDoesNotInitialiseAndSaysParallax) {
  Scenario sc;
  sc.motion.radius_m = 0.0;
  sc.motion.omega_radps = 0.0;
  sc.motion.z_amp_m = 0.0;
  sc.motion.roll_amp_rad = 0.0;
  const RunResult r = run(simulate(sc), EkfConfig{});
  EXPECT_FALSE(r.state.has_value()) << (r.state ? r.state->detail : std::string());
  EXPECT_NE(r.status.find("parallax"), std::string::npos) << r.status;
}

TEST(EkfDynamicInitializer, PureRotationDoesNotInitialise) {
  Scenario sc;
  sc.motion.radius_m = 0.0;  // spinning about the vertical at 0.5 rad/s and rolling, IMU in place
  sc.motion.z_amp_m = 0.0;
  const RunResult r = run(simulate(sc), EkfConfig{});
  EXPECT_FALSE(r.state.has_value()) << (r.state ? r.state->detail : std::string());
  EXPECT_TRUE(r.status.find("parallax") != std::string::npos ||
              r.status.find("translation") != std::string::npos)
      << r.status;
}

TEST(EkfDynamicInitializer, TooLittleTranslationDoesNotInitialise) {
  Scenario sc;
  sc.motion.radius_m = 0.02;  // a 2 cm circle: rotation with a little translation
  sc.motion.z_amp_m = 0.01;
  const RunResult r = run(simulate(sc), EkfConfig{});
  EXPECT_FALSE(r.state.has_value()) << (r.state ? r.state->detail : std::string());
  EXPECT_TRUE(r.status.find("parallax") != std::string::npos ||
              r.status.find("translation") != std::string::npos)
      << r.status;
}

TEST(EkfDynamicInitializer, ImagesWithoutFeaturesFailCleanly) {
  Scenario sc;
  sc.features = false;
  const Data d = simulate(sc);
  const RunResult r = run(d, EkfConfig{});
  EXPECT_FALSE(r.state.has_value());
  EXPECT_NE(r.status.find("no features"), std::string::npos) << r.status;

  // A null observation list, images out of order and IMU samples out of order: no crash, a reason.
  DynamicInitializer init(EkfConfig{}, camera_in_imu(), kFocalPx);
  InitFrame f;
  f.t_ns = d.image_t_ns[1];
  f.imu = std::span<const ImuSample>(d.imu).first(20);
  EXPECT_FALSE(init.add_frame(f).has_value());
  EXPECT_NE(init.status().find("no features"), std::string::npos) << init.status();
  f.t_ns = d.image_t_ns[0];
  EXPECT_FALSE(init.add_frame(f).has_value());
  EXPECT_NE(init.status().find("not after the previous image"), std::string::npos) << init.status();
  const std::vector<ImuSample> backwards = {d.imu[10], d.imu[5]};
  f.t_ns = d.image_t_ns[2];
  f.imu = backwards;
  EXPECT_FALSE(init.add_frame(f).has_value());
  EXPECT_NE(init.status().find("IMU sample"), std::string::npos) << init.status();
}

// The window's oldest images see too few features for the structure from motion (a texture-poor stretch);
// the images after it see plenty. The alignment must start on the newer part of the window as soon as it
// holds a well-conditioned pair, not wait until the poor images have left a whole window (2 s).
TEST(EkfDynamicInitializer, FewFeaturesInTheOldestImagesStillStart) {
  Scenario sc;
  sc.textured_from_s = 2.5;
  sc.duration_s = 6.0;
  const Data d = simulate(sc);
  // The poor stretch: fewer features per image than the SfM pair needs.
  const EkfConfig config;
  std::size_t poor_max = 0;
  for (std::size_t k = 0; k < d.image_t_ns.size(); ++k) {
    if (ns_to_s(d.image_t_ns[k]) - sc.t0_s < sc.textured_from_s) {
      poor_max = std::max(poor_max, d.observations[k].size());
    }
  }
  ASSERT_LT(poor_max, static_cast<std::size_t>(config.dynamic_init_min_features));
  const RunResult r = run(d, config);
  ASSERT_TRUE(r.state.has_value()) << r.status;
  const InitialState& s = *r.state;
  const double t = ns_to_s(s.state.t_ns);
  EXPECT_LT(t - sc.t0_s, sc.textured_from_s + config.dynamic_init_window_s) << s.detail;
  EXPECT_LT(s.window_s, 0.95 * config.dynamic_init_window_s) << s.detail;  // a whole window would not
  // And the start is right: gravity, velocity, scale.
  const Eigen::Matrix3d R_true = sc.motion.rotation(t);
  const Eigen::Matrix3d R_est = s.state.q_w_i.toRotationMatrix();
  EXPECT_LT(
      angle_deg(R_est.transpose() * Eigen::Vector3d::UnitZ(), R_true.transpose() * Eigen::Vector3d::UnitZ()),
      2.0)
      << s.detail;
  const Eigen::Vector3d v_true_b = R_true.transpose() * sc.motion.velocity(t);
  const Eigen::Vector3d v_est_b = R_est.transpose() * s.state.v_w_mps;
  // A shorter window fixes the velocity less well; the error must lie within what the start claims.
  EXPECT_LT((v_est_b - v_true_b).norm(), 3.0 * std::sqrt(s.vel_cov_m2ps2.trace())) << s.detail;
  EXPECT_LT((v_est_b - v_true_b).norm() / v_true_b.norm(), 0.2) << s.detail;
}

}  // namespace
}  // namespace loopgate
