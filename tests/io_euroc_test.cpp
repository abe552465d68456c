// EuRoC ASL reader: generated datasets (every part, damaged parts, lenient mode) and the shared real
// sequences (MH_05 without images, the V1_01 excerpt with images).
#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 40;
constexpr int kHeight = 24;
constexpr Timestamp kT0 = 1'000'000'000'000;
constexpr Timestamp kFramePeriod = 50'000'000;  // 20 Hz
constexpr Timestamp kImuPeriod = 5'000'000;     // 200 Hz
constexpr int kFrames = 12;

void write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

cv::Mat frame_image(int i, int width = kWidth, int height = kHeight) {
  cv::Mat image(height, width, CV_8UC1);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c)
      image.at<unsigned char>(r, c) = static_cast<unsigned char>((r * 7 + c * 3 + i * 11) % 256);
  }
  return image;
}

Eigen::Isometry3d gt_pose(Timestamp t_ns) {
  const double s = ns_to_s(t_ns - kT0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.3 * s, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(1.0 * s, 2.0 * s, 0.5);
  return T;
}

// A complete small EuRoC dataset at `dir` (dir/mav0/...). Ground truth starts 10 ms after the first
// frame and runs at 200 Hz, offset by 2.5 ms from the frame times (so frames need interpolation).
void make_euroc(const fs::path& dir, bool with_images = true) {
  const fs::path mav = dir / "mav0";
  std::vector<EurocImageEntry> entries;
  for (int i = 0; i < kFrames; ++i) {
    const Timestamp t = kT0 + i * kFramePeriod;
    entries.push_back(EurocImageEntry{t, std::to_string(t) + ".png"});
    if (with_images) {
      fs::create_directories(mav / "cam0/data");
      cv::imwrite((mav / "cam0/data" / entries.back().filename).string(), frame_image(i));
    }
  }
  write_euroc_camera_csv(mav / "cam0/data.csv", entries);
  CameraCalibration camera;
  camera.width_px = kWidth;
  camera.height_px = kHeight;
  camera.fx = 30;
  camera.fy = 31;
  camera.cx = 20;
  camera.cy = 12;
  camera.distortion_model = DistortionModel::kRadTan;
  camera.distortion = {-0.28, 0.07, 0.0002, 1.7e-5};
  camera.T_b_c.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  camera.rate_hz = 20;
  write_euroc_camera_yaml(mav / "cam0/sensor.yaml", camera);

  std::vector<ImuSample> imu;
  for (Timestamp t = kT0 - 20 * kImuPeriod; t <= kT0 + kFrames * kFramePeriod; t += kImuPeriod) {
    ImuSample s;
    s.t_ns = t;
    s.gyro_radps = Eigen::Vector3d(0, 0, 0.3);
    s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
    imu.push_back(s);
  }
  write_euroc_imu(mav / "imu0/data.csv", imu);
  ImuCalibration imu_calib;
  imu_calib.gyro_noise_density = 1.6968e-04;
  imu_calib.gyro_random_walk = 1.9393e-05;
  imu_calib.accel_noise_density = 2.0e-3;
  imu_calib.accel_random_walk = 3.0e-3;
  imu_calib.rate_hz = 200;
  write_euroc_imu_yaml(mav / "imu0/sensor.yaml", imu_calib);

  std::vector<GroundTruthState> gt;
  for (Timestamp t = kT0 + 10'000'000 + 2'500'000; t <= kT0 + kFrames * kFramePeriod; t += kImuPeriod) {
    GroundTruthState s;
    s.t_ns = t;
    s.T_w_b = gt_pose(t);
    gt.push_back(s);
  }
  write_euroc_groundtruth(mav / "state_groundtruth_estimate0/data.csv", gt);
}

using testing::catch_data_error;

TEST(IoEuroc, GeneratedDatasetReadsEverything) {
  const fs::path dir = testing::make_temp_dir("io-euroc");
  make_euroc(dir);
  for (const fs::path& root : {dir, dir / "mav0"}) {
    const auto d = open_euroc(root);
    EXPECT_EQ(d->layout(), DatasetLayout::kEuroc);
    EXPECT_EQ(d->root(), root);
    ASSERT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));
    EXPECT_EQ(d->frame_t_ns(3), kT0 + 3 * kFramePeriod);
    EXPECT_TRUE(d->has_images());
    EXPECT_EQ(d->image_path(3).filename().string(), std::to_string(kT0 + 3 * kFramePeriod) + ".png");
    for (std::size_t i = 0; i < d->frame_count(); ++i) {
      const cv::Mat image = d->load_image(i);
      ASSERT_EQ(image.type(), CV_8UC1);
      EXPECT_EQ(cv::norm(image, frame_image(static_cast<int>(i)), cv::NORM_INF), 0.0);
    }
    ASSERT_TRUE(d->has_imu());
    EXPECT_EQ(d->imu_samples().size(), static_cast<std::size_t>(20 + kFrames * 10 + 1));
    ASSERT_TRUE(d->camera());
    EXPECT_EQ(d->camera()->fy, 31);
    EXPECT_EQ(d->camera()->distortion_model, DistortionModel::kRadTan);
    EXPECT_EQ(d->camera()->T_b_c.translation(), Eigen::Vector3d(0.1, -0.2, 0.3));
    ASSERT_TRUE(d->imu_calibration());
    EXPECT_EQ(d->imu_calibration()->accel_noise_density, 2.0e-3);
    EXPECT_TRUE(d->issues().empty());

    // Ground truth: frame 0 precedes it; frame 1 onwards lies between two rows (interpolated).
    ASSERT_TRUE(d->has_ground_truth());
    EXPECT_FALSE(d->ground_truth_T_w_b(0));
    for (std::size_t i = 1; i < d->frame_count(); ++i) {
      const auto T = d->ground_truth_T_w_b(i);
      ASSERT_TRUE(T) << i;
      const Eigen::Isometry3d expected = gt_pose(d->frame_t_ns(i));
      EXPECT_LT((T->translation() - expected.translation()).norm(), 1e-9);       // linear motion: exact
      EXPECT_LT((T->linear() - expected.linear()).cwiseAbs().maxCoeff(), 1e-9);  // constant rate: slerp exact
    }
  }
}

