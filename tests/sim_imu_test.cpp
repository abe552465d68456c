// IMU synthesis: gravity and frames, the round trip (integrating the noise-free synthetic IMU from the true
// initial state reproduces the trajectory; drift after 60 s printed), noise statistics, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "sim/imu_synth.hpp"
#include "sim/simulator.hpp"
#include "sim/trajectory.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

constexpr double kGravity = 9.81;

struct NavState {
  Eigen::Quaterniond q_w_b;
  Eigen::Vector3d v_w;
  Eigen::Vector3d p_w;
};

struct NavDerivative {
  Eigen::Vector4d dq;  // quaternion coefficients (w, x, y, z)
  Eigen::Vector3d dv;
  Eigen::Vector3d dp;
};

NavDerivative derivative(const NavState& s, const Eigen::Vector3d& gyro, const Eigen::Vector3d& accel,
                         const Eigen::Vector3d& g_w) {
  const Eigen::Quaterniond omega(0.0, gyro.x(), gyro.y(), gyro.z());
  const Eigen::Quaterniond qdot = s.q_w_b * omega;
  NavDerivative d;
  d.dq = 0.5 * Eigen::Vector4d(qdot.w(), qdot.x(), qdot.y(), qdot.z());
  d.dv = s.q_w_b.normalized().toRotationMatrix() * accel + g_w;
  d.dp = s.v_w;
  return d;
}

NavState step(const NavState& s, const NavDerivative& d, double h) {
  NavState out;
  out.q_w_b = Eigen::Quaterniond(s.q_w_b.w() + h * d.dq[0], s.q_w_b.x() + h * d.dq[1],
                                 s.q_w_b.y() + h * d.dq[2], s.q_w_b.z() + h * d.dq[3]);
  out.v_w = s.v_w + h * d.dv;
  out.p_w = s.p_w + h * d.dp;
  return out;
}

// RK4 strapdown integration between consecutive samples, measurements linearly interpolated in time.
NavState integrate(const NavState& start, const std::vector<ImuSample>& imu, std::size_t last,
                   const Eigen::Vector3d& g_w) {
  NavState s = start;
  for (std::size_t k = 0; k < last; ++k) {
    const double h = ns_to_s(imu[k + 1].t_ns - imu[k].t_ns);
    const Eigen::Vector3d w0 = imu[k].gyro_radps, w1 = imu[k + 1].gyro_radps;
    const Eigen::Vector3d a0 = imu[k].accel_mps2, a1 = imu[k + 1].accel_mps2;
    const Eigen::Vector3d wm = 0.5 * (w0 + w1), am = 0.5 * (a0 + a1);
    const NavDerivative k1 = derivative(s, w0, a0, g_w);
    const NavDerivative k2 = derivative(step(s, k1, 0.5 * h), wm, am, g_w);
    const NavDerivative k3 = derivative(step(s, k2, 0.5 * h), wm, am, g_w);
    const NavDerivative k4 = derivative(step(s, k3, h), w1, a1, g_w);
    NavDerivative sum;
    sum.dq = (k1.dq + 2.0 * k2.dq + 2.0 * k3.dq + k4.dq) / 6.0;
    sum.dv = (k1.dv + 2.0 * k2.dv + 2.0 * k3.dv + k4.dv) / 6.0;
    sum.dp = (k1.dp + 2.0 * k2.dp + 2.0 * k3.dp + k4.dp) / 6.0;
    s = step(s, sum, h);
    s.q_w_b.normalize();
  }
  return s;
}

ImuCalibration noise_free() {
  return ImuCalibration{};
}

// Integrates the noise-free IMU over `duration_s` and returns the final position error (m).
double round_trip_drift_m(const SplineTrajectory& trajectory, const Eigen::Vector3d& up_w, double duration_s,
                          double* rotation_error_rad) {
  ImuSynthConfig config;
  config.add_noise = false;
  const Timestamp t0 = trajectory.start_t_ns();
  const Timestamp t1 = std::min(trajectory.end_t_ns(), t0 + s_to_ns(duration_s));
  const SyntheticImu imu = synthesize_imu(trajectory, up_w, noise_free(), config, 1, t0, t1);
  const TrajectoryState first = trajectory.evaluate(imu.samples.front().t_ns);
  NavState start{Eigen::Quaterniond(first.T_w_b.linear()), first.v_w_mps, first.T_w_b.translation()};
  const NavState end = integrate(start, imu.samples, imu.samples.size() - 1, -kGravity * up_w);
  const TrajectoryState truth = trajectory.evaluate(imu.samples.back().t_ns);
  *rotation_error_rad = so3_log(truth.T_w_b.linear().transpose() * end.q_w_b.toRotationMatrix()).norm();
  return (end.p_w - truth.T_w_b.translation()).norm();
}

