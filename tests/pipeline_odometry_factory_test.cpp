// The odometry factory (pipeline/odometry_factory.hpp): which source `odometry.source` builds for a dataset,
// what it reads out of the dataset for it, and the errors naming what is missing. The sources themselves
// are tested with plain data in the odometry_* tests.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <tuple>
#include <vector>

#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline_fake_dataset.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
constexpr const char* kMicro = "euroc/V1_01_easy_micro";

OdometryConfig source(const std::string& name) {
  OdometryConfig config;
  config.source = enum_value<OdometrySourceKind>(name).value();
  return config;
}

// Runs `odometry` over the frames of `dataset` with the ground truth as input, returns the estimates.
std::vector<PoseEstimate> run(OdometrySource& odometry, const Dataset& dataset) {
  std::vector<PoseEstimate> out;
  for (std::size_t i = 0; i < dataset.frame_count(); ++i) {
    OdometryInput input;
    input.frame = i;
    input.t_ns = dataset.frame_t_ns(i);
    input.T_w_b_true = dataset.ground_truth_T_w_b(i);
    out.push_back(odometry.process(input).pose);
  }
  return out;
}

TEST(PipelineOdometryFactory, BuildsTheEkfSourceAndAutoPicksItOnEuroc) {
  LOOPGATE_REQUIRE_SHARED_DATA(kMicro);
  const auto dataset = open_dataset(testing::shared_data_dir() / kMicro);
  const auto ekf = make_odometry_source(source("ekf"), EkfConfig{}, *dataset);
  EXPECT_STREQ(ekf->name(), "ekf");
  EXPECT_TRUE(ekf->needs_images());
  EXPECT_TRUE(ekf->needs_imu());
  EXPECT_FALSE(ekf->needs_ground_truth());  // it keeps the dataset's full ground-truth states itself
  OdometryConfig automatic;
  EXPECT_EQ(automatic.source, OdometrySourceKind::kAuto);  // the default
  EXPECT_NO_THROW(automatic.validate());
  EXPECT_EQ(resolve_odometry_source(automatic, EkfConfig{}, *dataset), OdometrySourceKind::kEkf);
  EXPECT_STREQ(make_odometry_source(automatic, EkfConfig{}, *dataset)->name(), "ekf");
  // EuRoC's world is z up: the IMU's mean specific force rotated by the ground truth says so.
  const auto up_w = world_up_axis_from_imu(*dataset);
  ASSERT_TRUE(up_w.has_value());
  EXPECT_EQ(*up_w, Eigen::Vector3d::UnitZ());
}

// An image folder (no IMU, no calibration, no ground truth): auto falls back to drift, an explicit ekf
// source is refused with an error saying what is missing, and so is drift (it needs ground truth).
TEST(PipelineOdometryFactory, DatasetWithoutImuIsRefusedClearly) {
  const fs::path dir = testing::make_temp_dir("odometry-factory-folder");
  for (int k = 0; k < 3; ++k) {
    cv::Mat image(48, 64, CV_8UC1, cv::Scalar(40 * k));
    cv::imwrite((dir / ("img_" + std::to_string(k) + ".png")).string(), image);
  }
  const auto dataset = open_dataset(dir);
  ASSERT_FALSE(dataset->has_imu());
  EXPECT_EQ(resolve_odometry_source(source("auto"), EkfConfig{}, *dataset),
            OdometrySourceKind::kNone);  // no ground truth either
  EXPECT_FALSE(world_up_axis_from_imu(*dataset).has_value());
  try {
    make_odometry_source(source("ekf"), EkfConfig{}, *dataset);
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("ekf needs IMU"), std::string::npos) << e.what();
  }
  try {
    make_odometry_source(source("drift"), *dataset);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("'drift' needs ground truth"), std::string::npos) << e.what();
  }
}

// IMU but no camera calibration: auto is drift, ekf names the missing calibration.
TEST(PipelineOdometryFactory, EkfNeedsTheCalibration) {
  const testing::FakeDataset dataset(20);
  EXPECT_EQ(resolve_odometry_source(source("auto"), EkfConfig{}, dataset), OdometrySourceKind::kDrift);
  try {
    make_odometry_source(source("ekf"), dataset);
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("camera calibration"), std::string::npos) << e.what();
  }
}

