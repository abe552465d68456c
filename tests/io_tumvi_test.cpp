// TUM-VI's variant of the EuRoC ASL layout: ground truth in mav0/mocap0/data.csv, calibration in Kalibr files
// at the tree's root or in dso/ (no state_groundtruth_estimate0, no sensor.yaml). What is read, which file
// wins when both kinds are present, and the errors (file and line).
#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

constexpr Timestamp kT0 = 1'520'530'308'199'447'626;  // TUM-VI room1's first image time
constexpr Timestamp kFramePeriod = 50'000'000;        // 20 Hz
constexpr Timestamp kMocapPeriod = 8'333'333;         // 120 Hz
constexpr int kFrames = 10;

void write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

const char* kCamchain = R"(cam0:
  T_cam_imu:
  - [0.0, -1.0, 0.0, 0.05]
  - [0.0, 0.0, -1.0, -0.04]
  - [1.0, 0.0, 0.0, -0.07]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [0.0034, 0.0007, -0.0021, 0.0002]
  distortion_model: equidistant
  intrinsics: [19.1, 19.0, 15.5, 11.5]
  resolution: [32, 24]
)";

const char* kImuConfig =
    "accelerometer_noise_density: 0.0028\naccelerometer_random_walk: 0.00086\n"
    "gyroscope_noise_density: 0.00016\ngyroscope_random_walk: 0.000022\nupdate_rate: 200.0\n";

// mocap0 rows: "t_ns,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []".
std::string mocap_csv() {
  std::string text =
      "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n";
  for (Timestamp t = kT0; t <= kT0 + kFrames * kFramePeriod; t += kMocapPeriod) {
    const double s = ns_to_s(t - kT0);
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.2 * s, Eigen::Vector3d::UnitZ()));
    text += std::to_string(t) + "," + std::to_string(0.5 * s) + "," + std::to_string(-0.25 * s) + ",1.2," +
            std::to_string(q.w()) + "," + std::to_string(q.x()) + "," + std::to_string(q.y()) + "," +
            std::to_string(q.z()) + "\n";
  }
  return text;
}

// A TUM-VI-style tree at `dir`: mav0/cam0 (images), mav0/imu0/data.csv, mav0/mocap0/data.csv,
// dso/camchain.yaml and dso/imu_config.yaml.
void make_tumvi(const fs::path& dir) {
  const fs::path mav = dir / "mav0";
  std::vector<EurocImageEntry> entries;
  fs::create_directories(mav / "cam0/data");
  for (int i = 0; i < kFrames; ++i) {
    const Timestamp t = kT0 + i * kFramePeriod;
    entries.push_back(EurocImageEntry{t, std::to_string(t) + ".png"});
    cv::imwrite((mav / "cam0/data" / entries.back().filename).string(),
                cv::Mat(24, 32, CV_8UC1, cv::Scalar(i * 20)));
  }
  write_euroc_camera_csv(mav / "cam0/data.csv", entries);
  std::vector<ImuSample> imu;
  for (Timestamp t = kT0; t <= kT0 + kFrames * kFramePeriod; t += 5'000'000) {
    ImuSample s;
    s.t_ns = t;
    s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
    imu.push_back(s);
  }
  write_euroc_imu(mav / "imu0/data.csv", imu);
  write_file(mav / "mocap0/data.csv", mocap_csv());
  write_file(dir / "dso/camchain.yaml", kCamchain);
  write_file(dir / "dso/imu_config.yaml", kImuConfig);
}

using testing::catch_data_error;

