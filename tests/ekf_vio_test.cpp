#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <opencv2/core/mat.hpp>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/dataset.hpp"
#include "stages/ekf/vio_ekf.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

CameraCalibration test_camera() {
  CameraCalibration c;
  c.width_px = 752;
  c.height_px = 480;
  c.fx = c.fy = 460.0;
  c.cx = 376.0;
  c.cy = 240.0;
  return c;
}

ImuCalibration test_imu() {
  ImuCalibration imu;
  imu.gyro_noise_density = 1.6968e-04;
  imu.gyro_random_walk = 1.9393e-05;
  imu.accel_noise_density = 2.0e-3;
  imu.accel_random_walk = 3.0e-3;
  imu.rate_hz = 200.0;
  return imu;
}

// Static IMU readings: the sensor is tilted by `R_w_i` and measures the specific force R_w_i^T (0, 0, g).
std::vector<ImuSample> static_imu(Timestamp t0_ns, Timestamp t1_ns, const Eigen::Matrix3d& R_w_i) {
  std::vector<ImuSample> out;
  for (Timestamp t = t0_ns; t <= t1_ns; t += 5'000'000) {
    ImuSample s;
    s.t_ns = t;
    s.accel_mps2 = R_w_i.transpose() * Eigen::Vector3d(0.0, 0.0, 9.81);
    out.push_back(s);
  }
  return out;
}