// The drift source's heading axis: "auto" is the normal of the ground truth's plane (the fake drive is
// a circle in the x-y plane: z), so with no position noise the estimate stays in that plane; a
// heading axis in the plane ("x") tilts it out.
TEST(PipelineOdometryFactory, DriftHeadingAxisFromTheGroundTruthPlane) {
  const testing::FakeDataset dataset(120);
  OdometryConfig config = source("drift");
  config.drift_position_sigma_m_per_sqrt_m = 0.0;
  config.drift_heading_sigma_rad_per_sqrt_m = 0.01;
  const auto automatic = make_odometry_source(config, dataset);
  EXPECT_STREQ(automatic->name(), "drift");
  double max_z_m = 0.0;
  for (const PoseEstimate& p : run(*automatic, dataset))
    max_z_m = std::max(max_z_m, std::abs(p.T_w_b.translation().z()));
  EXPECT_LT(max_z_m, 1e-12);
  config.heading_axis = HeadingAxis::kX;
  const auto tilted = make_odometry_source(config, dataset);
  max_z_m = 0.0;
  for (const PoseEstimate& p : run(*tilted, dataset))
    max_z_m = std::max(max_z_m, std::abs(p.T_w_b.translation().z()));
  EXPECT_GT(max_z_m, 1e-3);
}

// The file source reads the TUM trajectory named in the config; a missing or empty file is an error
// naming it.
TEST(PipelineOdometryFactory, FileSourceReadsTheTrajectory) {
  const testing::FakeDataset dataset(10);
  const fs::path dir = testing::make_temp_dir("odometry-factory-file");
  std::vector<StampedPose> poses;
  for (std::size_t i = 0; i < dataset.frame_count(); ++i) {
    poses.push_back(StampedPose{dataset.frame_t_ns(i), *dataset.ground_truth_T_w_b(i)});
    poses.back().T_w_b.translation().z() = 7.0;
  }
  write_tum(dir / "trajectory.tum", poses);
  OdometryConfig config = source("file");
  config.file = (dir / "trajectory.tum").string();
  const auto file = make_odometry_source(config, dataset);
  EXPECT_STREQ(file->name(), "file");
  const std::vector<PoseEstimate> estimates = run(*file, dataset);
  ASSERT_EQ(estimates.size(), dataset.frame_count());
  EXPECT_EQ(estimates[4].status, OdometryStatus::kTracking);
  EXPECT_NEAR(estimates[4].T_w_b.translation().z(), 7.0, 1e-9);

  config.file = (dir / "absent.tum").string();
  EXPECT_THROW(make_odometry_source(config, dataset), DataError);
  write_tum(dir / "empty.tum", {});
  config.file = (dir / "empty.tum").string();
  try {
    make_odometry_source(config, dataset);
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("no poses"), std::string::npos) << e.what();
  }
}

// odometry.file in KITTI (12 columns: line k is frame k, timed by the dataset; 13: a time first) and EuRoC
// formats as well as TUM, told apart by their content or named by odometry.file_format.
TEST(PipelineOdometryFactory, FileSourceReadsKittiAndEurocFormats) {
  const testing::FakeDataset dataset(10);
  const fs::path dir = testing::make_temp_dir("odometry-factory-formats");
  std::vector<Eigen::Isometry3d> matrices;
  std::vector<GroundTruthState> states;
  for (std::size_t i = 0; i < dataset.frame_count(); ++i) {
    matrices.push_back(*dataset.ground_truth_T_w_b(i));
    matrices.back().translation().z() = 5.0;
    GroundTruthState s;
    s.t_ns = dataset.frame_t_ns(i);
    s.T_w_b = matrices.back();
    s.T_w_b.translation().z() = 6.0;
    states.push_back(s);
  }
  write_kitti_poses(dir / "poses.txt", matrices);
  write_euroc_groundtruth(dir / "data.csv", states);
  OdometryConfig config = source("file");
  for (const auto& [file, format, z_m] : {std::tuple{"poses.txt", TrajectoryFormat::kAuto, 5.0},
                                          std::tuple{"poses.txt", TrajectoryFormat::kKitti, 5.0},
                                          std::tuple{"data.csv", TrajectoryFormat::kAuto, 6.0},
                                          std::tuple{"data.csv", TrajectoryFormat::kEuroc, 6.0}}) {
    config.file = (dir / file).string();
    config.file_format = format;
    const auto odometry = make_odometry_source(config, dataset);
    const std::vector<PoseEstimate> estimates = run(*odometry, dataset);
    EXPECT_EQ(estimates[4].status, OdometryStatus::kTracking) << file;
    EXPECT_NEAR(estimates[4].T_w_b.translation().z(), z_m, 1e-9) << file;
    EXPECT_TRUE(estimates[4].T_w_b.linear().isApprox(matrices[4].linear(), 1e-12)) << file;
  }
  // Named wrongly: the reader's error, naming the file and the line.
  config.file = (dir / "poses.txt").string();
  config.file_format = TrajectoryFormat::kEuroc;
  try {
    make_odometry_source(config, dataset);
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_EQ(e.file(), dir / "poses.txt");
    EXPECT_EQ(e.line(), 1u);
    EXPECT_NE(e.message().find("expected 8, 11, 14 or 17 columns"), std::string::npos) << e.what();
  }
}

