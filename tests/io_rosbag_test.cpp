// ROS1 bag reader on bags the tests write (tests/bag_test_writer.hpp): frames timed by
// header.stamp and read again in any order and from several threads, IMU, the encodings (colour converted
// like a colour PNG, 16-bit scaled like a 16-bit PNG, unknown ones named), CompressedImage decoding to the
// pixels of the same PNG or JPEG file, calibration and ground truth from an EuRoC ASL folder, and the errors
// naming the bag, the topic and the message. Every test skips in a build without bag support, but the one
// that checks its error.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>
#include <utility>

#include "bag_test_writer.hpp"
#include "core/error.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::BagTestWriter;

constexpr int kWidth = 40;
constexpr int kHeight = 24;
constexpr Timestamp kT0 = 1'403'636'579'763'555'584;  // EuRoC MH_01's first camera time
constexpr Timestamp kFramePeriod = 50'000'000;        // 20 Hz
constexpr Timestamp kImuPeriod = 5'000'000;           // 200 Hz
constexpr const char* kCam = "/cam0/image_raw";
constexpr const char* kImu = "/imu0";

cv::Mat frame_image(int i, int width = kWidth, int height = kHeight) {
  cv::Mat image(height, width, CV_8UC1);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c)
      image.at<unsigned char>(r, c) = static_cast<unsigned char>((r * 7 + c * 3 + i * 11) % 256);
  }
  return image;
}

cv::Mat colour_image(int i) {
  cv::Mat bgr(kHeight, kWidth, CV_8UC3);
  for (int r = 0; r < kHeight; ++r) {
    for (int c = 0; c < kWidth; ++c) {
      bgr.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<unsigned char>((r * 5 + i) % 256),
                                          static_cast<unsigned char>((c * 9 + 3 * i) % 256),
                                          static_cast<unsigned char>((r * c + 7 * i) % 256));
    }
  }
  return bgr;
}

// The bytes of `image` row by row with `step` bytes per row (padding 0xEE).
std::vector<std::uint8_t> rows_of(const cv::Mat& image, std::uint32_t step) {
  const std::size_t row_bytes = static_cast<std::size_t>(image.cols) * image.elemSize();
  std::vector<std::uint8_t> data(static_cast<std::size_t>(step) * static_cast<std::size_t>(image.rows), 0xEE);
  for (int r = 0; r < image.rows; ++r)
    std::copy_n(image.ptr<std::uint8_t>(r), row_bytes, data.begin() + static_cast<std::ptrdiff_t>(step) * r);
  return data;
}

void write_mono(BagTestWriter& bag, const std::string& topic, Timestamp t_ns, const cv::Mat& grey,
                Timestamp bag_t_ns = -1) {
  bag.image(topic, t_ns, static_cast<std::uint32_t>(grey.cols), static_cast<std::uint32_t>(grey.rows),
            "mono8", static_cast<std::uint32_t>(grey.cols),
            rows_of(grey, static_cast<std::uint32_t>(grey.cols)), bag_t_ns);
}

// A bag like EuRoC's: `frames` mono8 images on /cam0/image_raw and 200 Hz IMU on /imu0 from kT0 on. The
// images are recorded 3 ms after their header.stamp (bag time is the arrival time, the frame time is the
// stamp).
fs::path write_euroc_bag(const fs::path& dir, int frames, const std::string& compression = "none") {
  const fs::path file = dir / "seq.bag";
  BagTestWriter bag(file.string(), compression);
  for (int k = 0; k < frames * 10; ++k) {
    const double s = static_cast<double>(k) * 0.005;
    bag.imu(kImu, kT0 + k * kImuPeriod, {0.1 * s, -0.2, 0.3}, {9.81, 0.01 * k, -0.5});
    if (k % 10 == 0)
      write_mono(bag, kCam, kT0 + (k / 10) * kFramePeriod, frame_image(k / 10),
                 kT0 + k * kImuPeriod + 3'000'000);
  }
  bag.close();
  return file;
}

bool same_pixels(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::countNonZero(a != b) == 0;
}

OpenOptions strict() {
  OpenOptions options;
  options.strict = true;
  return options;
}