TEST(ImuSynth, StaticBodyMeasuresGravityUp) {
  std::vector<StampedPose> poses(4);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    poses[i].t_ns = static_cast<Timestamp>(i) * 100'000'000;
    poses[i].T_w_b.linear() =
        Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  }
  const SplineTrajectory trajectory = SplineTrajectory::fit(poses);
  const Eigen::Vector3d up_w(0.0, -1.0, 0.0);  // KITTI camera world
  const ImuSample s = ideal_imu_sample(trajectory.evaluate(150'000'000), up_w, kGravity);
  const Eigen::Vector3d up_b = poses[0].T_w_b.linear().transpose() * up_w;
  EXPECT_LT((s.accel_mps2 - kGravity * up_b).norm(), 1e-9);
  EXPECT_LT(s.gyro_radps.norm(), 1e-9);
}

TEST(ImuSynth, RoundTripOnTheProceduralCircuit) {
  const SplineTrajectory trajectory = SplineTrajectory::fit(make_procedural_route(ProceduralRouteConfig{}));
  double rotation_error_rad = 0.0;
  const double drift_m = round_trip_drift_m(trajectory, Eigen::Vector3d::UnitZ(), 60.0, &rotation_error_rad);
  std::printf("IMU round trip, procedural circuit (%.1f s): position drift %.4g m, rotation error %.3g rad\n",
              ns_to_s(trajectory.end_t_ns() - trajectory.start_t_ns()), drift_m, rotation_error_rad);
  ::testing::Test::RecordProperty("circuit_drift_m", std::to_string(drift_m));
  EXPECT_LT(drift_m, 0.05);
  EXPECT_LT(rotation_error_rad, 1e-4);
}

TEST(ImuSynth, RoundTripOnTheDemoRoute) {
  // The demo preset's waypoint route with the preset's fit (its corners are curvature steps).
  const SimulationConfig demo = make_preset("demo", "");
  const SplineTrajectory trajectory = SplineTrajectory::fit(make_procedural_route(demo.route), demo.fit);
  double rotation_error_rad = 0.0;
  const double drift_m = round_trip_drift_m(trajectory, Eigen::Vector3d::UnitZ(), 60.0, &rotation_error_rad);
  std::printf("IMU round trip, demo route (%.1f s): position drift %.4g m, rotation error %.3g rad\n",
              ns_to_s(trajectory.end_t_ns() - trajectory.start_t_ns()), drift_m, rotation_error_rad);
  ::testing::Test::RecordProperty("demo_drift_m", std::to_string(drift_m));
  EXPECT_LT(drift_m, 0.05);
  EXPECT_LT(rotation_error_rad, 1e-4);
}

TEST(ImuSynth, RoundTripOnKitti00First60Seconds) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/poses.txt");
  const auto dir = loopgate::testing::shared_data_dir() / "kitti" / "00";
  const SplineTrajectory trajectory =
      SplineTrajectory::fit(load_kitti_trajectory(dir / "poses.txt", dir / "times.txt"));
  double rotation_error_rad = 0.0;
  const double drift_m =
      round_trip_drift_m(trajectory, Eigen::Vector3d(0.0, -1.0, 0.0), 60.0, &rotation_error_rad);
  std::printf("IMU round trip, KITTI 00 first 60 s: position drift %.4g m, rotation error %.3g rad\n",
              drift_m, rotation_error_rad);
  ::testing::Test::RecordProperty("kitti00_drift_60s_m", std::to_string(drift_m));
  EXPECT_LT(drift_m, 0.5);
}

TEST(ImuSynth, RoundTripOnMh05First60Seconds) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/MH_05_difficult/mav0/state_groundtruth_estimate0/data.csv");
  TrajectoryFitConfig fit;
  fit.knot_spacing_s = 0.025;
  const SplineTrajectory trajectory = SplineTrajectory::fit(
      load_euroc_trajectory(loopgate::testing::shared_data_dir() / "euroc/MH_05_difficult/mav0/"
                                                                   "state_groundtruth_estimate0/data.csv"),
      fit);
  double rotation_error_rad = 0.0;
  const double drift_m = round_trip_drift_m(trajectory, Eigen::Vector3d::UnitZ(), 60.0, &rotation_error_rad);
  std::printf("IMU round trip, MH_05 first 60 s: position drift %.4g m, rotation error %.3g rad\n", drift_m,
              rotation_error_rad);
  EXPECT_LT(drift_m, 0.5);
}

