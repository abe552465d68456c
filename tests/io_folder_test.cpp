// Image-folder reader: natural order, optional times.txt, colour to grey, damaged files, Nordland.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

void write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

cv::Mat grey(int value, int width = 20, int height = 10) {
  return cv::Mat(height, width, CV_8UC1, cv::Scalar(static_cast<double>(value)));
}

using testing::catch_data_error;

TEST(IoFolder, NaturalOrderMixedFormatsAndRate) {
  const fs::path dir = testing::make_temp_dir("io-folder");
  cv::imwrite((dir / "img10.png").string(), grey(10));
  cv::imwrite((dir / "img2.pgm").string(), grey(2));
  cv::imwrite((dir / "img1.png").string(), grey(1));
  cv::imwrite((dir / "img3.jpg").string(), grey(3));  // lossy, but a flat image survives
  write_file(dir / "notes.txt", "not an image");
  fs::create_directories(dir / "sub.png");  // a directory, not a file
  OpenOptions options;
  options.folder_rate_hz = 4.0;
  const auto d = open_dataset(dir, options);
  EXPECT_EQ(d->layout(), DatasetLayout::kFolder);
  ASSERT_EQ(d->frame_count(), 4u);
  const std::vector<std::string> names = {"img1.png", "img2.pgm", "img3.jpg", "img10.png"};
  const std::vector<int> values = {1, 2, 3, 10};
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(d->image_path(i).filename().string(), names[i]);
    EXPECT_EQ(d->frame_t_ns(i), static_cast<Timestamp>(i) * 250'000'000);
    const cv::Mat image = d->load_image(i);
    ASSERT_EQ(image.type(), CV_8UC1);
    EXPECT_NEAR(cv::mean(image)[0], values[i], 0.5);
  }
  EXPECT_FALSE(d->has_imu());
  EXPECT_FALSE(d->has_ground_truth());
  EXPECT_FALSE(d->camera());
  EXPECT_FALSE(d->ground_truth_T_w_b(1));
  options.folder_rate_hz = 0;
  EXPECT_THROW(open_image_folder(dir, options), ConfigError);
}