// The DataError opening `bag` gives (its what()); it must name `file` (the bag when empty).
std::string open_error(const fs::path& bag, const OpenOptions& options, const fs::path& file = {}) {
  try {
    open_dataset(bag, options);
  } catch (const DataError& e) {
    EXPECT_EQ(e.file(), file.empty() ? bag : file) << e.what();
    return e.what();
  }
  ADD_FAILURE() << bag << " opened, expected a DataError";
  return "";
}

TEST(IoRosbag, FramesByHeaderStampImuAndRandomAccess) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path bag = write_euroc_bag(testing::make_temp_dir("rosbag-euroc"), 8);
  const auto d = open_dataset(bag, strict());
  EXPECT_EQ(d->layout(), DatasetLayout::kRosbag);
  EXPECT_EQ(d->root(), bag);
  ASSERT_EQ(d->frame_count(), 8u);
  ASSERT_TRUE(d->has_images());
  for (std::size_t f = 0; f < 8; ++f) {
    EXPECT_EQ(d->frame_t_ns(f),
              kT0 + static_cast<Timestamp>(f) * kFramePeriod);  // header.stamp, not bag time
    EXPECT_EQ(d->source_index(f), f);
    EXPECT_EQ(d->image_path(f), bag);
  }
  // Any frame again, in any order: a gated run's re-reads.
  for (const std::size_t f : {7u, 0u, 3u, 3u, 6u, 1u}) {
    EXPECT_TRUE(same_pixels(d->load_image(f), frame_image(static_cast<int>(f)))) << "frame " << f;
  }
  ASSERT_TRUE(d->has_imu());
  ASSERT_EQ(d->imu_samples().size(), 80u);
  const ImuSample& s = d->imu_samples()[12];
  EXPECT_EQ(s.t_ns, kT0 + 12 * kImuPeriod);
  EXPECT_DOUBLE_EQ(s.gyro_radps.x(), 0.1 * 12 * 0.005);
  EXPECT_DOUBLE_EQ(s.gyro_radps.y(), -0.2);
  EXPECT_DOUBLE_EQ(s.accel_mps2.y(), 0.12);
  EXPECT_EQ(d->imu_between(d->frame_t_ns(1), d->frame_t_ns(2)).size(), 10u);
  EXPECT_FALSE(d->has_ground_truth());
  EXPECT_FALSE(d->camera());
  EXPECT_TRUE(d->issues().empty());
}

TEST(IoRosbag, CompressedChunksReadTheSame) {
  LOOPGATE_REQUIRE_ROSBAG();
  for (const std::string compression : {"lz4", "bz2"}) {
    const fs::path bag = write_euroc_bag(testing::make_temp_dir("rosbag-" + compression), 6, compression);
    const auto d = open_dataset(bag, strict());
    ASSERT_EQ(d->frame_count(), 6u) << compression;
    for (const std::size_t f : {5u, 0u, 2u})
      EXPECT_TRUE(same_pixels(d->load_image(f), frame_image(static_cast<int>(f)))) << compression << " " << f;
    EXPECT_EQ(d->imu_samples().size(), 60u);
  }
}

TEST(IoRosbag, LoadsFromSeveralThreadsAtOnce) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path bag = write_euroc_bag(testing::make_temp_dir("rosbag-threads"), 12);
  const auto d = open_dataset(bag, strict());
  std::vector<int> wrong(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int round = 0; round < 5; ++round) {
        for (std::size_t k = 0; k < 12; ++k) {
          const std::size_t f = (k * 5 + static_cast<std::size_t>(t)) % 12;
          if (!same_pixels(d->load_image(f), frame_image(static_cast<int>(f))))
            ++wrong[static_cast<std::size_t>(t)];
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(wrong, std::vector<int>(4, 0));
}

TEST(IoRosbag, ColourEncodingsAreGreyLikeAColourPng) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-colour");
  const cv::Mat bgr = colour_image(1);
  cv::Mat rgb, bgra, rgba;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
  cv::cvtColor(bgr, rgba, cv::COLOR_BGR2RGBA);
  {
    BagTestWriter bag((dir / "colour.bag").string());
    const std::uint32_t w = kWidth;
    bag.image(kCam, kT0, w, kHeight, "bgr8", 3 * w + 8, rows_of(bgr, 3 * w + 8));  // rows padded
    bag.image(kCam, kT0 + kFramePeriod, w, kHeight, "rgb8", 3 * w, rows_of(rgb, 3 * w));
    bag.image(kCam, kT0 + 2 * kFramePeriod, w, kHeight, "bgra8", 4 * w, rows_of(bgra, 4 * w));
    bag.image(kCam, kT0 + 3 * kFramePeriod, w, kHeight, "rgba8", 4 * w, rows_of(rgba, 4 * w));
  }
  // The same image as a colour PNG in an image folder: the reference for the grey conversion.
  fs::create_directories(dir / "folder");
  cv::imwrite((dir / "folder" / "0.png").string(), bgr);
  const cv::Mat reference = open_dataset(dir / "folder")->load_image(0);
  OpenOptions options = strict();
  options.bag_imu_topic = "";
  const auto d = open_dataset(dir / "colour.bag", options);
  ASSERT_EQ(d->frame_count(), 4u);
  for (std::size_t f = 0; f < 4; ++f) EXPECT_TRUE(same_pixels(d->load_image(f), reference)) << "frame " << f;
}