TEST(IoEuroc, ImuBetweenIsHalfOpen) {
  const fs::path dir = testing::make_temp_dir("io-euroc-imu");
  make_euroc(dir);
  const auto d = open_dataset(dir);
  const auto span = d->imu_between(d->frame_t_ns(1), d->frame_t_ns(2));
  ASSERT_EQ(span.size(), 10u);
  EXPECT_EQ(span.front().t_ns, d->frame_t_ns(1));
  EXPECT_EQ(span.back().t_ns, d->frame_t_ns(2) - kImuPeriod);
  EXPECT_TRUE(d->imu_between(d->frame_t_ns(2), d->frame_t_ns(1)).empty());
}

TEST(IoEuroc, ImagesAbsentStillWorks) {
  const fs::path dir = testing::make_temp_dir("io-euroc-noimg");
  make_euroc(dir, false);
  const auto d = open_dataset(dir);
  EXPECT_EQ(d->layout(), DatasetLayout::kEuroc);
  EXPECT_FALSE(d->has_images());
  EXPECT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));
  EXPECT_TRUE(d->has_imu());
  EXPECT_TRUE(d->ground_truth_T_w_b(5));
  const DataError e = catch_data_error([&] { d->load_image(2); });
  EXPECT_NE(std::string(e.what()).find("frame 2: image absent"), std::string::npos) << e.what();
}

