// Time order of the dataset tables: a single outlier row is the one dropped, judged against the
// rows on both sides of it (the longest run of strictly increasing times is kept), not the good rows after
// it; a file mostly bad fails loudly even in lenient mode; a rejected KITTI row does not renumber the later
// frames; the reference image size is the majority's, not frame 0's.
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

void write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

std::string kitti_name(int i) {
  char name[16];
  std::snprintf(name, sizeof(name), "%06d.png", i);
  return name;
}

// A KITTI sequence of `frames` 32 x 16 images at 10 Hz; times.txt row `bad_row` (if >= 0) gets `bad_time`.
fs::path make_kitti(const std::string& tag, int frames, int bad_row = -1, const std::string& bad_time = "") {
  const fs::path dir = testing::make_temp_dir(tag);
  std::string times;
  for (int i = 0; i < frames; ++i) {
    times += i == bad_row ? bad_time + "\n" : std::to_string(0.1 * i) + "\n";
    fs::create_directories(dir / "image_0");
    cv::imwrite((dir / "image_0" / kitti_name(i)).string(), cv::Mat(16, 32, CV_8UC1, cv::Scalar(i % 250)));
  }
  write_file(dir / "times.txt", times);
  return dir;
}

OpenOptions lenient() {
  OpenOptions options;
  options.strict = false;
  return options;
}

TEST(IoTimeOrder, OneEarlyOutlierIsTheRowDroppedNotTheRowsAfterIt) {
  // The audit's case: a typo of 10^5 s at row 10 of 2000 kept the outlier and dropped the 1 990 rows after
  // it.
  const fs::path dir = make_kitti("time-outlier", 200, 10, "100000.0");
  const auto d = open_kitti(dir, lenient());
  EXPECT_EQ(d->frame_count(), 199u);
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].line, 11u);  // row 10 is line 11
  EXPECT_NE(d->issues()[0].message.find("time 100000.000000000 s is after line 12 (1.100000000 s)"),
            std::string::npos)
      << d->issues()[0].to_string();
  // The frames keep their KITTI numbers: frame 10 is missing, frame index 10 is image 000011.png.
  EXPECT_EQ(d->source_index(9), 9u);
  EXPECT_EQ(d->source_index(10), 11u);
  EXPECT_EQ(d->image_path(10).filename(), "000011.png");
  // Strict: the outlier's line is the error, not the good line after it.
  try {
    open_kitti(dir);
    FAIL() << "no DataError";
  } catch (const DataError& e) {
    EXPECT_EQ(e.line(), 11u) << e.what();
  }
}

TEST(IoTimeOrder, AnOutlierBelowItsNeighboursIsDroppedToo) {
  const fs::path dir = make_kitti("time-low", 50, 30, "0.05");
  const auto d = open_kitti(dir, lenient());
  EXPECT_EQ(d->frame_count(), 49u);
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].line, 31u);
  EXPECT_NE(d->issues()[0].message.find("is before line 30 (2.900000000 s)"), std::string::npos)
      << d->issues()[0].to_string();
}

// A stamp that breaks the series at either end of a table (a leading 0 before times near 10^6 s, a trailing
// typo 10^5 s on) is in order, yet dropped by the rule that drops it in the middle: far from its neighbours.
TEST(IoTimeOrder, AStampThatBreaksTheSeriesAtEitherEndIsDroppedToo) {
  const fs::path dir = make_kitti("time-leading-zero", 40);
  std::string times = "0.0\n";
  for (int i = 1; i < 40; ++i) times += std::to_string(1e6 + 0.1 * i) + "\n";
  write_file(dir / "times.txt", times);
  const auto d = open_kitti(dir, lenient());
  EXPECT_EQ(d->frame_count(), 39u);
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].line, 1u);
  EXPECT_NE(d->issues()[0].message.find("time 0.000000000 s is 1000000.100000000 s from line 2"),
            std::string::npos)
      << d->issues()[0].to_string();
  EXPECT_NE(d->issues()[0].message.find("breaks the series"), std::string::npos);
  EXPECT_EQ(d->frame_t_ns(0), 1'000'000'100'000'000);
  try {
    open_kitti(dir);
    FAIL() << "no DataError";
  } catch (const DataError& e) {
    EXPECT_EQ(e.line(), 1u) << e.what();
  }

  const auto trailing = open_kitti(make_kitti("time-trailing", 50, 49, "100000.0"), lenient());
  EXPECT_EQ(trailing->frame_count(), 49u);
  ASSERT_EQ(trailing->issues().size(), 1u);
  EXPECT_EQ(trailing->issues()[0].line, 50u);

  // A regular series starting at 0 (the simulator's) keeps every row.
  EXPECT_TRUE(open_kitti(make_kitti("time-from-zero", 30), lenient())->issues().empty());
}