TEST(IoRosbag, CompressedImageDecodesToThePixelsOfTheSamePngOrJpeg) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-compressed");
  fs::create_directories(dir / "folder");
  std::vector<std::vector<std::uint8_t>> files;
  const std::vector<std::pair<cv::Mat, std::string>> images = {{frame_image(0), ".png"},
                                                               {colour_image(1), ".png"},
                                                               {colour_image(2), ".jpg"},
                                                               {frame_image(3), ".jpg"}};
  for (std::size_t k = 0; k < images.size(); ++k) {
    std::vector<std::uint8_t> bytes;
    ASSERT_TRUE(cv::imencode(images[k].second, images[k].first, bytes));
    std::ofstream(dir / "folder" / (std::to_string(k) + images[k].second), std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    files.push_back(bytes);
  }
  {
    BagTestWriter bag((dir / "compressed.bag").string());
    for (std::size_t k = 0; k < files.size(); ++k) {
      bag.compressed_image("/cam0/image_raw/compressed", kT0 + static_cast<Timestamp>(k) * kFramePeriod,
                           images[k].second == ".png" ? "png" : "jpeg", files[k]);
    }
  }
  OpenOptions options = strict();
  options.bag_image_topic = "/cam0/image_raw/compressed";
  options.bag_imu_topic = "";
  const auto bag = open_dataset(dir / "compressed.bag", options);
  const auto folder = open_dataset(dir / "folder", strict());
  ASSERT_EQ(bag->frame_count(), 4u);
  ASSERT_EQ(folder->frame_count(), 4u);
  for (std::size_t f = 0; f < 4; ++f) {
    const cv::Mat from_bag = bag->load_image(f);
    EXPECT_EQ(from_bag.type(), CV_8UC1);
    EXPECT_TRUE(same_pixels(from_bag, folder->load_image(f))) << "frame " << f;
  }
  EXPECT_TRUE(same_pixels(bag->load_image(0), frame_image(0)));  // PNG is lossless
}

TEST(IoRosbag, MissingTopicListsTheTopicsOfTheBag) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path bag = write_euroc_bag(testing::make_temp_dir("rosbag-topic"), 3);
  OpenOptions options = strict();
  options.bag_image_topic = "/cam1/image_raw";
  options.camera_index = 1;
  std::string error = open_error(bag, options);
  EXPECT_NE(error.find(bag.string() + ": topic /cam1/image_raw is not in the bag; its topics: "),
            std::string::npos)
      << error;
  EXPECT_NE(
      error.find("/cam0/image_raw (sensor_msgs/Image, 3 messages), /imu0 (sensor_msgs/Imu, 30 messages)"),
      std::string::npos)
      << error;

  options = strict();
  options.bag_imu_topic = "/imu1";
  error = open_error(bag, options);
  EXPECT_NE(error.find("topic /imu1 is not in the bag"), std::string::npos) << error;
  EXPECT_NE(error.find("dataset.bag_imu_topic; empty = no IMU"), std::string::npos) << error;

  options.bag_imu_topic = "";  // no IMU
  const auto d = open_dataset(bag, options);
  EXPECT_FALSE(d->has_imu());
  EXPECT_EQ(d->frame_count(), 3u);
}