TEST(EkfVio, GroundTruthStateInterpolatesAndDifferentiates) {
  std::vector<GroundTruthState> states;
  for (int i = 0; i <= 10; ++i) {
    GroundTruthState s;
    s.t_ns = i * 100'000'000;
    s.T_w_b.translation() = Eigen::Vector3d(0.5 * i * 0.1, 0.0, 1.0);  // 0.5 m/s along x, no velocity given
    states.push_back(s);
  }
  const auto mid = ground_truth_state_at(states, 250'000'000);
  ASSERT_TRUE(mid.has_value());
  EXPECT_NEAR(mid->T_w_b.translation().x(), 0.125, 1e-12);
  EXPECT_NEAR(mid->v_w_mps.x(), 0.5, 1e-9);
  EXPECT_FALSE(ground_truth_state_at(states, 2'000'000'000).has_value());
  EXPECT_FALSE(ground_truth_state_at({}, 0).has_value());
}

TEST(EkfVio, EffectiveNoiseUsesOverridesAndRejectsZero) {
  EkfConfig config;
  ImuCalibration imu = test_imu();
  EXPECT_DOUBLE_EQ(effective_imu_noise(config, imu).gyro_noise_density,
                   config.imu_noise_inflation * imu.gyro_noise_density);
  config.imu_noise_inflation = 1.0;
  EXPECT_DOUBLE_EQ(effective_imu_noise(config, imu).accel_random_walk, imu.accel_random_walk);
  config.gyro_noise_density = 1e-3;
  config.imu_noise_inflation = 2.0;
  EXPECT_DOUBLE_EQ(effective_imu_noise(config, imu).gyro_noise_density, 2e-3);
  imu.accel_random_walk = 0.0;
  try {
    effective_imu_noise(config, imu);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("ekf.accel_random_walk"), std::string::npos);
  }
}

TEST(EkfVio, StaticInitialisationFindsGravity) {
  EkfConfig config;
  config.init_mode = EkfInitMode::kStatic;
  VioEkf vio(config, test_camera(), test_imu());
  const Eigen::Matrix3d R_tilt =
      (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  const std::vector<ImuSample> imu = static_imu(0, 4'000'000'000, R_tilt);
  // Still features (the static initialiser needs to see that the image does not move), none for
  // lost_max_frames images from frame 25 on.
  std::vector<FeatureObservation> still;
  for (int i = 0; i < 50; ++i)
    still.push_back(FeatureObservation{static_cast<std::uint64_t>(i),
                                       Eigen::Vector2d(0.01 * (i % 10) - 0.05, 0.02 * (i / 10) - 0.05)});
  const std::vector<FeatureObservation> none;
  const int gap_begin = 25;
  const int gap_end = gap_begin + config.lost_max_frames;
  OdometryStatus status = OdometryStatus::kInitialising;
  int first_tracking = -1;
  int first_lost = -1;
  int reinitialised = -1;
  for (int k = 0; k <= 75; ++k) {
    EkfFrameInput in;
    in.t_ns = static_cast<Timestamp>(k) * 50'000'000;
    const auto begin = static_cast<std::size_t>(k > 0 ? (k - 1) * 10 : 0);
    in.imu = std::span<const ImuSample>(imu.data() + begin, static_cast<std::size_t>(k > 0 ? 11 : 1));
    in.observations = (k >= gap_begin && k < gap_end) ? &none : &still;
    const EkfFrameOutput out = vio.process(in);
    status = out.pose.status;
    if (status == OdometryStatus::kTracking && first_tracking < 0) first_tracking = k;
    if (status == OdometryStatus::kLost && first_lost < 0) first_lost = k;
    if (status == OdometryStatus::kTracking && first_lost >= 0 && reinitialised < 0) reinitialised = k;
    if (k < 20) {
      EXPECT_EQ(status, OdometryStatus::kInitialising) << "frame " << k;
      EXPECT_NE(out.reason.find("static"), std::string::npos) << out.reason;
    }
    if (k == 22) {
      // Roll and pitch match the tilt (yaw is set to zero): gravity directions agree.
      const Eigen::Vector3d up_est = out.pose.T_w_b.rotation().transpose() * Eigen::Vector3d::UnitZ();
      const Eigen::Vector3d up_true = R_tilt.transpose() * Eigen::Vector3d::UnitZ();
      EXPECT_LT((up_est - up_true).norm(), 1e-6);
      EXPECT_LT(out.pose.T_w_b.translation().norm(), 1e-6);
    }
  }
  EXPECT_EQ(first_tracking, 20);  // after static_window_s = 1 s of IMU at 20 Hz
  ASSERT_TRUE(vio.initial_state().has_value());
  EXPECT_EQ(vio.initial_state()->method, InitMethod::kStatic);
  // Without features the track is declared lost after lost_max_frames, then re-initialised from a new
  // still window: the run goes on.
  EXPECT_EQ(first_lost, gap_end - 1);
  EXPECT_EQ(reinitialised, first_lost + 20);
  EXPECT_EQ(vio.starts(), 2u);
}

TEST(EkfVio, DivergenceIsReportedAndRecovered) {
  EkfConfig config;
  config.init_mode = EkfInitMode::kGroundTruth;  // the test hands the filter its ground truth
  VioEkf vio(config, test_camera(), test_imu());
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  std::vector<ImuSample> imu = static_imu(0, 2'000'000'000, R);
  // A corrupted reading (NaN) half-way: the filter must not crash but report lost and re-initialise.
  imu[200].gyro_radps.x() = std::numeric_limits<double>::quiet_NaN();
  std::vector<FeatureObservation> obs;
  for (int i = 0; i < 50; ++i)
    obs.push_back(FeatureObservation{static_cast<std::uint64_t>(i),
                                     Eigen::Vector2d(0.01 * (i % 10) - 0.05, 0.02 * (i / 10) - 0.05)});
  GroundTruthState gt;
  gt.T_w_b.translation() = Eigen::Vector3d(1.0, 2.0, 3.0);
  int lost_frames = 0;
  int tracking_after_loss = 0;
  for (int k = 0; k < 40; ++k) {
    EkfFrameInput in;
    in.t_ns = static_cast<Timestamp>(k) * 50'000'000;
    const auto begin = static_cast<std::size_t>(k > 0 ? (k - 1) * 10 : 0);
    in.imu = std::span<const ImuSample>(imu.data() + begin, static_cast<std::size_t>(k > 0 ? 11 : 1));
    in.observations = &obs;
    gt.t_ns = in.t_ns;
    in.ground_truth = gt;
    const EkfFrameOutput out = vio.process(in);
    if (out.pose.status == OdometryStatus::kLost) {
      ++lost_frames;
      EXPECT_FALSE(out.reason.empty());
    }
    if (lost_frames > 0 && out.pose.status == OdometryStatus::kTracking) {
      ++tracking_after_loss;
      EXPECT_TRUE(out.pose.T_w_b.matrix().allFinite());
      EXPECT_NEAR((out.pose.T_w_b.translation() - gt.T_w_b.translation()).norm(), 0.0, 0.05);
    }
    if (k < 20) {
      EXPECT_EQ(out.pose.status, OdometryStatus::kTracking) << "frame " << k;
    }
  }
  EXPECT_GE(lost_frames, 1);
  EXPECT_GT(tracking_after_loss, 10);
}

// clone_every_n_frames = 2: every second image becomes a clone, the others only propagate the state; every
// image still gets a pose at its own time.
TEST(EkfVio, CloneEveryNFramesClonesEverySecondImage) {
  EkfConfig config;
  config.init_mode = EkfInitMode::kGroundTruth;  // the test hands the filter its ground truth
  config.clone_every_n_frames = 2;
  VioEkf vio(config, test_camera(), test_imu());
  const std::vector<ImuSample> imu = static_imu(0, 1'000'000'000, Eigen::Matrix3d::Identity());
  const std::vector<FeatureObservation> none;
  GroundTruthState gt;
  for (int k = 0; k < 9; ++k) {
    EkfFrameInput in;
    in.t_ns = static_cast<Timestamp>(k) * 50'000'000;
    const auto begin = static_cast<std::size_t>(k > 0 ? (k - 1) * 10 : 0);
    in.imu = std::span<const ImuSample>(imu.data() + begin, static_cast<std::size_t>(k > 0 ? 11 : 1));
    in.observations = &none;
    gt.t_ns = in.t_ns;
    in.ground_truth = gt;
    const EkfFrameOutput out = vio.process(in);
    ASSERT_EQ(out.pose.status, OdometryStatus::kTracking) << "frame " << k;
    EXPECT_EQ(vio.filter().state().t_ns, in.t_ns);
    // The initial image, then images 2, 4, 6, 8.
    EXPECT_EQ(vio.filter().clones().size(), static_cast<std::size_t>(1 + k / 2)) << "frame " << k;
  }
}

std::string fmt_vec(const Eigen::Vector3d& v) {
  char buf[96];
  std::snprintf(buf, sizeof(buf), "(%.3f %.3f %.3f)", v.x(), v.y(), v.z());
  return buf;
}

// Real EuRoC images and IMU, initialised from ground truth. The 95 frames (4.7 s) of the excerpt are a
// standstill before take-off: no parallax, so the MSCKF gets nothing from its features (they fail
// triangulation) and without zero-velocity updates the position runs away by metres (the ground truth
// gives no IMU biases); with them it holds to millimetres.
TEST(EkfVio, RunsOnRealEurocMicro) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/V1_01_easy_micro");
  const auto dataset = open_dataset(testing::shared_data_dir() / "euroc/V1_01_easy_micro");
  ASSERT_TRUE(dataset->camera().has_value());
  ASSERT_TRUE(dataset->imu_calibration().has_value());
  EkfConfig config;
  config.init_mode = EkfInitMode::kGroundTruth;  // the test hands the filter its ground truth
  VioEkf vio(config, *dataset->camera(), *dataset->imu_calibration());
  const std::size_t frames = dataset->frame_count();
  double max_error = 0.0;
  double final_error = 0.0;
  double path_m = 0.0;
  int used = 0;
  int zero_velocity_frames = 0;
  int initialised_frames = 0;
  Eigen::Vector3d previous_true = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < frames; ++i) {
    const Timestamp t_ns = dataset->frame_t_ns(i);
    const Timestamp t_prev_ns = i > 0 ? dataset->frame_t_ns(i - 1) : t_ns;
    // Samples bracketing [t_prev, t]: the propagator interpolates to both ends as the sync node would.
    const std::span<const ImuSample> imu = dataset->imu_between(t_prev_ns - 5'000'000, t_ns + 5'000'001);
    const cv::Mat image = dataset->load_image(i);
    EkfFrameInput in;
    in.t_ns = t_ns;
    in.imu = imu;
    in.image = &image;
    in.ground_truth = ground_truth_state_at(dataset->ground_truth(), t_ns);
    const EkfFrameOutput out = vio.process(in);
    if (!in.ground_truth.has_value()) {
      // Before the ground truth starts the filter waits.
      ASSERT_EQ(out.pose.status, OdometryStatus::kInitialising);
      ASSERT_LT(i, 40u);
      continue;
    }
    ASSERT_EQ(out.pose.status, OdometryStatus::kTracking) << "frame " << i << ": " << out.reason;
    used += out.update.used_features;
    ++initialised_frames;
    if (out.zero_velocity) ++zero_velocity_frames;
    EXPECT_GE(out.tracked_features, 100);
    const Eigen::Vector3d p_true = in.ground_truth->T_w_b.translation();
    if (!previous_true.isZero()) path_m += (p_true - previous_true).norm();
    previous_true = p_true;
    final_error = (out.pose.T_w_b.translation() - p_true).norm();
    max_error = std::max(max_error, final_error);
    if (std::getenv("EKF_DEBUG") != nullptr) {
      std::printf("frame %zu imu %zu err %.3f est %s true %s v %s used %d rej %d/%d sigma %.3f\n", i,
                  imu.size(), final_error, fmt_vec(out.pose.T_w_b.translation()).c_str(),
                  fmt_vec(p_true).c_str(), fmt_vec(vio.filter().state().v_w_mps).c_str(),
                  out.update.used_features, out.update.rejected_triangulation, out.update.rejected_chi2,
                  out.position_sigma_m);
    }
    EXPECT_GT(out.position_sigma_m, 0.0);
  }
  std::printf(
      "V1_01 micro: %zu frames (%d initialised, %d zero-velocity), path %.3f m, max position error %.4f m, "
      "final "
      "%.4f m, features used %d\n",
      frames, initialised_frames, zero_velocity_frames, path_m, max_error, final_error, used);
  EXPECT_GT(initialised_frames, 50);
  EXPECT_GT(zero_velocity_frames, initialised_frames * 3 / 4);
  EXPECT_LT(max_error, 0.02);
}

}  // namespace
}  // namespace loopgate