TEST(IoTumVi, MocapGroundTruthAndKalibrCalibration) {
  const fs::path dir = testing::make_temp_dir("io-tumvi");
  make_tumvi(dir);
  for (const fs::path& root : {dir, dir / "mav0"}) {  // the tree or its mav0: dso/ is found beside mav0
    const auto d = open_dataset(root);
    EXPECT_EQ(d->layout(), DatasetLayout::kEuroc);
    ASSERT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));
    ASSERT_TRUE(d->has_ground_truth());
    EXPECT_EQ(d->ground_truth().front().t_ns, kT0);
    const auto T_w_b = d->ground_truth_T_w_b(4);  // frame 4 at 0.2 s, between two mocap rows
    ASSERT_TRUE(T_w_b.has_value());
    EXPECT_NEAR(T_w_b->translation().x(), 0.1, 1e-6);
    EXPECT_NEAR(T_w_b->translation().y(), -0.05, 1e-6);
    EXPECT_NEAR(T_w_b->translation().z(), 1.2, 1e-12);
    EXPECT_NEAR(Eigen::AngleAxisd(T_w_b->linear()).angle(), 0.04, 1e-5);

    const auto camera = d->camera();
    ASSERT_TRUE(camera.has_value());
    EXPECT_EQ(camera->distortion_model, DistortionModel::kEquidistant);
    EXPECT_DOUBLE_EQ(camera->fx, 19.1);
    EXPECT_EQ(camera->width_px, 32);
    // T_cam_imu's inverse: the camera centre sits at -R^T t in the IMU (body) frame.
    EXPECT_TRUE(camera->T_b_c.translation().isApprox(Eigen::Vector3d(0.07, 0.05, -0.04), 1e-12))
        << camera->T_b_c.translation().transpose();
    const auto imu = d->imu_calibration();
    ASSERT_TRUE(imu.has_value());
    EXPECT_DOUBLE_EQ(imu->gyro_noise_density, 0.00016);
    EXPECT_DOUBLE_EQ(imu->rate_hz, 200.0);
    EXPECT_TRUE(d->has_imu());
    EXPECT_EQ(d->load_image(3).at<unsigned char>(0, 0), 60);
  }
}

TEST(IoTumVi, KalibrFilesAtTheRootUnderKalibrNames) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-root");
  make_tumvi(dir);
  fs::rename(dir / "dso/camchain.yaml", dir / "camchain-imucam.yaml");
  fs::rename(dir / "dso/imu_config.yaml", dir / "imu.yaml");
  const auto d = open_euroc(dir);
  ASSERT_TRUE(d->camera().has_value());
  EXPECT_DOUBLE_EQ(d->camera()->fy, 19.0);
  ASSERT_TRUE(d->imu_calibration().has_value());
  EXPECT_DOUBLE_EQ(d->imu_calibration()->accel_noise_density, 0.0028);
}

// Kalibr names its outputs after the bag it calibrated from (camchain-imucam-<bag>.yaml, imu-<bag>.yaml).
TEST(IoTumVi, KalibrOutputsNamedAfterTheirBag) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-kalibr-bag");
  make_tumvi(dir);
  fs::rename(dir / "dso/camchain.yaml", dir / "camchain-imucam-calib_2024.yaml");
  fs::rename(dir / "dso/imu_config.yaml", dir / "imu-calib_2024.yaml");
  const auto d = open_euroc(dir);
  ASSERT_TRUE(d->camera().has_value());
  EXPECT_DOUBLE_EQ(d->camera()->fy, 19.0);
  EXPECT_TRUE(d->camera()->T_b_c.translation().isApprox(Eigen::Vector3d(0.07, 0.05, -0.04), 1e-12));
  ASSERT_TRUE(d->imu_calibration().has_value());
  EXPECT_DOUBLE_EQ(d->imu_calibration()->accel_noise_density, 0.0028);
}