TEST(IoEuroc, DamagedImagesFailOnlyTheirFrame) {
  const fs::path dir = testing::make_temp_dir("io-euroc-damaged");
  make_euroc(dir);
  const auto d0 = open_euroc(dir);
  // Frame 2: garbage bytes. Frame 4: removed. Frame 6: wrong size. Frame 8: empty file. Frame 10: truncated.
  write_file(d0->image_path(2), "this is not a png");
  fs::remove(d0->image_path(4));
  cv::imwrite(d0->image_path(6).string(), frame_image(6, kWidth + 2, kHeight));
  write_file(d0->image_path(8), "");
  // Frame 10: a grey PNG cut in half (the fast grey path declines it, OpenCV refuses it).
  {
    std::string bytes(fs::file_size(d0->image_path(10)), '\0');
    std::ifstream(d0->image_path(10), std::ios::binary)
        .read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    write_file(d0->image_path(10), bytes.substr(0, bytes.size() / 2));
  }
  const auto d = open_euroc(dir);
  EXPECT_TRUE(d->has_images());
  const auto expect_frame_error = [&](std::size_t frame, const std::string& needle) {
    const DataError e = catch_data_error([&] { d->load_image(frame); });
    EXPECT_EQ(e.file(), d->image_path(frame));
    EXPECT_NE(std::string(e.what()).find("frame " + std::to_string(frame) + ": " + needle), std::string::npos)
        << e.what();
  };
  expect_frame_error(2, "cannot decode image");
  expect_frame_error(4, "image file missing");
  expect_frame_error(6, "image is 42x24, expected 40x24 like cam0/sensor.yaml resolution");
  expect_frame_error(8, "cannot decode image");
  expect_frame_error(10, "cannot decode image");
  for (const std::size_t ok : {0u, 1u, 3u, 5u, 7u, 9u, 11u}) EXPECT_EQ(d->load_image(ok).cols, kWidth);
}

TEST(IoEuroc, MissingPartsAreReported) {
  const fs::path dir = testing::make_temp_dir("io-euroc-missing");
  EXPECT_THROW(open_euroc(dir / "nowhere"), DataError);
  make_euroc(dir);
  // cam1 requested but absent.
  OpenOptions cam1;
  cam1.camera_index = 1;
  const DataError e1 = catch_data_error([&] { open_euroc(dir, cam1); });
  EXPECT_NE(std::string(e1.what()).find("cam1"), std::string::npos) << e1.what();
  OpenOptions bad_index;
  bad_index.camera_index = 2;
  try {
    open_euroc(dir, bad_index);
    ADD_FAILURE() << "expected a ConfigError";
  } catch (const ConfigError& e) {  // 2 and 3 are KITTI's colour cameras, not EuRoC's
    EXPECT_NE(std::string(e.what()).find("camera_index: 2, expected 0 or 1 for the EuRoC layout"),
              std::string::npos)
        << e.what();
  }
  // IMU and ground truth are optional.
  fs::remove_all(dir / "mav0/imu0");
  fs::remove_all(dir / "mav0/state_groundtruth_estimate0");
  const auto d = open_euroc(dir);
  EXPECT_FALSE(d->has_imu());
  EXPECT_FALSE(d->has_ground_truth());
  EXPECT_FALSE(d->imu_calibration());
  EXPECT_FALSE(d->ground_truth_T_w_b(3));
  // cam0/data.csv is required.
  fs::remove(dir / "mav0/cam0/data.csv");
  const DataError e2 = catch_data_error([&] { open_euroc(dir); });
  EXPECT_EQ(e2.file(), dir / "mav0/cam0/data.csv");
  EXPECT_NE(std::string(e2.what()).find("file not found"), std::string::npos);
}

TEST(IoEuroc, CameraIndexOneReadsCam1) {
  const fs::path dir = testing::make_temp_dir("io-euroc-cam1");
  make_euroc(dir);
  fs::copy(dir / "mav0/cam0", dir / "mav0/cam1", fs::copy_options::recursive);
  OpenOptions options;
  options.camera_index = 1;
  const auto d = open_euroc(dir, options);
  EXPECT_EQ(d->image_path(0).parent_path().parent_path().filename(), "cam1");
  EXPECT_EQ(d->load_image(0).rows, kHeight);
}

