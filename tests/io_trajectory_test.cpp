// Trajectory and calibration files: TUM, KITTI poses/times/calib, EuRoC csv and sensor.yaml, read and
// write, including malformed input.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/csv_text.hpp"
#include "io/trajectory_io.hpp"
#include "pose_test_support.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

void write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

// Expects `fn` to throw DataError whose file ends with `file_name`, at `line` (0 = any), and whose
// message contains `needle`.
template <class Fn>
void expect_data_error(Fn&& fn, const std::string& file_name, std::size_t line, const std::string& needle) {
  try {
    fn();
    FAIL() << "expected DataError mentioning '" << needle << "'";
  } catch (const DataError& e) {
    EXPECT_EQ(e.file().filename().string(), file_name) << e.what();
    if (line > 0) {
      EXPECT_EQ(e.line(), line) << e.what();
    }
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

using testing::make_pose;
using testing::pose_difference;

TEST(IoTrajectory, SecondsParseExactly) {
  Timestamp t = 0;
  ASSERT_TRUE(io_detail::parse_seconds_ns("1403715274.30214", t));
  EXPECT_EQ(t, 1403715274302140000);
  ASSERT_TRUE(io_detail::parse_seconds_ns("1403638518.077829376", t));
  EXPECT_EQ(t, 1403638518077829376);
  ASSERT_TRUE(io_detail::parse_seconds_ns("1.037359e-01", t));
  EXPECT_EQ(t, 103735900);
  ASSERT_TRUE(io_detail::parse_seconds_ns("-0.5", t));
  EXPECT_EQ(t, -500000000);
  ASSERT_TRUE(io_detail::parse_seconds_ns("2.0000000005", t));  // rounds the 10th decimal
  EXPECT_EQ(t, 2000000001);
  for (const char* bad : {"", ".", "1.2.3", "abc", "nan", "inf", "1e400", "12a"}) {
    EXPECT_FALSE(io_detail::parse_seconds_ns(bad, t)) << bad;
  }
  std::string out;
  io_detail::append_seconds(out, 1403638518077829376);
  EXPECT_EQ(out, "1403638518.077829376");
}

TEST(IoTrajectory, TumRoundTrip) {
  const fs::path dir = testing::make_temp_dir("io-tum");
  std::vector<StampedPose> poses;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  Timestamp t = 1403638518077829376;
  for (int i = 0; i < 50; ++i) {
    t += 5000000 + i;
    poses.push_back(
        StampedPose{t, make_pose(u(rng), u(rng) / 3, u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)))});
  }
  write_tum(dir / "traj.txt", poses);
  const std::vector<StampedPose> read = read_tum(dir / "traj.txt");
  ASSERT_EQ(read.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(read[i].t_ns, poses[i].t_ns);  // exact: seconds written with 9 decimals from integer ns
    EXPECT_LT(pose_difference(read[i].T_w_b, poses[i].T_w_b), 1e-14);
  }
}

TEST(IoTrajectory, TumRealFile) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/MH_05_difficult/estimates/vio_mono_tum.txt");
  const auto poses =
      read_tum(testing::shared_data_dir() / "euroc/MH_05_difficult/estimates/vio_mono_tum.txt");
  ASSERT_GT(poses.size(), 100u);
  for (std::size_t i = 1; i < poses.size(); ++i) ASSERT_GT(poses[i].t_ns, poses[i - 1].t_ns);
}