// run.camera_index 1 with the default /cam0 topic paired cam0's images with cam1's calibration, silently.
TEST(IoRosbag, ATopicOfAnotherCameraThanCameraIndexIsRefused) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path bag = write_euroc_bag(testing::make_temp_dir("rosbag-camera-index"), 3);
  OpenOptions options = strict();
  options.camera_index = 1;  // the topic stays /cam0/image_raw
  std::string error;
  try {
    open_dataset(bag, options);
  } catch (const ConfigError& e) {
    error = e.what();
  }
  EXPECT_NE(error.find("dataset.bag_image_topic '/cam0/image_raw' is camera 0's images, and run.camera_index "
                       "is 1 (cam1's calibration): set dataset.bag_image_topic=/cam1/image_raw, or "
                       "run.camera_index=0"),
            std::string::npos)
      << error;
  options.camera_index = 0;
  EXPECT_EQ(open_dataset(bag, options)->frame_count(), 3u);
  options.bag_image_topic = "/camera/image_raw";  // names no camera number: no check
  options.camera_index = 1;
  EXPECT_NE(open_error(bag, options).find("topic /camera/image_raw is not in the bag"), std::string::npos);
}

TEST(IoRosbag, TopicOfAnotherTypeIsNamed) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-type");
  {
    BagTestWriter bag((dir / "t.bag").string());
    write_mono(bag, kCam, kT0, frame_image(0));
    bag.temperature("/imu0", kT0, 21.5);
  }
  OpenOptions options = strict();
  options.bag_image_topic = "/imu0";
  std::string error = open_error(dir / "t.bag", options);
  EXPECT_NE(error.find("topic /imu0 holds sensor_msgs/Temperature, expected sensor_msgs/Image or "
                       "sensor_msgs/CompressedImage"),
            std::string::npos)
      << error;
  error = open_error(dir / "t.bag", strict());  // images fine, the IMU topic is a thermometer
  EXPECT_NE(error.find("topic /imu0 holds sensor_msgs/Temperature, expected sensor_msgs/Imu"),
            std::string::npos)
      << error;
}

TEST(IoRosbag, UnknownEncodingNamesTheBagTopicAndMessage) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-encoding");
  const fs::path file = dir / "bayer.bag";
  {
    BagTestWriter bag(file.string());
    for (int i = 0; i < 5; ++i) {
      const cv::Mat image = frame_image(i);
      bag.image(kCam, kT0 + i * kFramePeriod, kWidth, kHeight, i == 2 ? "bayer_rggb8" : "mono8", kWidth,
                rows_of(image, kWidth));
    }
  }
  OpenOptions options = strict();
  options.bag_imu_topic = "";
  const std::string error = open_error(file, options);
  EXPECT_EQ(error,
            file.string() +
                ": /cam0/image_raw message 2: unknown encoding 'bayer_rggb8', expected mono8, bgr8, rgb8, "
                "bgra8, rgba8 or their 16-bit forms (mono16, ...)");
  // Lenient: that frame is skipped and recorded; the frames keep the numbers of their messages.
  options.strict = false;
  const auto d = open_dataset(file, options);
  ASSERT_EQ(d->frame_count(), 4u);
  EXPECT_EQ(d->source_index(2), 3u);
  EXPECT_TRUE(same_pixels(d->load_image(2), frame_image(3)));
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].to_string(), error);

  // Every frame of an unknown encoding: an error in lenient mode too.
  const fs::path all = dir / "yuv.bag";
  {
    BagTestWriter bag(all.string());
    for (int i = 0; i < 3; ++i)
      bag.image(kCam, kT0 + i * kFramePeriod, kWidth, kHeight, "yuv422", 2 * kWidth,
                std::vector<std::uint8_t>(2 * kWidth * kHeight, 0));
  }
  const std::string all_error = open_error(all, options);
  EXPECT_NE(all_error.find(": 3 of the 3 messages of /cam0/image_raw are bad (first: "), std::string::npos)
      << all_error;
  EXPECT_NE(all_error.find("/cam0/image_raw message 0: unknown encoding 'yuv422'"), std::string::npos)
      << all_error;
}