TEST(IoTimeOrder, AFileMostlyBadFailsLoudlyEvenWhenLenient) {
  const fs::path dir = make_kitti("time-mostly-bad", 20);
  std::string times;
  for (int i = 0; i < 20; ++i) times += i < 8 ? std::to_string(0.1 * i) + "\n" : "oops\n";
  write_file(dir / "times.txt", times);
  try {
    open_kitti(dir, lenient());
    FAIL() << "no DataError";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("12 of its 20 rows are bad (first: "), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("times.txt:9: "), std::string::npos) << e.what();
  }
}

TEST(IoTimeOrder, EurocCameraAndImuOutliers) {
  const fs::path dir = testing::make_temp_dir("time-euroc");
  const Timestamp t0 = 1'000'000'000'000;
  const Timestamp period = 50'000'000;
  std::string cam = "#timestamp [ns],filename\n";
  std::string imu = "#timestamp [ns],wx,wy,wz,ax,ay,az\n";
  for (int i = 0; i < 40; ++i) {
    const Timestamp t = i == 5 ? t0 + 100'000 * period : t0 + i * period;  // row 5: an outlier
    cam += std::to_string(t) + "," + std::to_string(t0 + i * period) + ".png\n";
  }
  for (int k = 0; k < 400; ++k) {
    const Timestamp t = k == 7 ? t0 + 1'000'000 * period : t0 + k * period / 10;
    imu += std::to_string(t) + ",0,0,0,0,0,9.8\n";
  }
  write_file(dir / "mav0/cam0/data.csv", cam);
  write_file(dir / "mav0/imu0/data.csv", imu);
  const auto d = open_euroc(dir, lenient());
  EXPECT_EQ(d->frame_count(), 39u);
  EXPECT_EQ(d->source_index(5), 6u);  // the frame's number is its data row: a gap, not a shift
  EXPECT_EQ(d->imu_samples().size(), 399u);
  // Every frame interval gets its IMU samples (an outlier kept in file order used to cut them all off).
  EXPECT_EQ(d->imu_between(t0 + 20 * period, t0 + 21 * period).size(), 10u);
  ASSERT_EQ(d->issues().size(), 2u);
  EXPECT_EQ(d->issues()[0].file.filename(), "data.csv");
  EXPECT_EQ(d->issues()[0].line, 7u);
  EXPECT_NE(d->issues()[0].message.find("camera timestamp"), std::string::npos);
  EXPECT_EQ(d->issues()[1].line, 9u);
  EXPECT_NE(d->issues()[1].message.find("IMU timestamp"), std::string::npos);
}

TEST(IoTimeOrder, ImageSizeIsTheMajoritysNotFrameZeros) {
  const fs::path dir = make_kitti("size-majority", 20);
  cv::imwrite((dir / "image_0" / kitti_name(0)).string(), cv::Mat(10, 20, CV_8UC1, cv::Scalar(3)));
  const auto d = open_kitti(dir);
  EXPECT_EQ(d->load_image(5).cols, 32);  // every other frame loads
  try {
    d->load_image(0);
    FAIL() << "no DataError";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 0: image is 20x10, expected 32x16 like most frames"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace loopgate