// One damaged dataset, read strictly (first problem throws) and leniently (problems recorded).
void damage(const fs::path& dir) {
  const fs::path mav = dir / "mav0";
  std::string cam = "#timestamp [ns],filename\n";
  for (int i = 0; i < kFrames; ++i) {
    const Timestamp t = kT0 + i * kFramePeriod;
    cam += std::to_string(t) + "," + std::to_string(t) + ".png\n";
    if (i == 3) cam += std::to_string(t) + "," + std::to_string(t) + ".png\n";  // line 6: duplicate
    if (i == 5) cam += "garbage,x.png\n";                                       // line 9: non-numeric
  }
  write_file(mav / "cam0/data.csv", cam);
  std::string imu = "#timestamp [ns],wx,wy,wz,ax,ay,az\n";
  imu += std::to_string(kT0) + ",0,0,0,0,0,9.8\n";
  imu += std::to_string(kT0 + 10) + ",0,0,0,0,0,9.8\n";
  imu += std::to_string(kT0 + 5) + ",0,0,0,0,0,9.8\n";     // line 4: 5 after 10...
  imu += std::to_string(kT0 + 10) + ",0,0,0,0,0,9.8\n";    // line 5: ...so line 3 is the one out of order
  imu += std::to_string(kT0 + 20) + ",0,0,nan,0,0,9.8\n";  // line 6: NaN (skipped)
  imu += std::to_string(kT0 + 30) + ",0,0,0,0,0,9.8\n";
  imu += std::to_string(kT0 + 40) + ",0,0,0";  // line 8: truncated (recorded)
  write_file(mav / "imu0/data.csv", imu);
  std::string gt = "#t,p,q\n";
  gt += std::to_string(kT0) + ",0,0,0,1,0,0,0\n";
  gt += std::to_string(kT0 + kFramePeriod * 20) + ",1,2,3,1,0,0,0\n";
  gt += std::to_string(kT0 + kFramePeriod) + ",9,9,9,1,0,0,0\n";     // line 4: goes back (skipped)
  gt += std::to_string(kT0 + kFramePeriod * 21) + ",1,2,3,1,0,0\n";  // line 5: 7 columns
  write_file(mav / "state_groundtruth_estimate0/data.csv", gt);
}

TEST(IoEuroc, StrictThrowsOnFirstProblem) {
  const fs::path dir = testing::make_temp_dir("io-euroc-strict");
  make_euroc(dir);
  damage(dir);
  const DataError e = catch_data_error([&] { open_euroc(dir); });
  EXPECT_EQ(e.file(), dir / "mav0/cam0/data.csv");
  EXPECT_EQ(e.line(), 6u);
  EXPECT_NE(e.message().find("duplicate camera timestamp"), std::string::npos) << e.what();
}