// 16-bit unsigned images (TUM-VI's bags and PNGs) are read by the rule of every reader: scaled to 8 bits
// over the full range (v / 257). A raw mono16 message, a 16-bit PNG inside a CompressedImage and the same PNG
// in a folder give the same pixels; signed samples are refused.
TEST(IoRosbag, SixteenBitImagesAreScaledLikeA16BitPng) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-16bit");
  cv::Mat deep(kHeight, kWidth, CV_16UC1);
  for (int r = 0; r < deep.rows; ++r)
    for (int c = 0; c < deep.cols; ++c)
      deep.at<std::uint16_t>(r, c) = static_cast<std::uint16_t>((r * 771 + c * 2570) % 65536);
  cv::Mat expected;
  deep.convertTo(expected, CV_8U, 1.0 / 257.0);
  std::vector<std::uint8_t> png16;
  ASSERT_TRUE(cv::imencode(".png", deep, png16));
  {
    BagTestWriter bag((dir / "mono16.bag").string());
    bag.image(kCam, kT0, kWidth, kHeight, "mono16", 2 * kWidth, rows_of(deep, 2 * kWidth));
  }
  {
    BagTestWriter bag((dir / "png16.bag").string());
    bag.compressed_image(kCam, kT0, "png", png16);
  }
  {
    BagTestWriter bag((dir / "signed.bag").string());
    bag.image(kCam, kT0, kWidth, kHeight, "16SC1", 2 * kWidth, rows_of(deep, 2 * kWidth));
  }
  fs::create_directories(dir / "folder");
  cv::imwrite((dir / "folder" / "0.png").string(), deep);
  OpenOptions options = strict();
  options.bag_imu_topic = "";
  for (const fs::path& source : {dir / "folder", dir / "mono16.bag", dir / "png16.bag"}) {
    const cv::Mat image = open_dataset(source, options)->load_image(0);
    ASSERT_EQ(image.type(), CV_8UC1) << source;
    EXPECT_EQ(cv::norm(image, expected, cv::NORM_INF), 0.0) << source;
  }
  const std::string signed_error = open_error(dir / "signed.bag", options);
  EXPECT_NE(
      signed_error.find("/cam0/image_raw message 0: image has signed integer samples (encoding '16SC1')"),
      std::string::npos)
      << signed_error;
}

TEST(IoRosbag, DataThatDoesNotHoldTheImageIsNamed) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-size");
  {
    BagTestWriter bag((dir / "short.bag").string());
    write_mono(bag, kCam, kT0, frame_image(0));
    bag.image(kCam, kT0 + kFramePeriod, kWidth, kHeight, "mono8", kWidth,
              std::vector<std::uint8_t>(kWidth * (kHeight - 1), 0));
    bag.image(kCam, kT0 + 2 * kFramePeriod, kWidth, kHeight, "bgr8", kWidth,  // step of a grey row
              std::vector<std::uint8_t>(kWidth * kHeight, 0));
    for (int i = 3; i < 6; ++i) write_mono(bag, kCam, kT0 + i * kFramePeriod, frame_image(i));
  }
  OpenOptions options = strict();
  options.bag_imu_topic = "";
  EXPECT_EQ(open_error(dir / "short.bag", options),
            (dir / "short.bag").string() +
                ": /cam0/image_raw message 1: data holds 920 bytes, expected step x height = 40 x 24 = 960");
  options.strict = false;
  const auto d = open_dataset(dir / "short.bag", options);
  EXPECT_EQ(d->frame_count(), 4u);
  ASSERT_EQ(d->issues().size(), 2u);
  EXPECT_NE(d->issues()[1].message.find(
                "message 2: step 40 bytes is less than a row of 40 bgr8 pixels (120 bytes)"),
            std::string::npos)
      << d->issues()[1].to_string();
}

TEST(IoRosbag, HeaderStampsOutOfOrderAreSkippedLikeRowsOutOfOrder) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-order");
  const fs::path file = dir / "order.bag";
  {
    BagTestWriter bag(file.string());
    // Message 3 carries a stamp from before message 2 (its bag time is in order).
    const Timestamp stamps[] = {kT0, kT0 + kFramePeriod, kT0 + 2 * kFramePeriod, kT0 + kFramePeriod / 2,
                                kT0 + 4 * kFramePeriod};
    for (int i = 0; i < 5; ++i) write_mono(bag, kCam, stamps[i], frame_image(i), kT0 + i * kFramePeriod);
  }
  OpenOptions options;
  options.strict = false;
  options.bag_imu_topic = "";
  const auto d = open_dataset(file, options);
  ASSERT_EQ(d->frame_count(), 4u);
  EXPECT_EQ(d->source_index(3), 4u);
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].to_string(),
            file.string() + ": /cam0/image_raw message 3: header.stamp " +
                std::to_string(kT0 + kFramePeriod / 2) + " ns is before message 2 (" +
                std::to_string(kT0 + 2 * kFramePeriod) +
                " ns), expected strictly increasing times: this message is out of order with the messages "
                "around it");
  options.strict = true;
  EXPECT_EQ(open_error(file, options), d->issues()[0].to_string());
}

