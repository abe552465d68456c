// Kalibr calibration files (camchain-imucam.yaml, imu.yaml; TUM-VI's dso/camchain.yaml, dso/imu_config.yaml):
// what is read, the frame convention (T_cam_imu is the inverse of the body-from-camera transform), and the
// errors, each naming the file and the line.
#include <gtest/gtest.h>

#include <fstream>

#include "core/error.hpp"
#include "io/kalibr_calibration.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

fs::path write_file(const fs::path& dir, const std::string& name, const std::string& text) {
  fs::create_directories(dir);
  std::ofstream(dir / name, std::ios::binary) << text;
  return dir / name;
}

// TUM-VI's dso/camchain.yaml for 512x512 images, values rounded (cam1 abridged).
const char* kCamchain = R"(cam0:
  T_cam_imu:
  - [-0.9995, 0.0296, -0.0085, 0.0475]
  - [0.0075, -0.0344, -0.9994, -0.0474]
  - [-0.0299, -0.9990, 0.0342, -0.0681]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [0.0034, 0.0007, -0.0021, 0.0002]
  distortion_model: equidistant
  intrinsics: [190.98, 190.97, 254.93, 256.90]
  resolution: [512, 512]
  rostopic: /cam0/image_raw
  timeshift_cam_imu: 0.0
cam1:
  T_cam_imu:
  - [-0.9995, 0.0300, -0.0059, -0.0536]
  - [0.0048, -0.0386, -0.9992, -0.0470]
  - [-0.0302, -0.9988, 0.0384, -0.0705]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [-0.0001, 0.0030, -0.0009, 0.0001, 0.0]
  distortion_model: radtan
  intrinsics: [190.44, 190.43, 252.60, 254.92]
  resolution: [512, 512]
)";

using testing::catch_data_error;

void expect_error(const DataError& e, const fs::path& file, std::size_t line, const std::string& needle) {
  EXPECT_EQ(e.file(), file) << e.what();
  EXPECT_EQ(e.line(), line) << e.what();
  EXPECT_NE(e.message().find(needle), std::string::npos) << e.what();
}

TEST(IoKalibrCalibration, CamchainCameraZero) {
  const fs::path file = write_file(testing::make_temp_dir("kalibr-cam"), "camchain.yaml", kCamchain);
  const CameraCalibration camera = read_kalibr_camchain(file, 0);
  EXPECT_EQ(camera.width_px, 512);
  EXPECT_EQ(camera.height_px, 512);
  EXPECT_DOUBLE_EQ(camera.fx, 190.98);
  EXPECT_DOUBLE_EQ(camera.fy, 190.97);
  EXPECT_DOUBLE_EQ(camera.cx, 254.93);
  EXPECT_DOUBLE_EQ(camera.cy, 256.90);
  EXPECT_EQ(camera.distortion_model, DistortionModel::kEquidistant);
  EXPECT_EQ(camera.distortion, (std::vector<double>{0.0034, 0.0007, -0.0021, 0.0002}));
  // T_cam_imu maps IMU coordinates into the camera: the body (IMU) from camera transform is its inverse (to
  // the rounding of the 4 decimals above, which leave the rotation orthonormal to about 1e-3).
  Eigen::Matrix4d T_c_i;
  T_c_i << -0.9995, 0.0296, -0.0085, 0.0475, 0.0075, -0.0344, -0.9994, -0.0474, -0.0299, -0.9990, 0.0342,
      -0.0681, 0, 0, 0, 1;
  EXPECT_TRUE((camera.T_b_c.matrix() * T_c_i).isApprox(Eigen::Matrix4d::Identity(), 2e-3));
  const Eigen::Vector3d p_c(0.1, -0.2, 1.5);
  const Eigen::Vector3d p_i = camera.T_b_c * p_c;
  EXPECT_TRUE((T_c_i.topLeftCorner<3, 3>() * p_i + T_c_i.topRightCorner<3, 1>()).isApprox(p_c, 2e-3));
}

TEST(IoKalibrCalibration, CamchainCameraOneIsRadtanWithFourCoefficients) {
  std::string text = kCamchain;
  text.replace(text.find("0.0001, 0.0]"), 12, "0.0001]");
  const fs::path file = write_file(testing::make_temp_dir("kalibr-cam1"), "camchain.yaml", text);
  const CameraCalibration camera = read_kalibr_camchain(file, 1);
  EXPECT_EQ(camera.distortion_model, DistortionModel::kRadTan);
  EXPECT_DOUBLE_EQ(camera.fx, 190.44);
  EXPECT_NEAR(camera.T_b_c.inverse().translation().x(), -0.0536, 1e-4);
}

