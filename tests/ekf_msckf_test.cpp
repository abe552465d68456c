// The MSCKF on a simulated scene with known truth (no images): landmarks on a cylinder around a circular
// trajectory, projected through a pinhole camera with pixel noise; synthetic IMU with noise and biases.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "core/geometry.hpp"
#include "ekf_sim_support.hpp"
#include "stages/ekf/chi_square.hpp"
#include "stages/ekf/msckf.hpp"

namespace loopgate {
namespace {

using ekf_test::CircleMotion;
using ekf_test::ImuNoiseSim;

constexpr double kFocalPx = 460.0;
constexpr double kCx = 376.0;
constexpr double kCy = 240.0;
constexpr int kWidth = 752;
constexpr int kHeight = 480;

// Camera looking outwards (body x), x right = body -y, y down = body -z; slightly offset from the IMU.
Eigen::Isometry3d camera_to_imu() {
  Eigen::Matrix3d R_i_c;
  R_i_c.col(0) = Eigen::Vector3d(0.0, -1.0, 0.0);
  R_i_c.col(1) = Eigen::Vector3d(0.0, 0.0, -1.0);
  R_i_c.col(2) = Eigen::Vector3d(1.0, 0.0, 0.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R_i_c;
  T.translation() = Eigen::Vector3d(0.05, -0.02, 0.01);
  return T;
}

std::vector<Eigen::Vector3d> make_landmarks(std::mt19937_64* rng) {
  std::uniform_real_distribution<double> angle(0.0, 2.0 * M_PI);
  std::uniform_real_distribution<double> height(-2.5, 3.0);
  std::uniform_real_distribution<double> radius(7.0, 9.0);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 1000; ++i) {
    const double a = angle(*rng);
    const double r = radius(*rng);
    points.emplace_back(r * std::cos(a), r * std::sin(a), height(*rng));
  }
  return points;
}

struct RunSettings {
  std::uint64_t seed = 1;
  double duration_s = 20.0;
  double camera_rate_hz = 10.0;
  double imu_rate_hz = 200.0;
  bool noisy = true;
  double pixel_sigma_px = 1.0;
};

struct RunResult {
  std::vector<double> nees_position;
  std::vector<double> nees_rotation;
  std::vector<double> position_error_m;
  // 6-dof NEES of the body pose relative to the oldest clone of the window (Msckf::relative_pose).
  std::vector<double> nees_relative;
  double final_position_error_m = 0;
  double final_rotation_error_rad = 0;
  int features_used = 0;
  int rejected_chi2 = 0;
  bool healthy = true;
};

RunResult run_filter(const RunSettings& settings) {
  const CircleMotion motion;
  std::mt19937_64 rng(settings.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  const std::vector<Eigen::Vector3d> landmarks = make_landmarks(&rng);
  const Eigen::Isometry3d T_i_c = camera_to_imu();

  EkfConfig config;
  config.pixel_sigma_px = settings.pixel_sigma_px > 0.0 ? settings.pixel_sigma_px : 0.1;
  config.init_sigma_gyro_bias_radps = 0.002;
  // LOOPGATE_EKF_FEJ=1: first-estimate Jacobians on (off by default, see ekf_config.hpp), to compare by hand.
  if (std::getenv("LOOPGATE_EKF_FEJ") != nullptr) config.first_estimate_jacobians = true;
  config.init_sigma_accel_bias_mps2 = 0.02;
  const ImuNoise noise{1.6968e-04, 1.9393e-05, 2.0e-3, 3.0e-3};
  ImuNoiseSim sim_noise;
  if (settings.noisy)
    sim_noise = {noise.gyro_noise_density, noise.gyro_random_walk, noise.accel_noise_density,
                 noise.accel_random_walk};

  // Initial covariance and an initial error drawn from it (noisy runs).
  Eigen::Matrix<double, kImuErrorDim, 1> sigmas;
  sigmas << Eigen::Vector3d::Constant(config.init_sigma_rot_rad),
      Eigen::Vector3d::Constant(config.init_sigma_pos_m),
      Eigen::Vector3d::Constant(config.init_sigma_vel_mps),
      Eigen::Vector3d::Constant(config.init_sigma_gyro_bias_radps),
      Eigen::Vector3d::Constant(config.init_sigma_accel_bias_mps2);
  const ImuMatrix P0 = sigmas.array().square().matrix().asDiagonal();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();
  ImuState init;
  init.t_ns = 0;
  init.q_w_i = Eigen::Quaterniond(motion.rotation(0.0));
  init.p_w_m = motion.position(0.0);
  init.v_w_mps = motion.velocity(0.0);
  if (settings.noisy) {
    Eigen::Matrix<double, kImuErrorDim, 1> dx;
    for (int i = 0; i < kImuErrorDim; ++i) dx(i) = sigmas(i) * n01(rng);
    init.apply_correction(-dx);  // truth = estimate (+) dx
    // The true biases are drawn from the prior; the estimate starts at zero.
    gyro_bias = dx.segment<3>(9);
    accel_bias = dx.segment<3>(12);
  }
  const std::vector<ImuSample> imu = ekf_test::make_imu(
      motion, 0.0, settings.duration_s + 0.1, settings.imu_rate_hz, sim_noise, &rng, &gyro_bias, &accel_bias);

  Msckf filter(config, noise, T_i_c, kFocalPx);
  filter.initialize(init, P0);
  RunResult result;
  const double sigma_norm = settings.pixel_sigma_px / kFocalPx;
  const auto frames = static_cast<int>(settings.duration_s * settings.camera_rate_hz);
  std::size_t imu_begin = 0;
  for (int k = 0; k <= frames; ++k) {
    const double t = static_cast<double>(k) / settings.camera_rate_hz;
    const Timestamp t_ns = s_to_ns(t);
    std::size_t imu_end = imu_begin;
    while (imu_end < imu.size() && imu[imu_end].t_ns <= t_ns) ++imu_end;
    const std::span<const ImuSample> slice(imu.data() + imu_begin, imu_end - imu_begin);
    imu_begin = imu_end > 0 ? imu_end - 1 : 0;

    const Eigen::Isometry3d T_w_c = motion.pose(t) * T_i_c;
    const Eigen::Isometry3d T_c_w = T_w_c.inverse();
    std::vector<FeatureObservation> observations;
    for (std::size_t id = 0; id < landmarks.size(); ++id) {
      const Eigen::Vector3d p_c = T_c_w * landmarks[id];
      if (p_c.z() < 0.3) continue;
      const Eigen::Vector2d xy = p_c.head<2>() / p_c.z();
      const double u = kFocalPx * xy.x() + kCx;
      const double v = kFocalPx * xy.y() + kCy;
      if (u < 0 || v < 0 || u > kWidth - 1 || v > kHeight - 1) continue;
      FeatureObservation obs;
      obs.id = id;
      obs.xy = xy + sigma_norm * Eigen::Vector2d(n01(rng), n01(rng));
      observations.push_back(obs);
    }
    const MsckfUpdateStats stats = filter.process_frame(t_ns, slice, observations);
    result.features_used += stats.used_features;
    result.rejected_chi2 += stats.rejected_chi2;
    std::string reason;
    if (!filter.healthy(&reason)) {
      ADD_FAILURE() << "filter unhealthy at frame " << k << ": " << reason;
      result.healthy = false;
      return result;
    }
    const PoseEstimate est = filter.pose_estimate(Eigen::Isometry3d::Identity());
    const Eigen::Isometry3d T_true = motion.pose(t);
    const Eigen::Vector3d e_p = T_true.translation() - est.T_w_b.translation();
    const Eigen::Vector3d e_r = so3_log(est.T_w_b.rotation().transpose() * T_true.rotation());
    const Eigen::Matrix3d P_p = est.cov.topLeftCorner<3, 3>();
    const Eigen::Matrix3d P_r = est.cov.bottomRightCorner<3, 3>();
    result.nees_position.push_back(e_p.dot(P_p.ldlt().solve(e_p)));
    result.nees_rotation.push_back(e_r.dot(P_r.ldlt().solve(e_r)));
    result.position_error_m.push_back(e_p.norm());
    if (filter.clones().size() >= 2) {
      // A body frame apart from the IMU's, so that the extrinsic's terms are exercised.
      Eigen::Isometry3d T_b_i = Eigen::Isometry3d::Identity();
      T_b_i.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
      T_b_i.translation() = Eigen::Vector3d(3.0, -2.0, 5.0);  // metres: its lever arm must show
      const auto [T_r_b, cov] = filter.relative_pose(0, T_b_i);
      const double t_r = ns_to_s(filter.clones().front().t_ns);
      const Eigen::Isometry3d T_r_b_true =
          (motion.pose(t_r) * T_b_i.inverse()).inverse() * (T_true * T_b_i.inverse());
      Eigen::Matrix<double, 6, 1> e;
      e.head<3>() = T_r_b_true.translation() - T_r_b.translation();
      e.tail<3>() = so3_log(T_r_b.rotation().transpose() * T_r_b_true.rotation());
      result.nees_relative.push_back(e.dot(cov.ldlt().solve(e)));
    }
    result.final_position_error_m = e_p.norm();
    result.final_rotation_error_rad = e_r.norm();
  }
  return result;
}

// Seeds of the Monte-Carlo runs (LOOPGATE_EKF_SEED_BASE overrides, to check other draws by hand).
std::uint64_t seed_base() {
  const char* env = std::getenv("LOOPGATE_EKF_SEED_BASE");
  return env != nullptr ? std::strtoull(env, nullptr, 10) : 100;
}

TEST(EkfMsckf, NoiseFreeRunDriftsLessThanOneCentimetreIn30s) {
  RunSettings settings;
  settings.noisy = false;
  settings.pixel_sigma_px = 0.0;
  settings.duration_s = 30.0;
  const RunResult result = run_filter(settings);
  ASSERT_TRUE(result.healthy);
  double max_error = 0.0;
  for (double e : result.position_error_m) max_error = std::max(max_error, e);
  std::printf("noise-free 30 s: max position error %.5f m, final rotation error %.2e rad\n", max_error,
              result.final_rotation_error_rad);
  EXPECT_LT(max_error, 0.01);
  EXPECT_LT(result.final_rotation_error_rad, 1e-3);
  EXPECT_GT(result.features_used, 1000);  // the updates really ran
}

// The relative pose's covariance (the pose graph's odometry edges, posegraph.odometry_cov odometry) is as
// consistent as the filter: its NEES against the true relative pose over the window.
TEST(EkfMsckf, RelativePoseNeesInsideThe95PercentBoundsOverMonteCarloRuns) {
  constexpr int kRuns = 5;
  double sum = 0.0;
  std::size_t count = 0;
  for (int run = 0; run < kRuns; ++run) {
    RunSettings settings;
    settings.seed = seed_base() + static_cast<std::uint64_t>(run);
    const RunResult result = run_filter(settings);
    ASSERT_TRUE(result.healthy);
    ASSERT_GT(result.nees_relative.size(), 100u);
    for (std::size_t k = 10; k < result.nees_relative.size(); ++k) {
      sum += result.nees_relative[k];
      ++count;
    }
  }
  const double nees = sum / static_cast<double>(count);
  const double lower = chi_square_quantile(0.025, 6 * kRuns) / kRuns;
  const double upper = chi_square_quantile(0.975, 6 * kRuns) / kRuns;
  std::printf("average NEES of the pose relative to the oldest clone %.3f, bounds [%.3f, %.3f]\n", nees,
              lower, upper);
  EXPECT_GT(nees, lower);
  EXPECT_LT(nees, upper);
}

TEST(EkfMsckf, NeesInsideThe95PercentBoundsOverMonteCarloRuns) {
  constexpr int kRuns = 5;
  std::vector<double> mean_nees_p;
  std::vector<double> mean_nees_r;
  double sum_p = 0.0;
  double sum_r = 0.0;
  std::size_t count = 0;
  int used = 0;
  int rejected = 0;
  for (int run = 0; run < kRuns; ++run) {
    RunSettings settings;
    settings.seed = seed_base() + static_cast<std::uint64_t>(run);
    const RunResult result = run_filter(settings);
    ASSERT_TRUE(result.healthy);
    for (std::size_t k = 10; k < result.nees_position.size(); ++k) {  // after the first second
      sum_p += result.nees_position[k];
      sum_r += result.nees_rotation[k];
      ++count;
    }
    if (std::getenv("LOOPGATE_EKF_NEES_BINS") != nullptr) {
      for (std::size_t b = 0; b + 20 <= result.nees_position.size(); b += 20) {
        double bp = 0, br = 0;
        for (std::size_t k = b; k < b + 20; ++k) {
          bp += result.nees_position[k] / 20.0;
          br += result.nees_rotation[k] / 20.0;
        }
        std::printf("run %d t=%2zu s nees_p %.2f nees_r %.2f\n", run, b / 10, bp, br);
      }
    }
    used += result.features_used;
    rejected += result.rejected_chi2;
    EXPECT_LT(result.final_position_error_m, 0.3) << "run " << run;
  }
  const double nees_p = sum_p / static_cast<double>(count);
  const double nees_r = sum_r / static_cast<double>(count);
  // Monte-Carlo average of N runs of a 3-dof NEES: N * NEES ~ chi2(3N); two-sided 95% bounds.
  const double lower = chi_square_quantile(0.025, 3 * kRuns) / kRuns;
  const double upper = chi_square_quantile(0.975, 3 * kRuns) / kRuns;
  RecordProperty("nees_position", std::to_string(nees_p));
  RecordProperty("nees_rotation", std::to_string(nees_r));
  std::printf(
      "average NEES position %.3f, rotation %.3f, bounds [%.3f, %.3f]; features used %d, chi2 rejected %d\n",
      nees_p, nees_r, lower, upper, used, rejected);
  EXPECT_GT(nees_p, lower);
  EXPECT_LT(nees_p, upper);
  EXPECT_GT(nees_r, lower);
  EXPECT_LT(nees_r, upper);
  // The gate rejects roughly 5% of the (inlier) features, not nearly all of them.
  EXPECT_LT(rejected, used / 5);
}

}  // namespace
}  // namespace loopgate