TEST(IoRosbag, CalibrationAndGroundTruthFromAnAslFolder) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-asl");
  const fs::path bag = write_euroc_bag(dir, 6);
  CameraCalibration camera;
  camera.width_px = kWidth;
  camera.height_px = kHeight;
  camera.fx = camera.fy = 30;
  camera.cx = 20;
  camera.cy = 12;
  camera.rate_hz = 20;
  std::vector<GroundTruthState> truth;
  for (int k = 0; k < 40; ++k) {
    GroundTruthState s;
    s.t_ns = kT0 + k * kImuPeriod * 2;
    s.T_w_b.translation() = Eigen::Vector3d(0.1 * k, 0, 1);
    truth.push_back(s);
  }
  // Beside the bag, named like it: seq.bag -> seq/mav0/...
  write_euroc_camera_yaml(dir / "seq" / "mav0" / "cam0" / "sensor.yaml", camera);
  write_euroc_groundtruth(dir / "seq" / "mav0" / "state_groundtruth_estimate0" / "data.csv", truth);
  auto d = open_dataset(bag, strict());
  ASSERT_TRUE(d->camera());
  EXPECT_EQ(d->camera()->fx, 30);
  ASSERT_TRUE(d->has_ground_truth());
  EXPECT_EQ(d->ground_truth().size(), 40u);
  const auto T = d->ground_truth_T_w_b(2);  // frame 2 at 100 ms = ground-truth sample 10
  ASSERT_TRUE(T);
  EXPECT_NEAR(T->translation().x(), 1.0, 1e-12);

  // Elsewhere, named by dataset.bag_asl_dir (a folder holding cam0/ directly is accepted like mav0/).
  const fs::path elsewhere = testing::make_temp_dir("rosbag-asl-elsewhere");
  camera.fx = camera.fy = 31;
  write_euroc_camera_yaml(elsewhere / "cam0" / "sensor.yaml", camera);
  OpenOptions options = strict();
  options.bag_asl_dir = elsewhere;
  d = open_dataset(bag, options);
  ASSERT_TRUE(d->camera());
  EXPECT_EQ(d->camera()->fx, 31);
  EXPECT_FALSE(d->has_ground_truth());
  // Its resolution is the size every frame must have.
  camera.width_px = kWidth + 2;
  write_euroc_camera_yaml(elsewhere / "cam0" / "sensor.yaml", camera);
  d = open_dataset(bag, options);
  try {
    d->load_image(0);
    ADD_FAILURE() << "a frame of another size than the calibration's loaded";
  } catch (const DataError& e) {
    EXPECT_EQ(e.file(), bag);
    EXPECT_NE(e.message().find("image is 40x24, expected 42x24 like cam0/sensor.yaml resolution"),
              std::string::npos)
        << e.what();
  }
  options.bag_asl_dir = dir / "absent";
  EXPECT_NE(open_error(bag, options, dir / "absent").find("dataset.bag_asl_dir: not a folder"),
            std::string::npos);
}