TEST(IoFolder, TimesFileAndColour) {
  const fs::path dir = testing::make_temp_dir("io-folder-times");
  for (int i = 0; i < 3; ++i) {
    cv::Mat colour(10, 20, CV_8UC3, cv::Scalar(30.0 * i, 60.0, 90.0));  // B, G, R
    cv::imwrite((dir / std::string("f").append(std::to_string(i)).append(".png")).string(), colour);
  }
  write_file(dir / "times.txt", "10.5\n10.75\n11.0\n");
  const auto d = open_dataset(dir);
  EXPECT_EQ(d->layout(), DatasetLayout::kFolder);
  ASSERT_EQ(d->frame_count(), 3u);
  EXPECT_EQ(d->frame_t_ns(0), 10'500'000'000);
  EXPECT_EQ(d->frame_t_ns(2), 11'000'000'000);
  const cv::Mat image = d->load_image(1);
  ASSERT_EQ(image.type(), CV_8UC1);
  EXPECT_NEAR(image.at<unsigned char>(0, 0), 0.114 * 30 + 0.587 * 60 + 0.299 * 90, 1.0);

  write_file(dir / "times.txt", "10.5\n10.5\n11.0\n");
  const DataError e1 = catch_data_error([&] { open_dataset(dir); });
  EXPECT_EQ(e1.line(), 2u);
  EXPECT_NE(e1.message().find("duplicate time"), std::string::npos);
  write_file(dir / "times.txt", "10.5\n10.75\n");
  const DataError e2 = catch_data_error([&] { open_dataset(dir); });
  EXPECT_NE(e2.message().find("2 rows, expected one per image (3 images)"), std::string::npos) << e2.what();
  OpenOptions lenient;
  lenient.strict = false;
  EXPECT_EQ(open_dataset(dir, lenient)->frame_count(), 2u);
}

// Images named by 19-digit nanosecond times (EuRoC's and TUM-VI's cam0/data/ as a plain folder): the names
// are the frame times; a name that is not one among them names the file (strict) or is skipped (lenient).
TEST(IoFolder, NanosecondFileNamesAreTheFrameTimes) {
  const fs::path dir = testing::make_temp_dir("io-folder-ns");
  const std::vector<Timestamp> times = {1403636579763555584, 1403636579813555456, 1403636579863555584,
                                        1403636579913555456};
  for (std::size_t i = 0; i < times.size(); ++i) {
    cv::imwrite((dir / (std::to_string(times[i]) + ".png")).string(), grey(static_cast<int>(10 * i)));
  }
  OpenOptions options;
  options.folder_rate_hz = 4.0;  // not used: the names give the times
  const auto d = open_dataset(dir, options);
  EXPECT_EQ(d->layout(), DatasetLayout::kFolder);
  ASSERT_EQ(d->frame_count(), times.size());
  for (std::size_t i = 0; i < times.size(); ++i) {
    EXPECT_EQ(d->frame_t_ns(i), times[i]);
    EXPECT_EQ(d->source_index(i), i);
  }
  EXPECT_NEAR(cv::mean(d->load_image(2))[0], 20, 0.5);

  // One image named otherwise among them: strict names it; lenient skips it, the others keep their number.
  cv::imwrite((dir / "1403636579888888888_copy.png").string(), grey(99));
  const DataError e = catch_data_error([&] { open_image_folder(dir); });
  EXPECT_EQ(e.file(), dir / "1403636579888888888_copy.png");
  EXPECT_NE(
      e.message().find("image name is not a 19-digit nanosecond time like the other 4 of 5 images (e.g. "
                       "1403636579763555584.png)"),
      std::string::npos)
      << e.what();
  OpenOptions lenient;
  lenient.strict = false;
  const auto skipped = open_image_folder(dir, lenient);
  ASSERT_EQ(skipped->frame_count(), times.size());
  EXPECT_EQ(skipped->frame_t_ns(3), times[3]);
  EXPECT_EQ(skipped->source_index(3), 4u);  // the odd file was number 3 in the folder
  ASSERT_EQ(skipped->issues().size(), 1u);
  EXPECT_EQ(skipped->issues()[0].file.filename(), "1403636579888888888_copy.png");
  fs::remove(dir / "1403636579888888888_copy.png");

  // The same time twice (png and jpg): the second is the problem.
  cv::imwrite((dir / (std::to_string(times[1]) + ".jpg")).string(), grey(5));
  const DataError twice = catch_data_error([&] { open_image_folder(dir); });
  EXPECT_EQ(twice.file().filename(), std::to_string(times[1]) + ".png");
  EXPECT_NE(
      twice.message().find("second image for time 1403636579813555456 ns besides 1403636579813555456.jpg"),
      std::string::npos)
      << twice.what();
  fs::remove(dir / (std::to_string(times[1]) + ".jpg"));

  // Names of 19 digits beyond int64, or mostly other names: frames at folder_rate_hz as before.
  cv::imwrite((dir / "a.png").string(), grey(1));
  cv::imwrite((dir / "b.png").string(), grey(2));
  cv::imwrite((dir / "c.png").string(), grey(3));
  cv::imwrite((dir / "9999999999999999999.png").string(), grey(4));
  const auto rate = open_image_folder(dir, options);
  ASSERT_EQ(rate->frame_count(), 8u);
  EXPECT_EQ(rate->frame_t_ns(1), 250'000'000);

  // 19 digits with leading zeros are zero-padded frame numbers, not times (they timed the frames 1 ns apart,
  // a real-time factor of 0.00): frames at folder_rate_hz.
  const fs::path padded = testing::make_temp_dir("folder-padded");
  for (int i = 1; i <= 4; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%019d.png", i);
    cv::imwrite((padded / name).string(), grey(i));
  }
  const auto numbered = open_image_folder(padded, options);
  ASSERT_EQ(numbered->frame_count(), 4u);
  EXPECT_EQ(numbered->frame_t_ns(1) - numbered->frame_t_ns(0), 250'000'000);
  EXPECT_TRUE(numbered->issues().empty());
}

TEST(IoFolder, DamagedImagesAndEmptyFolder) {
  const fs::path dir = testing::make_temp_dir("io-folder-bad");
  EXPECT_THROW(open_image_folder(dir), DataError);  // no images
  write_file(dir / "a0.png", "garbage");            // the first file does not decode: size comes from a1
  cv::imwrite((dir / "a1.png").string(), grey(5));
  cv::imwrite((dir / "a2.png").string(), grey(5, 21, 10));
  cv::imwrite((dir / "a3.png").string(), grey(7));
  cv::Mat deep(10, 20, CV_16UC1, cv::Scalar(1000.0));
  cv::imwrite((dir / "a4.png").string(), deep);
  const auto d = open_image_folder(dir);
  ASSERT_EQ(d->frame_count(), 5u);
  EXPECT_NE(catch_data_error([&] { d->load_image(0); }).message().find("frame 0: cannot decode image"),
            std::string::npos);
  EXPECT_NE(
      catch_data_error([&] { d->load_image(2); })
          .message()
          .find("image is 21x10, expected 20x10 like most frames (3 of 4 probed, e.g. frame 1 (a1.png))"),
      std::string::npos);
  EXPECT_EQ(d->load_image(4).at<unsigned char>(0, 0), 4);  // 16-bit: 1000 / 257, rounded (to_8bit_samples)
  EXPECT_EQ(d->load_image(3).at<unsigned char>(0, 0), 7);
  fs::remove(dir / "a3.png");
  EXPECT_NE(catch_data_error([&] { d->load_image(3); }).message().find("frame 3: image file missing"),
            std::string::npos);
}

TEST(IoFolder, RealNordland) {
  LOOPGATE_REQUIRE_SHARED_DATA("nordland-64x32/summer");
  const auto d = open_dataset(testing::shared_data_dir() / "nordland-64x32/summer");
  EXPECT_EQ(d->layout(), DatasetLayout::kFolder);
  ASSERT_EQ(d->frame_count(), 3576u);
  EXPECT_EQ(d->image_path(0).filename().string(), "images-00010.png");
  EXPECT_EQ(d->image_path(3575).filename().string(), "images-35760.png");
  EXPECT_EQ(d->frame_t_ns(10), 10'000'000'000);  // default 1 Hz
  for (const std::size_t i : {0u, 1000u, 3575u}) {
    const cv::Mat image = d->load_image(i);
    ASSERT_EQ(image.type(), CV_8UC1);
    EXPECT_EQ(image.cols, 64);
    EXPECT_EQ(image.rows, 32);
    // The files are RGB with equal channels: grey equals any channel exactly.
    const cv::Mat colour = cv::imread(d->image_path(i).string(), cv::IMREAD_COLOR);
    cv::Mat channels[3];
    cv::split(colour, channels);
    EXPECT_EQ(cv::norm(image, channels[1], cv::NORM_INF), 0.0);
  }
}

}  // namespace
}  // namespace loopgate