// A trajectory that does not overlap the dataset made every frame "odometry lost" with exit 0;
// now it is an error naming the file and both time spans.
// An image folder has no ground truth, IMU or calibration: auto resolves to none (appearance only), which
// gives no poses; a run that needs them (the gate, odometry mode, verify) is refused, saying why.
TEST(PipelineOdometryFactory, AutoOnAnImageFolderIsNoOdometry) {
  const fs::path dir = testing::make_temp_dir("odometry-factory-folder");
  for (int i = 0; i < 3; ++i)
    cv::imwrite((dir / ("img" + std::to_string(i) + ".png")).string(),
                cv::Mat(16, 32, CV_8UC1, cv::Scalar(i)));
  const auto dataset = open_dataset(dir);
  ASSERT_EQ(dataset->layout(), DatasetLayout::kFolder);
  EXPECT_EQ(resolve_odometry_source(source("auto"), EkfConfig{}, *dataset), OdometrySourceKind::kNone);
  const auto none = make_odometry_source(source("auto"), EkfConfig{}, *dataset);
  EXPECT_STREQ(none->name(), "none");
  EXPECT_FALSE(none->estimates_poses());
  PipelineConfig config;
  config.run.mode = RunMode::kFull;
  EXPECT_NO_THROW(require_poses_if_needed(config, *dataset));
  config.run.mode = RunMode::kGated;
  try {
    require_poses_if_needed(config, *dataset);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(
        std::string(e.what()).find("run.mode: 'gated' needs poses for the pose gate, and odometry.source "
                                   "auto found no odometry for dataset " +
                                   dir.string()),
        std::string::npos)
        << e.what();
  }
  config.odometry.source =
      OdometrySourceKind::kDrift;  // asked for: its own error, naming the dataset and the ways out
  try {
    make_odometry_source(config.odometry, EkfConfig{}, *dataset);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("or none for an appearance-only run.mode full"), std::string::npos);
  }
}

// A trajectory that misses the dataset: the source is built (the run goes through its frames, every one
// 'odometry lost', and fails at the end, run_checks.hpp), and what it expected names the file and both spans.
TEST(PipelineOdometryFactory, FileSourceThatMissesTheDatasetIsExplained) {
  const testing::FakeDataset dataset(10);  // frames at 1.0 .. 1.9 s
  const fs::path dir = testing::make_temp_dir("odometry-factory-overlap");
  std::vector<StampedPose> poses;
  for (int i = 0; i < 10; ++i)
    poses.push_back(StampedPose{s_to_ns(500.0 + i), Eigen::Isometry3d::Identity()});
  write_tum(dir / "other.tum", poses);
  OdometryConfig config = source("file");
  config.file = (dir / "other.tum").string();
  const auto odometry = make_odometry_source(config, dataset);
  OdometryInput input;
  input.t_ns = dataset.frame_t_ns(0);
  EXPECT_EQ(odometry->process(input).pose.status, OdometryStatus::kLost);
  const std::string expected = odometry_expectation(config, EkfConfig{}, dataset);
  EXPECT_NE(expected.find("poses in " + config.file + " within odometry.file_max_gap_s = 0.5 s"),
            std::string::npos)
      << expected;
  EXPECT_NE(
      expected.find("poses at t = 500.000 .. 509.000 s, the dataset's 10 frames at t = 1.000 .. 1.900 s"),
      std::string::npos)
      << expected;
  // Half of the frames covered: accepted (the others are reported lost, frame by frame).
  poses.clear();
  for (int i = 0; i < 5; ++i)
    poses.push_back(
        StampedPose{dataset.frame_t_ns(static_cast<std::size_t>(i)), Eigen::Isometry3d::Identity()});
  write_tum(dir / "half.tum", poses);
  config.file = (dir / "half.tum").string();
  EXPECT_NO_THROW(make_odometry_source(config, dataset));
  // Drift: the dataset's ground truth, and the span it covers.
  EXPECT_NE(odometry_expectation(source("drift"), EkfConfig{}, dataset).find("ground truth of "),
            std::string::npos);
}

}  // namespace
}  // namespace loopgate