// TUM-VI publishes bags too; its tree beside the bag gives mocap0 ground truth and Kalibr calibration (dso/).
TEST(IoRosbag, CalibrationAndGroundTruthFromATumViTree) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-tumvi");
  const fs::path bag = write_euroc_bag(dir, 6);
  std::string mocap =
      "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n";
  for (int k = 0; k <= 40; ++k)
    mocap += std::to_string(kT0 + k * 10'000'000) + "," + std::to_string(0.01 * k) + ",0,1.2,1,0,0,0\n";
  fs::create_directories(dir / "seq" / "mav0" / "mocap0");
  std::ofstream(dir / "seq" / "mav0" / "mocap0" / "data.csv") << mocap;
  fs::create_directories(dir / "seq" / "dso");
  std::ofstream(dir / "seq" / "dso" / "camchain.yaml")
      << "cam0:\n  T_cam_imu:\n  - [0.0, -1.0, 0.0, 0.05]\n  - [0.0, 0.0, -1.0, -0.04]\n"
         "  - [1.0, 0.0, 0.0, -0.07]\n  - [0.0, 0.0, 0.0, 1.0]\n  camera_model: pinhole\n"
         "  distortion_coeffs: [0.0034, 0.0007, -0.0021, 0.0002]\n  distortion_model: equidistant\n"
         "  intrinsics: [19.1, 19.0, 20.0, 12.0]\n  resolution: [40, 24]\n";
  std::ofstream(dir / "seq" / "dso" / "imu_config.yaml")
      << "accelerometer_noise_density: 0.0028\naccelerometer_random_walk: 0.00086\n"
         "gyroscope_noise_density: 0.00016\ngyroscope_random_walk: 0.000022\nupdate_rate: 200.0\n";
  const auto d = open_dataset(bag, strict());
  ASSERT_TRUE(d->has_ground_truth());
  EXPECT_EQ(d->ground_truth().size(), 41u);
  const auto T = d->ground_truth_T_w_b(1);  // 50 ms: mocap row 5
  ASSERT_TRUE(T);
  EXPECT_NEAR(T->translation().x(), 0.05, 1e-12);
  ASSERT_TRUE(d->camera());
  EXPECT_DOUBLE_EQ(d->camera()->fx, 19.1);
  EXPECT_EQ(d->camera()->distortion_model, DistortionModel::kEquidistant);
  ASSERT_TRUE(d->imu_calibration());
  EXPECT_DOUBLE_EQ(d->imu_calibration()->rate_hz, 200.0);
  EXPECT_TRUE(same_pixels(d->load_image(2), frame_image(2)));  // 40 x 24 like camchain's resolution
}

TEST(IoRosbag, AFileThatIsNotABag) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-not");
  std::ofstream(dir / "x.bag") << "#ROSBAG V2.0\nnot really\n";
  const std::string error = open_error(dir / "x.bag", strict());
  EXPECT_NE(error.find((dir / "x.bag").string() + ": cannot read it as a ROS1 bag: "), std::string::npos)
      << error;
  std::ofstream(dir / "x.txt") << "text\n";
  try {
    open_dataset(dir / "x.txt");
    ADD_FAILURE() << "a text file opened as a dataset";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("expected a dataset directory or a ROS1 .bag file"),
              std::string::npos);
  }
}

// The records of a bag file in order (format 2.0: "#ROSBAG V2.0\n", then [header length][header][data
// length][data]), each with its op and where its header and data start.
struct RawRecord {
  std::size_t pos = 0;
  std::uint8_t op = 0;
  std::size_t data_pos = 0;
  std::uint32_t data_bytes = 0;
};

std::uint32_t le32(const std::string& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(b[at + static_cast<std::size_t>(i)]);
  return v;
}

void put_le32(std::string& b, std::size_t at, std::uint32_t v) {
  for (std::size_t i = 0; i < 4; ++i) b[at + i] = static_cast<char>((v >> (8 * i)) & 0xFF);
}

std::vector<RawRecord> raw_records(const std::string& bytes) {
  std::vector<RawRecord> records;
  std::size_t pos = 13;
  while (pos + 4 <= bytes.size()) {
    RawRecord r;
    r.pos = pos;
    const std::uint32_t header = le32(bytes, pos);
    const std::string fields = bytes.substr(pos + 4, header);
    const std::size_t op_at = fields.find(std::string("op=", 3));
    r.op = op_at == std::string::npos ? 0 : static_cast<std::uint8_t>(fields[op_at + 3]);
    r.data_bytes = le32(bytes, pos + 4 + header);
    r.data_pos = pos + 8 + header;
    records.push_back(r);
    pos = r.data_pos + r.data_bytes;
  }
  return records;
}

// Opens `bag` and reads every frame: any outcome but a crash is a pass here; returns the open error (empty
// when it opened).
std::string open_and_read_all(const fs::path& bag) {
  try {
    const auto d = open_dataset(bag, OpenOptions{});
    for (std::size_t f = 0; f < d->frame_count(); ++f) {
      try {
        (void)d->load_image(f);
      } catch (const DataError&) {
      }
    }
  } catch (const DataError& e) {
    return e.what();
  }
  return "";
}