TEST(IoTrajectory, TumBadInput) {
  const fs::path dir = testing::make_temp_dir("io-tum-bad");
  expect_data_error([&] { read_tum(dir / "missing.txt"); }, "missing.txt", 0, "file not found");
  write_file(dir / "cols.txt", "# header\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "cols.txt"); }, "cols.txt", 3, "expected 8 columns");
  write_file(dir / "text.txt", "1.0 0 0 0 0 0 0 1\n2.0 0 zero 0 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "text.txt"); }, "text.txt", 2, "column 3 (ty): expected a number");
  write_file(dir / "nan.txt", "1.0 0 0 nan 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "nan.txt"); }, "nan.txt", 1, "expected a finite number, got 'nan'");
  write_file(dir / "inf.txt", "1.0 0 0 0 0 0 0 1\n2.0 inf 0 0 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "inf.txt"); }, "inf.txt", 2, "finite");
  write_file(dir / "dup.txt", "1.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "dup.txt"); }, "dup.txt", 2, "duplicate timestamp");
  write_file(dir / "back.txt", "2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "back.txt"); }, "back.txt", 2,
                    "timestamp 1.000000000 s is before line 1 (2.000000000 s)");
  // Nanosecond stamps in a file of seconds: the error says so and shows the time in seconds.
  write_file(dir / "ns.txt", "1403636579763555584 0 0 0 0 0 0 1\n");
  expect_data_error([&] { read_tum(dir / "ns.txt"); }, "ns.txt", 1,
                    "it looks like a time in nanoseconds (19 digits): this file takes seconds, e.g. "
                    "1403636579.763555584");
  write_file(dir / "quat.txt", "1.0 0 0 0 0 0 0 0\n");
  expect_data_error([&] { read_tum(dir / "quat.txt"); }, "quat.txt", 1, "unit quaternion");
}

TEST(IoTrajectory, EurocImuRoundTripIsExact) {
  const fs::path dir = testing::make_temp_dir("io-imu");
  std::vector<ImuSample> samples;
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 2.0);
  for (int i = 0; i < 1000; ++i) {
    ImuSample s;
    s.t_ns = 1403638518097829376 + i * 5000000LL;
    s.gyro_radps = Eigen::Vector3d(n(rng), n(rng), n(rng)) * 1e-3;
    s.accel_mps2 = Eigen::Vector3d(n(rng), n(rng), 9.81 + n(rng));
    samples.push_back(s);
  }
  write_euroc_imu(dir / "imu0/data.csv", samples);
  const auto read = read_euroc_imu(dir / "imu0/data.csv");
  ASSERT_EQ(read.size(), samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    EXPECT_EQ(read[i].t_ns, samples[i].t_ns);
    EXPECT_EQ(read[i].gyro_radps, samples[i].gyro_radps);  // bit-exact (shortest round-trip text)
    EXPECT_EQ(read[i].accel_mps2, samples[i].accel_mps2);
  }
}

TEST(IoTrajectory, EurocImuBadInput) {
  const fs::path dir = testing::make_temp_dir("io-imu-bad");
  const std::string header = "#timestamp [ns],wx,wy,wz,ax,ay,az\n";
  write_file(dir / "cols.csv", header + "100,0,0,0,0,0,9.8\n200,0,0,0,0,9.8\n");
  expect_data_error([&] { read_euroc_imu(dir / "cols.csv"); }, "cols.csv", 3, "expected 7 columns");
  write_file(dir / "ts.csv", header + "1.5e9,0,0,0,0,0,9.8\n");
  expect_data_error([&] { read_euroc_imu(dir / "ts.csv"); }, "ts.csv", 2, "integer timestamp in ns");
  write_file(dir / "nan.csv", header + "100,0,0,0,0,0,NaN\n");
  expect_data_error([&] { read_euroc_imu(dir / "nan.csv"); }, "nan.csv", 2, "column 7 (a_z)");
  write_file(dir / "dup.csv", header + "100,0,0,0,0,0,9.8\n100,0,0,0,0,0,9.8\n");
  expect_data_error([&] { read_euroc_imu(dir / "dup.csv"); }, "dup.csv", 3, "duplicate IMU timestamp");
  write_file(dir / "back.csv", header + "200,0,0,0,0,0,9.8\n100,0,0,0,0,0,9.8\n");
  expect_data_error([&] { read_euroc_imu(dir / "back.csv"); }, "back.csv", 3,
                    "IMU timestamp 100 ns is before line 2 (200 ns)");
  write_file(dir / "trunc.csv", header + "100,0,0,0,0,0,9.8\n200,0,0,0,0");
  expect_data_error([&] { read_euroc_imu(dir / "trunc.csv"); }, "trunc.csv", 3, "truncated last line");
  // A complete last line without a newline is fine; so are CRLF line ends and blanks around fields.
  write_file(dir / "ok.csv", header + "100, 0,0,0,0,0,9.8\r\n200,0,0,0,0,0,9.8");
  EXPECT_EQ(read_euroc_imu(dir / "ok.csv").size(), 2u);
}

TEST(IoTrajectory, EurocGroundTruthRoundTrip) {
  const fs::path dir = testing::make_temp_dir("io-gt");
  std::vector<GroundTruthState> states;
  for (int i = 0; i < 200; ++i) {
    GroundTruthState s;
    s.t_ns = 1403638519492829440 + i * 5000000LL;
    s.T_w_b = make_pose(0.01 * i, 0.2, -0.3, Eigen::Vector3d(4.46 + 0.01 * i, -1.68, 0.58));
    s.v_w_mps = Eigen::Vector3d(0.1 * i, -0.2, 0.003);
    s.gyro_bias_radps = Eigen::Vector3d(-0.001806, 0.02094, 0.07687);
    s.accel_bias_mps2 = Eigen::Vector3d(-0.020544, 0.124837, 0.0618);
    states.push_back(s);
  }
  write_euroc_groundtruth(dir / "data.csv", states);
  const auto read = read_euroc_groundtruth(dir / "data.csv");
  ASSERT_EQ(read.size(), states.size());
  for (std::size_t i = 0; i < states.size(); ++i) {
    EXPECT_EQ(read[i].t_ns, states[i].t_ns);
    EXPECT_LT(pose_difference(read[i].T_w_b, states[i].T_w_b), 1e-14);
    EXPECT_EQ(read[i].v_w_mps, states[i].v_w_mps);
    EXPECT_EQ(read[i].gyro_bias_radps, states[i].gyro_bias_radps);
    EXPECT_EQ(read[i].accel_bias_mps2, states[i].accel_bias_mps2);
  }
}

TEST(IoTrajectory, EurocGroundTruthBadInput) {
  const fs::path dir = testing::make_temp_dir("io-gt-bad");
  write_file(dir / "short.csv", "#t,p,q\n100,1,2,3,1,0,0\n");
  expect_data_error([&] { read_euroc_groundtruth(dir / "short.csv"); }, "short.csv", 2,
                    "expected 8, 11, 14 or 17");
  write_file(dir / "mixed.csv", "#t,p,q\n100,1,2,3,1,0,0,0\n200,1,2,3,1,0,0,0,1,1,1\n");
  expect_data_error([&] { read_euroc_groundtruth(dir / "mixed.csv"); }, "mixed.csv", 3,
                    "like the first data row");
  write_file(dir / "dup.csv", "#t,p,q\n100,1,2,3,1,0,0,0\n100,1,2,3,1,0,0,0\n");
  expect_data_error([&] { read_euroc_groundtruth(dir / "dup.csv"); }, "dup.csv", 3, "duplicate ground-truth");
  write_file(dir / "inf.csv", "#t,p,q\n100,1,-inf,3,1,0,0,0\n");
  expect_data_error([&] { read_euroc_groundtruth(dir / "inf.csv"); }, "inf.csv", 2, "column 3 (p_y)");
}

TEST(IoTrajectory, EurocCameraCsvRoundTrip) {
  const fs::path dir = testing::make_temp_dir("io-camcsv");
  std::vector<EurocImageEntry> images;
  for (int i = 0; i < 20; ++i) {
    const Timestamp t = 1403638518077829376 + i * 50000000LL;
    images.push_back(EurocImageEntry{t, std::to_string(t) + ".png"});
  }
  write_euroc_camera_csv(dir / "data.csv", images);
  const auto read = read_euroc_camera_csv(dir / "data.csv");
  ASSERT_EQ(read.size(), images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    EXPECT_EQ(read[i].t_ns, images[i].t_ns);
    EXPECT_EQ(read[i].filename, images[i].filename);
  }
  write_file(dir / "bad.csv", "#t,f\n100,100.png\n100,101.png\n");
  expect_data_error([&] { read_euroc_camera_csv(dir / "bad.csv"); }, "bad.csv", 3,
                    "duplicate camera timestamp");
  write_file(dir / "nofile.csv", "#t,f\n100,\n");
  expect_data_error([&] { read_euroc_camera_csv(dir / "nofile.csv"); }, "nofile.csv", 2,
                    "expected an image file");
}

// A resolution beyond any camera (1e12 px) was accepted and read as -2147483648 px: refused with its bound.
TEST(IoTrajectory, HugeResolutionIsRefusedWithItsBound) {
  const fs::path dir = testing::make_temp_dir("io-yaml-size");
  CameraCalibration camera;
  camera.width_px = 752;
  camera.height_px = 480;
  camera.fx = camera.fy = 458.0;
  camera.cx = 367.0;
  camera.cy = 248.0;
  camera.distortion_model = DistortionModel::kRadTan;
  camera.distortion = {0, 0, 0, 0};
  write_euroc_camera_yaml(dir / "sensor.yaml", camera);
  std::istringstream in(testing::read_file(dir / "sensor.yaml"));
  std::string line, text;
  while (std::getline(in, line))
    text += (line.find("resolution") != std::string::npos ? "resolution: [1e12, 32]" : line) + "\n";
  write_file(dir / "sensor.yaml", text);
  expect_data_error([&] { read_euroc_camera_yaml(dir / "sensor.yaml"); }, "sensor.yaml", 0,
                    "resolution: [1000000000000, 32] px, expected sides of at most 100000 px");
}

TEST(IoTrajectory, EurocYamlRoundTrip) {
  const fs::path dir = testing::make_temp_dir("io-yaml");
  CameraCalibration camera;
  camera.width_px = 752;
  camera.height_px = 480;
  camera.fx = 458.654;
  camera.fy = 457.296;
  camera.cx = 367.215;
  camera.cy = 248.375;
  camera.distortion_model = DistortionModel::kRadTan;
  camera.distortion = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
  camera.T_b_c =
      make_pose(1.5, 0.02, -0.01, Eigen::Vector3d(-0.0216401454975, -0.064676986768, 0.00981073058949));
  camera.rate_hz = 20;
  write_euroc_camera_yaml(dir / "cam0/sensor.yaml", camera);
  const CameraCalibration c = read_euroc_camera_yaml(dir / "cam0/sensor.yaml");
  EXPECT_EQ(c.width_px, camera.width_px);
  EXPECT_EQ(c.height_px, camera.height_px);
  EXPECT_EQ(c.fx, camera.fx);
  EXPECT_EQ(c.fy, camera.fy);
  EXPECT_EQ(c.cx, camera.cx);
  EXPECT_EQ(c.cy, camera.cy);
  EXPECT_EQ(c.distortion_model, camera.distortion_model);
  EXPECT_EQ(c.distortion, camera.distortion);
  EXPECT_EQ(c.T_b_c.matrix(), camera.T_b_c.matrix());  // bit-exact
  EXPECT_EQ(c.rate_hz, camera.rate_hz);

  camera.distortion_model = DistortionModel::kEquidistant;
  camera.distortion = {0.1, -0.01, 0.001, -1e-4};
  write_euroc_camera_yaml(dir / "cam1/sensor.yaml", camera);
  EXPECT_EQ(read_euroc_camera_yaml(dir / "cam1/sensor.yaml").distortion, camera.distortion);
  camera.distortion_model = DistortionModel::kNone;
  camera.distortion.clear();
  write_euroc_camera_yaml(dir / "cam2/sensor.yaml", camera);
  EXPECT_EQ(read_euroc_camera_yaml(dir / "cam2/sensor.yaml").distortion_model, DistortionModel::kNone);

  ImuCalibration imu;
  imu.gyro_noise_density = 1.6968e-04;
  imu.gyro_random_walk = 1.9393e-05;
  imu.accel_noise_density = 2.0e-3;
  imu.accel_random_walk = 3.0e-3;
  imu.rate_hz = 200;
  imu.T_b_i = make_pose(0.1, 0.2, 0.3, Eigen::Vector3d(0.01, 0.02, 0.03));
  write_euroc_imu_yaml(dir / "imu0/sensor.yaml", imu);
  const ImuCalibration i = read_euroc_imu_yaml(dir / "imu0/sensor.yaml");
  EXPECT_EQ(i.gyro_noise_density, imu.gyro_noise_density);
  EXPECT_EQ(i.gyro_random_walk, imu.gyro_random_walk);
  EXPECT_EQ(i.accel_noise_density, imu.accel_noise_density);
  EXPECT_EQ(i.accel_random_walk, imu.accel_random_walk);
  EXPECT_EQ(i.rate_hz, imu.rate_hz);
  EXPECT_EQ(i.T_b_i.matrix(), imu.T_b_i.matrix());
}

TEST(IoTrajectory, EurocYamlBadInput) {
  const fs::path dir = testing::make_temp_dir("io-yaml-bad");
  const std::string T_BS = "T_BS:\n  cols: 4\n  rows: 4\n  data: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n";
  expect_data_error([&] { read_euroc_camera_yaml(dir / "none.yaml"); }, "none.yaml", 0, "file not found");
  write_file(dir / "intr.yaml",
             "%YAML:1.0\n" + T_BS + "resolution: [752, 480]\nintrinsics: [458.6, 457.3, 367.2]\n");
  expect_data_error([&] { read_euroc_camera_yaml(dir / "intr.yaml"); }, "intr.yaml", 7,
                    "expected a list of 4");
  write_file(dir / "nan.yaml",
             "%YAML:1.0\n" + T_BS + "resolution: [752, 480]\nintrinsics: [458.6, .nan, 1, 2]\n");
  expect_data_error([&] { read_euroc_camera_yaml(dir / "nan.yaml"); }, "nan.yaml", 7, "finite number");
  write_file(dir / "nokey.yaml", "%YAML:1.0\n" + T_BS + "intrinsics: [1, 2, 3, 4]\n");
  expect_data_error([&] { read_euroc_camera_yaml(dir / "nokey.yaml"); }, "nokey.yaml", 0,
                    "missing key 'resolution'");
  write_file(
      dir / "model.yaml",
      "%YAML:1.0\n" + T_BS + "resolution: [752, 480]\nintrinsics: [1, 2, 3, 4]\ndistortion_model: fancy\n");
  expect_data_error([&] { read_euroc_camera_yaml(dir / "model.yaml"); }, "model.yaml", 8,
                    "expected radial-tangential");
  write_file(dir / "syntax.yaml", "%YAML:1.0\nT_BS: [1, 2\nrate_hz: 3\n");
  expect_data_error([&] { read_euroc_imu_yaml(dir / "syntax.yaml"); }, "syntax.yaml", 0, "malformed YAML");
  write_file(dir / "tbs.yaml",
             "%YAML:1.0\nT_BS:\n  cols: 4\n  rows: 4\n  data: [2,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n"
             "rate_hz: 200\ngyroscope_noise_density: 1\ngyroscope_random_walk: 1\n"
             "accelerometer_noise_density: 1\naccelerometer_random_walk: 1\n");
  expect_data_error([&] { read_euroc_imu_yaml(dir / "tbs.yaml"); }, "tbs.yaml", 5, "not a rotation matrix");
  write_file(dir / "imu.yaml", "%YAML:1.0\n" + T_BS + "rate_hz: 200\ngyroscope_noise_density: 1\n");
  expect_data_error([&] { read_euroc_imu_yaml(dir / "imu.yaml"); }, "imu.yaml", 0, "gyroscope_random_walk");
}

TEST(IoTrajectory, EurocRealYaml) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/MH_05_difficult/mav0/cam0/sensor.yaml");
  const fs::path mav = testing::shared_data_dir() / "euroc/MH_05_difficult/mav0";
  const CameraCalibration c = read_euroc_camera_yaml(mav / "cam0/sensor.yaml");
  EXPECT_EQ(c.width_px, 752);
  EXPECT_EQ(c.height_px, 480);
  EXPECT_DOUBLE_EQ(c.fx, 458.654);
  EXPECT_DOUBLE_EQ(c.cy, 248.375);
  EXPECT_EQ(c.distortion_model, DistortionModel::kRadTan);
  ASSERT_EQ(c.distortion.size(), 4u);
  EXPECT_DOUBLE_EQ(c.distortion[3], 1.76187114e-05);
  EXPECT_DOUBLE_EQ(c.T_b_c.translation().y(), -0.064676986768);
  EXPECT_DOUBLE_EQ(c.rate_hz, 20);
  const ImuCalibration i = read_euroc_imu_yaml(mav / "imu0/sensor.yaml");
  EXPECT_DOUBLE_EQ(i.gyro_noise_density, 1.6968e-04);
  EXPECT_DOUBLE_EQ(i.accel_random_walk, 3.0e-3);
  EXPECT_DOUBLE_EQ(i.rate_hz, 200);
  EXPECT_TRUE(i.T_b_i.matrix().isIdentity(0.0));
}

TEST(IoTrajectory, KittiPosesTimesCalib) {
  const fs::path dir = testing::make_temp_dir("io-kitti");
  std::vector<Eigen::Isometry3d> poses;
  std::vector<Timestamp> times;
  for (int i = 0; i < 30; ++i) {
    poses.push_back(make_pose(0.05 * i, 0.01, 0.0, Eigen::Vector3d(0.1 * i, 0.0, 0.8 * i)));
    times.push_back(103735900LL * i);
  }
  write_kitti_poses(dir / "poses.txt", poses);
  write_kitti_times(dir / "times.txt", times);
  EXPECT_EQ(read_kitti_times(dir / "times.txt"), times);
  const auto read = read_kitti_poses(dir / "poses.txt", dir / "times.txt");
  ASSERT_EQ(read.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(read[i].t_ns, times[i]);
    EXPECT_EQ(read[i].T_w_b.matrix(), poses[i].matrix());  // the matrix is kept as written
  }
  // Fewer poses than times: an error unless allowed.
  write_kitti_poses(dir / "short.txt", std::vector<Eigen::Isometry3d>(poses.begin(), poses.begin() + 10));
  expect_data_error([&] { read_kitti_poses(dir / "short.txt", dir / "times.txt"); }, "short.txt", 0,
                    "10 poses, expected 30");
  EXPECT_EQ(read_kitti_poses(dir / "short.txt", dir / "times.txt", true).size(), 10u);

  write_file(dir / "badpose.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 0 0\n");
  write_file(dir / "t2.txt", "0.0\n0.1\n");
  expect_data_error([&] { read_kitti_poses(dir / "badpose.txt", dir / "t2.txt"); }, "badpose.txt", 2,
                    "not a rotation matrix");
  write_file(dir / "badtimes.txt", "0.0\n0.1\n0.1\n");
  expect_data_error([&] { read_kitti_times(dir / "badtimes.txt"); }, "badtimes.txt", 3, "duplicate time");

  write_file(
      dir / "calib.txt",
      "P0: 7.188560000000e+02 0 6.071928000000e+02 0 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0\n"
      "P1: 7.188560000000e+02 0 6.071928000000e+02 -3.861448000000e+02 0 7.188560000000e+02 "
      "1.852157000000e+02 0 0 0 1 0\n");
  const CameraCalibration c0 = read_kitti_calib(dir / "calib.txt", 0);
  EXPECT_DOUBLE_EQ(c0.fx, 718.856);
  EXPECT_DOUBLE_EQ(c0.cx, 607.1928);
  EXPECT_DOUBLE_EQ(c0.cy, 185.2157);
  EXPECT_TRUE(c0.T_b_c.matrix().isIdentity(0.0));
  const CameraCalibration c1 = read_kitti_calib(dir / "calib.txt", 1);
  EXPECT_NEAR(c1.T_b_c.translation().x(), 386.1448 / 718.856, 1e-12);  // right camera, +x of camera 0
  expect_data_error([&] { read_kitti_calib(dir / "calib.txt", 2); }, "calib.txt", 0, "no line 'P2:'");
}

// Random damage never escapes as anything but DataError (strict) and never throws at all (lenient).
TEST(IoTrajectory, GarbageInputOnlyGivesDataErrors) {
  const fs::path dir = testing::make_temp_dir("io-fuzz");
  const std::string alphabet = "0123456789,.,-e+ \n\n#naif\r\t";
  std::mt19937 rng(11);
  std::uniform_int_distribution<std::size_t> pick(0, alphabet.size() - 1);
  std::uniform_int_distribution<int> length(0, 400);
  int strict_errors = 0;
  for (int round = 0; round < 200; ++round) {
    std::string text = round % 2 ? "100,0,0,0,0,0,9.8\n200,0,0,0,1,0,0,0\n" : "";
    const int n = length(rng);
    for (int i = 0; i < n; ++i) text += alphabet[pick(rng)];
    const fs::path file = dir / "garbage.txt";
    write_file(file, text);
    const auto strict = [&](auto&& read) {
      try {
        read();
      } catch (const DataError&) {
        ++strict_errors;
      }
    };
    strict([&] { read_euroc_imu(file); });
    strict([&] { read_euroc_groundtruth(file); });
    strict([&] { read_euroc_camera_csv(file); });
    strict([&] { read_tum(file); });
    strict([&] { read_kitti_times(file); });
    std::vector<DataIssue> issues;
    io_detail::IssueLog lenient(false, &issues);
    // Lenient: bad rows are recorded; only a file mostly bad is an error, and only a DataError.
    const auto tolerant = [&](auto&& read) {
      try {
        read();
      } catch (const DataError& e) {
        EXPECT_NE(e.message().find("more than half of the file is rejected"), std::string::npos) << e.what();
      }
    };
    tolerant([&] { io_detail::read_euroc_imu(file, lenient); });
    tolerant([&] { io_detail::read_euroc_groundtruth(file, lenient); });
    tolerant([&] { io_detail::read_euroc_camera_csv(file, lenient); });
    tolerant([&] { io_detail::read_tum(file, lenient); });
    tolerant([&] { io_detail::read_kitti_time_rows(file, lenient); });
    tolerant([&] { io_detail::read_kitti_pose_rows(file, lenient); });
    for (const DataIssue& issue : issues) ASSERT_GT(issue.line, 0u) << issue.to_string();
  }
  EXPECT_GT(strict_errors, 200);  // the garbage is mostly rejected
}

}  // namespace
}  // namespace loopgate