TEST(IoKalibrCalibration, CamchainErrorsNameFileAndLine) {
  const fs::path dir = testing::make_temp_dir("kalibr-bad");
  // No cam0: the file and the line of its first key, and the sections it has.
  const fs::path no_cam0 = write_file(dir, "no_cam0.yaml", "# TUM-VI\ncam1:\n  camera_model: pinhole\n");
  const DataError missing = catch_data_error([&] { read_kalibr_camchain(no_cam0, 0); });
  expect_error(missing, no_cam0, 2, "no section 'cam0' (camera sections here: cam1)");

  // cam1 has 5 distortion coefficients in kCamchain: the list's line.
  const fs::path five = write_file(dir, "five.yaml", kCamchain);
  expect_error(catch_data_error([&] { read_kalibr_camchain(five, 1); }), five, 21,
               "distortion_coeffs [k1, k2, p1, p2]: expected a list of 4 numbers");

  std::string omni = kCamchain;
  omni.replace(omni.find("camera_model: pinhole"), 21, "camera_model: omni");
  const fs::path omni_file = write_file(dir, "omni.yaml", omni);
  expect_error(catch_data_error([&] { read_kalibr_camchain(omni_file, 0); }), omni_file, 7,
               "cam0.camera_model: 'omni', expected pinhole");

  std::string no_extrinsics = kCamchain;
  no_extrinsics.replace(no_extrinsics.find("  T_cam_imu:"), 11, "  T_cam_cam:");
  const fs::path no_T = write_file(dir, "no_T.yaml", no_extrinsics);
  expect_error(catch_data_error([&] { read_kalibr_camchain(no_T, 0); }), no_T, 1,
               "cam0: no T_cam_imu (Kalibr) or T_imu_cam (OpenVINS)");

  std::string bad_row = kCamchain;
  bad_row.replace(bad_row.find("[0.0, 0.0, 0.0, 1.0]"), 20, "[0.0, 0.0, 0.5, 1.0]");
  const fs::path bad_row_file = write_file(dir, "bad_row.yaml", bad_row);
  expect_error(catch_data_error([&] { read_kalibr_camchain(bad_row_file, 0); }), bad_row_file, 3,
               "cam0.T_cam_imu: expected bottom row [0, 0, 0, 1]");

  std::string short_row = kCamchain;
  short_row.replace(short_row.find("[0.0075, -0.0344, -0.9994, -0.0474]"), 35, "[0.0075, -0.0344, -0.9994]");
  const fs::path short_row_file = write_file(dir, "short_row.yaml", short_row);
  expect_error(catch_data_error([&] { read_kalibr_camchain(short_row_file, 0); }), short_row_file, 4,
               "cam0.T_cam_imu row 2: expected a list of 4 numbers");

  const fs::path broken = write_file(dir, "broken.yaml", "cam0:\n  intrinsics: [1, 2\n");
  EXPECT_NE(catch_data_error([&] { read_kalibr_camchain(broken, 0); }).message().find("malformed YAML"),
            std::string::npos);
}

TEST(IoKalibrCalibration, ImuFlatAsTumViAndNestedAsKalibrResult) {
  const fs::path dir = testing::make_temp_dir("kalibr-imu");
  const std::string keys =
      "accelerometer_noise_density: 0.0028\naccelerometer_random_walk: 0.00086\n"
      "gyroscope_noise_density: 0.00016\ngyroscope_random_walk: 0.000022\nupdate_rate: 200.0\n";
  const fs::path flat = write_file(dir, "imu_config.yaml", "# TUM-VI dso/imu_config.yaml\n" + keys);
  std::string nested_keys;
  for (std::size_t pos = 0; pos < keys.size();) {
    const std::size_t end = keys.find('\n', pos);
    nested_keys += "  " + keys.substr(pos, end + 1 - pos);
    pos = end + 1;
  }
  const fs::path nested = write_file(dir, "imu.yaml",
                                     "imu0:\n  T_i_b:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n"
                                     "  - [0, 0, 0, 1]\n" +
                                         nested_keys + "  model: calibrated\n  rostopic: /imu0\n");
  for (const fs::path& file : {flat, nested}) {
    const ImuCalibration imu = read_kalibr_imu(file);
    EXPECT_DOUBLE_EQ(imu.accel_noise_density, 0.0028) << file;
    EXPECT_DOUBLE_EQ(imu.accel_random_walk, 0.00086);
    EXPECT_DOUBLE_EQ(imu.gyro_noise_density, 0.00016);
    EXPECT_DOUBLE_EQ(imu.gyro_random_walk, 0.000022);
    EXPECT_DOUBLE_EQ(imu.rate_hz, 200.0);
    EXPECT_TRUE(imu.T_b_i.matrix().isIdentity(0.0));
  }
}

TEST(IoKalibrCalibration, ImuErrorsNameFileAndLine) {
  const fs::path dir = testing::make_temp_dir("kalibr-imu-bad");
  const fs::path no_rate =
      write_file(dir, "no_rate.yaml",
                 "imu0:\n  accelerometer_noise_density: 0.0028\n"
                 "  accelerometer_random_walk: 0.00086\n  gyroscope_noise_density: 0.00016\n"
                 "  gyroscope_random_walk: 0.000022\n");
  expect_error(catch_data_error([&] { read_kalibr_imu(no_rate); }), no_rate, 1,
               "imu0: missing key 'update_rate'");
  const fs::path negative =
      write_file(dir, "negative.yaml",
                 "accelerometer_noise_density: 0.0028\naccelerometer_random_walk: 0.00086\n"
                 "gyroscope_noise_density: -0.00016\ngyroscope_random_walk: 0.000022\n"
                 "update_rate: 200.0\n");
  expect_error(catch_data_error([&] { read_kalibr_imu(negative); }), negative, 3,
               "gyroscope_noise_density: expected >= 0");
  const fs::path text_rate =
      write_file(dir, "text_rate.yaml",
                 "accelerometer_noise_density: 0.0028\naccelerometer_random_walk: 0.00086\n"
                 "gyroscope_noise_density: 0.00016\ngyroscope_random_walk: 0.000022\n"
                 "update_rate: fast\n");
  expect_error(catch_data_error([&] { read_kalibr_imu(text_rate); }), text_rate, 5,
               "update_rate: expected a finite number, got 'fast'");
}

}  // namespace
}  // namespace loopgate