// A corrupt index (an IndexData record, op 0x04) must give an error naming the bag, never a crash in
// librosbag: an entry offset far past its chunk, one pointing inside a message, the record's header length,
// and its entry count; for uncompressed, bz2 and lz4 chunks.
TEST(IoRosbag, CorruptIndexRecordsAreErrorsNotCrashes) {
  LOOPGATE_REQUIRE_ROSBAG();
  for (const std::string compression : {"none", "bz2", "lz4"}) {
    SCOPED_TRACE(compression);
    const fs::path dir = testing::make_temp_dir("rosbag-corrupt-index");
    const fs::path good = write_euroc_bag(dir, 6, compression);
    const std::string bytes = testing::read_file(good);
    std::vector<RawRecord> index;
    for (const RawRecord& r : raw_records(bytes))
      if (r.op == 0x04 && r.data_bytes >= 12) index.push_back(r);
    ASSERT_FALSE(index.empty());
    const RawRecord& r = index.front();
    struct Mutation {
      std::string name;
      std::size_t at;
      std::uint32_t value;
    };
    const std::vector<Mutation> mutations = {
        {"offset 0x80000000", r.data_pos + 8, 0x80000000u},
        {"offset inside a message", r.data_pos + 8, le32(bytes, r.data_pos + 8) + 37},
        {"header length", r.pos, le32(bytes, r.pos) + 0x10000000u},
        {"data length", r.data_pos - 4, 0xFFFFFFF0u},
        {"offset just below the end", r.data_pos + 8, 0x7FFFFFFFu}};
    for (const Mutation& m : mutations) {
      SCOPED_TRACE(m.name);
      std::string bad = bytes;
      put_le32(bad, m.at, m.value);
      const fs::path file = dir / "bad.bag";
      std::ofstream(file, std::ios::binary) << bad;
      const std::string error = open_and_read_all(file);
      EXPECT_NE(error.find(file.string() + ": cannot read it as a ROS1 bag: "), std::string::npos) << error;
    }
  }
}

// Every byte of an index record and of a chunk-info record inverted in turn in turn: opening and
// reading never crashes (an error or a bag read as it is).
TEST(IoRosbag, EveryIndexByteChangedNeverCrashes) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path dir = testing::make_temp_dir("rosbag-index-bytes");
  const fs::path good = write_euroc_bag(dir, 3);
  const std::string bytes = testing::read_file(good);
  const fs::path file = dir / "bad.bag";
  std::size_t tried = 0;
  bool index_seen = false, chunk_info_seen = false;  // the first record of each kind
  for (const RawRecord& r : raw_records(bytes)) {
    if (r.op == 0x04 ? std::exchange(index_seen, true) : r.op != 0x06 || std::exchange(chunk_info_seen, true))
      continue;
    for (std::size_t at = r.pos; at < r.data_pos + r.data_bytes; ++at) {
      {
        std::string bad = bytes;
        bad[at] = static_cast<char>(~static_cast<unsigned char>(bad[at]));
        std::ofstream(file, std::ios::binary | std::ios::trunc) << bad;
        (void)open_and_read_all(file);
        ++tried;
      }
    }
  }
  EXPECT_GT(tried, 100u);
}

// The only test that runs without bag support: a .bag then gets an error that says how to get it.
TEST(IoRosbag, WithoutBagSupportABagSaysHowToEnableIt) {
  if (rosbag_support_built()) GTEST_SKIP() << "this build reads bags (LOOPGATE_WITH_ROSBAG=ON)";
  const fs::path dir = testing::make_temp_dir("rosbag-unsupported");
  std::ofstream(dir / "seq.bag") << "#ROSBAG V2.0\n";
  const std::string error = open_error(dir / "seq.bag", OpenOptions{});
  EXPECT_NE(error.find("built without ROS1 bag support"), std::string::npos) << error;
  EXPECT_NE(error.find("-DLOOPGATE_WITH_ROSBAG=ON"), std::string::npos) << error;
  EXPECT_NE(error.find("scripts/setup.sh"), std::string::npos) << error;
}

}  // namespace
}  // namespace loopgate