TEST(IoEuroc, LenientRecordsAndSkips) {
  const fs::path dir = testing::make_temp_dir("io-euroc-lenient");
  make_euroc(dir);
  damage(dir);
  OpenOptions options;
  options.strict = false;
  const auto d = open_euroc(dir, options);
  EXPECT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));  // the two bad rows skipped
  for (std::size_t i = 0; i < d->frame_count(); ++i) EXPECT_EQ(d->frame_t_ns(i), kT0 + i * kFramePeriod);
  // IMU: the longest run of increasing times is kept (0, 5, 10, 30: line 3 is the sample out of
  // order with the samples around it, dropped like a row of any other table); NaN and truncated rows skipped.
  std::vector<Timestamp> imu_t;
  for (const ImuSample& s : d->imu_samples()) imu_t.push_back(s.t_ns - kT0);
  EXPECT_EQ(imu_t, (std::vector<Timestamp>{0, 5, 10, 30}));
  EXPECT_EQ(d->imu_between(kT0 + 6, kT0 + 30).size(), 1u);  // 10
  ASSERT_EQ(d->ground_truth().size(), 2u);

  struct Expected {
    std::string file;
    std::size_t line;
    std::string needle;
  };
  const std::vector<Expected> expected = {
      {"cam0/data.csv", 6, "duplicate camera timestamp"},
      {"cam0/data.csv", 9, "column 1 (timestamp [ns]): expected an integer timestamp in ns, got 'garbage'"},
      {"imu0/data.csv", 3,
       "IMU timestamp " + std::to_string(kT0 + 10) + " ns is after line 4 (" + std::to_string(kT0 + 5) +
           " ns)"},
      {"imu0/data.csv", 6, "column 4 (w_z): expected a finite number, got 'nan'"},
      {"imu0/data.csv", 8, "truncated last line"},
      {"state_groundtruth_estimate0/data.csv", 4, "ground-truth timestamp"},
      {"state_groundtruth_estimate0/data.csv", 5, "expected 8 columns like the first data row, got 7"},
  };
  ASSERT_EQ(d->issues().size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const DataIssue& issue = d->issues()[i];
    EXPECT_EQ(issue.file, dir / "mav0" / expected[i].file) << issue.to_string();
    EXPECT_EQ(issue.line, expected[i].line) << issue.to_string();
    EXPECT_NE(issue.message.find(expected[i].needle), std::string::npos) << issue.to_string();
    EXPECT_EQ(
        issue.to_string().rfind(
            (dir / "mav0" / expected[i].file).string() + ":" + std::to_string(expected[i].line) + ": ", 0),
        0u);
  }
}

TEST(IoEuroc, LenientIgnoresMalformedCalibration) {
  const fs::path dir = testing::make_temp_dir("io-euroc-badyaml");
  make_euroc(dir);
  write_file(dir / "mav0/cam0/sensor.yaml", "%YAML:1.0\nintrinsics: [1, 2]\n");
  EXPECT_THROW(open_euroc(dir), DataError);
  OpenOptions options;
  options.strict = false;
  const auto d = open_euroc(dir, options);
  EXPECT_FALSE(d->camera());
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_NE(d->issues()[0].message.find("calibration ignored"), std::string::npos);
  EXPECT_EQ(d->load_image(0).cols, kWidth);  // size reference then comes from the first frame
}