// OpenVINS ships kalibr_imucam_chain.yaml (with T_imu_cam, the inverse of Kalibr's T_cam_imu, and an OpenCV
// "%YAML:1.0" first line) and kalibr_imu_chain.yaml (an imu0 section).
TEST(IoTumVi, OpenVinsChainWithTImuCamIsInverted) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-openvins");
  make_tumvi(dir);
  fs::remove(dir / "dso/camchain.yaml");
  fs::remove(dir / "dso/imu_config.yaml");
  write_file(dir / "kalibr_imucam_chain.yaml", R"(%YAML:1.0

cam0:
  T_imu_cam:
  - [0.0, 0.0, 1.0, 0.07]
  - [-1.0, 0.0, 0.0, 0.05]
  - [0.0, -1.0, 0.0, -0.04]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: []
  camera_model: pinhole
  distortion_coeffs: [0.0034, 0.0007, -0.0021, 0.0002]
  distortion_model: equidistant
  intrinsics: [19.1, 19.0, 15.5, 11.5]
  resolution: [32, 24]
  rostopic: /cam0/image_raw
)");
  write_file(dir / "kalibr_imu_chain.yaml",
             "%YAML:1.0\n\nimu0:\n  T_i_b:\n  - [1.0, 0.0, 0.0, 0.0]\n  - [0.0, 1.0, 0.0, 0.0]\n"
             "  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n  accelerometer_noise_density: 0.0028\n"
             "  accelerometer_random_walk: 0.00086\n  gyroscope_noise_density: 0.00016\n"
             "  gyroscope_random_walk: 0.000022\n  rostopic: /imu0\n  update_rate: 200.0\n");
  const auto d = open_euroc(dir);
  ASSERT_TRUE(d->camera().has_value());
  // The same camera as the T_cam_imu of kCamchain: T_imu_cam is taken as it is, not inverted twice.
  EXPECT_TRUE(d->camera()->T_b_c.translation().isApprox(Eigen::Vector3d(0.07, 0.05, -0.04), 1e-12))
      << d->camera()->T_b_c.translation().transpose();
  EXPECT_TRUE(d->camera()->T_b_c.linear().col(2).isApprox(Eigen::Vector3d(1.0, 0.0, 0.0), 1e-12));
  ASSERT_TRUE(d->imu_calibration().has_value());
  EXPECT_DOUBLE_EQ(d->imu_calibration()->gyro_noise_density, 0.00016);
}

// A Kalibr chain named by the user (--calibration, dataset.calibration) replaces the tree's, wherever it is;
// the Kalibr IMU file is looked for beside it first.
TEST(IoTumVi, CalibrationFileNamedByTheUserWins) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-calibration-file");
  make_tumvi(dir);  // dso/camchain.yaml: fy 19.0; dso/imu_config.yaml: accel noise 0.0028
  const fs::path elsewhere = testing::make_temp_dir("io-tumvi-calibration-file-lab");
  std::string chain = kCamchain;
  chain.replace(chain.find("19.0"), 4, "21.0");
  write_file(elsewhere / "camchain-imucam-lab.yaml", chain);
  write_file(elsewhere / "imu-lab.yaml",
             "accelerometer_noise_density: 0.005\naccelerometer_random_walk: 0.00086\n"
             "gyroscope_noise_density: 0.00016\ngyroscope_random_walk: 0.000022\nupdate_rate: 200.0\n");
  OpenOptions options;
  options.calibration_file = elsewhere / "camchain-imucam-lab.yaml";
  const auto d = open_dataset(dir, options);
  ASSERT_TRUE(d->camera().has_value());
  EXPECT_DOUBLE_EQ(d->camera()->fy, 21.0);
  EXPECT_TRUE(d->camera()->T_b_c.translation().isApprox(Eigen::Vector3d(0.07, 0.05, -0.04), 1e-12));
  ASSERT_TRUE(d->imu_calibration().has_value());
  EXPECT_DOUBLE_EQ(d->imu_calibration()->accel_noise_density, 0.005);
  // Without an IMU file beside it, the tree's is used.
  fs::remove(elsewhere / "imu-lab.yaml");
  const auto tree_imu = open_dataset(dir, options);
  ASSERT_TRUE(tree_imu->imu_calibration().has_value());
  EXPECT_DOUBLE_EQ(tree_imu->imu_calibration()->accel_noise_density, 0.0028);
}

// A named calibration that is missing or unusable is an error naming it, in lenient mode too (it is not an
// optional file of the tree); KITTI sequences and image folders do not take one.
TEST(IoTumVi, CalibrationFileErrorsNameTheFile) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-calibration-file-bad");
  make_tumvi(dir);
  OpenOptions options;
  options.strict = false;
  options.calibration_file = dir / "no-such-camchain.yaml";
  DataError e = catch_data_error([&] { open_dataset(dir, options); });
  EXPECT_EQ(e.file(), options.calibration_file) << e.what();
  EXPECT_NE(e.message().find("calibration file not found"), std::string::npos) << e.what();

  options.calibration_file = dir / "kalibr_imucam_chain.yaml";
  write_file(options.calibration_file, "cam1:\n  camera_model: pinhole\n");
  e = catch_data_error([&] { open_dataset(dir, options); });
  EXPECT_EQ(e.file(), options.calibration_file) << e.what();
  EXPECT_NE(e.message().find("no section 'cam0'"), std::string::npos) << e.what();

  const fs::path kitti = testing::make_temp_dir("io-tumvi-calibration-file-kitti");
  write_file(kitti / "times.txt", "0.0\n0.1\n");
  options.calibration_file = dir / "dso/camchain.yaml";
  e = catch_data_error([&] { open_dataset(kitti, options); });
  EXPECT_EQ(e.file(), options.calibration_file) << e.what();
  EXPECT_NE(e.message().find("KITTI sequence"), std::string::npos) << e.what();
}