TEST(ImuSynth, NoiseMatchesTheCalibration) {
  const SplineTrajectory trajectory = SplineTrajectory::fit(make_procedural_route(ProceduralRouteConfig{}));
  ImuCalibration calib;
  calib.gyro_noise_density = 1.6968e-04;
  calib.gyro_random_walk = 1.9393e-05;
  calib.accel_noise_density = 2.0e-3;
  calib.accel_random_walk = 3.0e-3;
  ImuSynthConfig noisy;
  ImuSynthConfig clean;
  clean.add_noise = false;
  const Timestamp t0 = trajectory.start_t_ns();
  const Timestamp t1 = trajectory.end_t_ns();
  const SyntheticImu a = synthesize_imu(trajectory, Eigen::Vector3d::UnitZ(), calib, noisy, 42, t0, t1);
  const SyntheticImu ideal = synthesize_imu(trajectory, Eigen::Vector3d::UnitZ(), calib, clean, 42, t0, t1);
  ASSERT_EQ(a.samples.size(), ideal.samples.size());
  ASSERT_GT(a.samples.size(), 11000u);
  EXPECT_EQ(a.samples[1].t_ns - a.samples[0].t_ns, 5'000'000);
  // White noise = measured - ideal - bias.
  double sum_g2 = 0.0, sum_a2 = 0.0;
  for (std::size_t k = 0; k < a.samples.size(); ++k) {
    sum_g2 += (a.samples[k].gyro_radps - ideal.samples[k].gyro_radps - a.gyro_bias_radps[k]).squaredNorm();
    sum_a2 += (a.samples[k].accel_mps2 - ideal.samples[k].accel_mps2 - a.accel_bias_mps2[k]).squaredNorm();
  }
  const double n3 = 3.0 * static_cast<double>(a.samples.size());
  const double gyro_sigma = std::sqrt(sum_g2 / n3);
  const double accel_sigma = std::sqrt(sum_a2 / n3);
  EXPECT_NEAR(gyro_sigma, calib.gyro_noise_density * std::sqrt(200.0), 0.03 * gyro_sigma);
  EXPECT_NEAR(accel_sigma, calib.accel_noise_density * std::sqrt(200.0), 0.03 * accel_sigma);
  // Bias random walk: step sigma = random_walk / sqrt(rate).
  double sum_db2 = 0.0;
  for (std::size_t k = 1; k < a.samples.size(); ++k) {
    sum_db2 += (a.accel_bias_mps2[k] - a.accel_bias_mps2[k - 1]).squaredNorm();
  }
  const double step_sigma = std::sqrt(sum_db2 / (3.0 * static_cast<double>(a.samples.size() - 1)));
  EXPECT_NEAR(step_sigma, calib.accel_random_walk / std::sqrt(200.0), 0.03 * step_sigma);
}

TEST(ImuSynth, DeterministicPerSeed) {
  const SplineTrajectory trajectory = SplineTrajectory::fit(make_procedural_route(ProceduralRouteConfig{}));
  ImuCalibration calib;
  calib.gyro_noise_density = 1e-4;
  calib.accel_noise_density = 1e-3;
  ImuSynthConfig config;
  const Timestamp t0 = trajectory.start_t_ns();
  const Timestamp t1 = t0 + 2'000'000'000;
  const auto a = synthesize_imu(trajectory, Eigen::Vector3d::UnitZ(), calib, config, 7, t0, t1);
  const auto b = synthesize_imu(trajectory, Eigen::Vector3d::UnitZ(), calib, config, 7, t0, t1);
  const auto c = synthesize_imu(trajectory, Eigen::Vector3d::UnitZ(), calib, config, 8, t0, t1);
  ASSERT_EQ(a.samples.size(), 401u);
  bool same_b = true, same_c = true;
  for (std::size_t k = 0; k < a.samples.size(); ++k) {
    same_b = same_b && a.samples[k].gyro_radps == b.samples[k].gyro_radps &&
             a.samples[k].accel_mps2 == b.samples[k].accel_mps2;
    same_c = same_c && a.samples[k].gyro_radps == c.samples[k].gyro_radps;
  }
  EXPECT_TRUE(same_b);
  EXPECT_FALSE(same_c);
}

TEST(ImuSynth, RejectsAnImuOffTheBody) {
  const SplineTrajectory trajectory = SplineTrajectory::fit(make_procedural_route(ProceduralRouteConfig{}));
  ImuCalibration calib;
  calib.T_b_i.translation() = Eigen::Vector3d(0.1, 0.0, 0.0);
  EXPECT_THROW(
      synthesize_imu(trajectory, Eigen::Vector3d::UnitZ(), calib, ImuSynthConfig{}, 1, 0, 1'000'000'000),
      ConfigError);
  ImuSynthConfig bad;
  bad.rate_hz = 0.0;
  EXPECT_THROW(bad.validate(), ConfigError);
}

TEST(GaussianRng, StandardNormalMoments) {
  GaussianRng rng(123);
  double sum = 0.0, sum2 = 0.0;
  constexpr int kN = 200000;
  for (int i = 0; i < kN; ++i) {
    const double x = rng.next();
    sum += x;
    sum2 += x * x;
  }
  EXPECT_NEAR(sum / kN, 0.0, 0.01);
  EXPECT_NEAR(sum2 / kN, 1.0, 0.01);
}

}  // namespace
}  // namespace loopgate::sim