TEST(IoEuroc, GroundTruthSensorExtrinsicIsApplied) {
  const fs::path dir = testing::make_temp_dir("io-euroc-gtbs");
  make_euroc(dir);
  write_file(dir / "mav0/state_groundtruth_estimate0/sensor.yaml",
             "%YAML:1.0\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1,0,0,0.5, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n");
  const auto d = open_euroc(dir);
  const auto T = d->ground_truth_T_w_b(4);
  ASSERT_TRUE(T);
  Eigen::Isometry3d T_s_b = Eigen::Isometry3d::Identity();
  T_s_b.translation() = Eigen::Vector3d(-0.5, 0, 0);
  // Interpolating the moved poses is not exact (lever arm under rotation), but far below the 0.5 m offset.
  EXPECT_LT(((gt_pose(d->frame_t_ns(4)) * T_s_b).matrix() - T->matrix()).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(IoEuroc, RealMh05WithoutImages) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/MH_05_difficult/mav0");
  const auto d = open_dataset(testing::shared_data_dir() / "euroc/MH_05_difficult");
  EXPECT_EQ(d->layout(), DatasetLayout::kEuroc);
  EXPECT_EQ(d->frame_count(), 2273u);
  EXPECT_EQ(d->frame_t_ns(0), 1403638518077829376);
  EXPECT_FALSE(d->has_images());
  EXPECT_THROW(d->load_image(0), DataError);
  ASSERT_TRUE(d->has_imu());
  EXPECT_EQ(d->imu_samples().size(), 22721u);
  EXPECT_EQ(d->imu_samples().front().t_ns, 1403638518097829376);
  EXPECT_DOUBLE_EQ(d->imu_samples().front().accel_mps2.x(), 9.0874956666666655);
  EXPECT_DOUBLE_EQ(d->imu_samples().back().accel_mps2.z(), -3.702010375);
  ASSERT_TRUE(d->has_ground_truth());
  EXPECT_EQ(d->ground_truth().size(), 22212u);
  EXPECT_EQ(d->ground_truth().front().t_ns, 1403638519492829440);
  EXPECT_DOUBLE_EQ(d->ground_truth().front().T_w_b.translation().x(), 4.460675);
  EXPECT_DOUBLE_EQ(d->ground_truth().front().gyro_bias_radps.z(), 0.076870);
  EXPECT_FALSE(d->ground_truth_T_w_b(0));  // before the ground truth starts
  // A frame inside the span interpolates between its neighbours.
  std::size_t inside = 0;
  while (d->frame_t_ns(inside) < d->ground_truth().front().t_ns) ++inside;
  const auto T = d->ground_truth_T_w_b(inside + 100);
  ASSERT_TRUE(T);
  EXPECT_LT(T->translation().norm(), 30.0);
  ASSERT_TRUE(d->camera());
  EXPECT_EQ(d->camera()->width_px, 752);
  EXPECT_DOUBLE_EQ(d->camera()->fx, 458.654);
  EXPECT_DOUBLE_EQ(d->camera()->distortion[0], -0.28340811);
  EXPECT_NEAR(d->camera()->T_b_c(0, 1), -0.999880929698, 0);
  ASSERT_TRUE(d->imu_calibration());
  EXPECT_DOUBLE_EQ(d->imu_calibration()->gyro_random_walk, 1.9393e-05);
  EXPECT_TRUE(d->issues().empty());
  // Frames are 20 Hz: about 10 IMU samples between consecutive frames.
  EXPECT_EQ(d->imu_between(d->frame_t_ns(100), d->frame_t_ns(101)).size(), 10u);
}

TEST(IoEuroc, RealV101MicroImagesDecode) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/V1_01_easy_micro/mav0");
  const auto d = open_dataset(testing::shared_data_dir() / "euroc/V1_01_easy_micro");
  EXPECT_EQ(d->frame_count(), 95u);
  ASSERT_TRUE(d->has_images());
  for (std::size_t i = 0; i < d->frame_count(); ++i) {
    const cv::Mat image = d->load_image(i);
    ASSERT_EQ(image.cols, 752);
    ASSERT_EQ(image.rows, 480);
    ASSERT_EQ(image.type(), CV_8UC1);
  }
  EXPECT_GT(cv::mean(d->load_image(50))[0], 10.0);  // real pixels, not blank
  EXPECT_EQ(d->imu_samples().size(), 29120u);
  // Ground truth comes from groundtruth_tum.txt beside mav0/.
  EXPECT_EQ(d->ground_truth().size(), 28712u);
  EXPECT_EQ(d->ground_truth().front().t_ns, 1403715274302140000);
  EXPECT_FALSE(d->ground_truth_T_w_b(0));  // images start 1 s before the ground truth
  EXPECT_TRUE(d->ground_truth_T_w_b(94));
  // cam1 has its own data.csv (99 rows) but no images here.
  OpenOptions cam1;
  cam1.camera_index = 1;
  const auto d1 = open_dataset(testing::shared_data_dir() / "euroc/V1_01_easy_micro", cam1);
  EXPECT_EQ(d1->frame_count(), 99u);
  EXPECT_FALSE(d1->has_images());
  EXPECT_DOUBLE_EQ(d1->camera()->fx, 457.587);
}

}  // namespace
}  // namespace loopgate