// EuRoC's own files win: state_groundtruth_estimate0 over mocap0, sensor.yaml over Kalibr.
TEST(IoTumVi, EurocFilesWinOverTumViFiles) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-both");
  make_tumvi(dir);
  std::vector<GroundTruthState> gt(2);
  gt[0].t_ns = kT0;
  gt[1].t_ns = kT0 + kFrames * kFramePeriod;
  write_euroc_groundtruth(dir / "mav0/state_groundtruth_estimate0/data.csv", gt);
  CameraCalibration camera;
  camera.width_px = 32;
  camera.height_px = 24;
  camera.fx = camera.fy = 40;
  write_euroc_camera_yaml(dir / "mav0/cam0/sensor.yaml", camera);
  const auto d = open_euroc(dir);
  EXPECT_EQ(d->ground_truth().size(), 2u);
  ASSERT_TRUE(d->camera().has_value());
  EXPECT_DOUBLE_EQ(d->camera()->fx, 40);
  EXPECT_EQ(d->camera()->distortion_model, DistortionModel::kNone);
  ASSERT_TRUE(d->imu_calibration().has_value());  // no imu0/sensor.yaml: still the Kalibr file
}

TEST(IoTumVi, MocapRowWithTooFewColumnsNamesFileAndLine) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-mocap");
  make_tumvi(dir);
  std::string text = mocap_csv();
  std::size_t pos = 0;
  for (int line = 1; line < 5; ++line) pos = text.find('\n', pos) + 1;  // line 5: the 4th data row
  const std::size_t end = text.find('\n', pos);
  std::string row = text.substr(pos, end - pos);
  row = row.substr(0, row.rfind(','));  // 7 columns
  text.replace(pos, end - pos, row);
  write_file(dir / "mav0/mocap0/data.csv", text);
  const DataError e = catch_data_error([&] { open_euroc(dir, OpenOptions{}); });
  EXPECT_EQ(e.file(), dir / "mav0/mocap0/data.csv") << e.what();
  EXPECT_EQ(e.line(), 5u) << e.what();
  EXPECT_NE(e.message().find("expected 8 columns (timestamp [ns], p_RS_R_x"), std::string::npos) << e.what();
  EXPECT_NE(e.message().find("got 7"), std::string::npos) << e.what();

  // Lenient: the row is skipped and recorded, the rest of the ground truth is kept.
  OpenOptions lenient;
  lenient.strict = false;
  const auto d = open_euroc(dir, lenient);
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].line, 5u);
  EXPECT_TRUE(d->has_ground_truth());
}

TEST(IoTumVi, BrokenKalibrFileNamesFileAndLine) {
  const fs::path dir = testing::make_temp_dir("io-tumvi-kalibr");
  make_tumvi(dir);
  write_file(dir / "dso/camchain.yaml", "cam1:\n  camera_model: pinhole\n");
  const DataError e = catch_data_error([&] { open_euroc(dir, OpenOptions{}); });
  EXPECT_EQ(e.file(), dir / "dso/camchain.yaml") << e.what();
  EXPECT_EQ(e.line(), 1u) << e.what();
  EXPECT_NE(e.message().find("no section 'cam0'"), std::string::npos) << e.what();
  // Lenient: recorded, and the dataset opens without a camera calibration.
  OpenOptions lenient;
  lenient.strict = false;
  const auto d = open_euroc(dir, lenient);
  EXPECT_FALSE(d->camera().has_value());
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_NE(d->issues()[0].to_string().find("camchain.yaml:1: no section 'cam0'"), std::string::npos)
      << d->issues()[0].to_string();
}

}  // namespace
}  // namespace loopgate
