// The common Dataset interface: layout detection, errors for missing input, DataIssue text,
// concurrent image loading.
#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <thread>

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

TEST(IoDataset, DetectsLayouts) {
  const fs::path root = testing::make_temp_dir("io-detect");
  // EuRoC: mav0/cam0/data.csv.
  write_euroc_camera_csv(root / "euroc/mav0/cam0/data.csv", {{100, "100.png"}, {200, "200.png"}});
  EXPECT_EQ(open_dataset(root / "euroc")->layout(), DatasetLayout::kEuroc);
  EXPECT_EQ(open_dataset(root / "euroc/mav0")->layout(), DatasetLayout::kEuroc);
  // KITTI: image_0/ + times.txt.
  write_kitti_times(root / "kitti/times.txt", {0, 100000000});
  fs::create_directories(root / "kitti/image_0");
  cv::imwrite((root / "kitti/image_0/000000.png").string(), cv::Mat(4, 4, CV_8UC1, cv::Scalar(1.0)));
  EXPECT_EQ(open_dataset(root / "kitti")->layout(), DatasetLayout::kKitti);
  // Folder: images (a times.txt next to images still means a folder).
  fs::create_directories(root / "folder");
  cv::imwrite((root / "folder/x.png").string(), cv::Mat(4, 4, CV_8UC1, cv::Scalar(1.0)));
  EXPECT_EQ(open_dataset(root / "folder")->layout(), DatasetLayout::kFolder);
  write_file(root / "folder/times.txt", "0.5\n");
  const auto folder = open_dataset(root / "folder");
  EXPECT_EQ(folder->layout(), DatasetLayout::kFolder);
  EXPECT_EQ(folder->frame_t_ns(0), 500'000'000);
}

TEST(IoDataset, MissingInputNamesThePath) {
  const fs::path root = testing::make_temp_dir("io-missing");
  try {
    open_dataset(root / "nope");
    FAIL();
  } catch (const DataError& e) {
    EXPECT_EQ(e.file(), root / "nope");
    EXPECT_NE(e.message().find("not found"), std::string::npos);
  }
  write_file(root / "file.txt", "x");
  EXPECT_THROW(open_dataset(root / "file.txt"), DataError);
  fs::create_directories(root / "empty");
  try {
    open_dataset(root / "empty");
    FAIL();
  } catch (const DataError& e) {
    EXPECT_NE(e.message().find("no dataset found"), std::string::npos) << e.what();
  }
  // A directory where a file is expected.
  fs::create_directories(root / "odd/mav0/cam0/data.csv");
  try {
    open_dataset(root / "odd");
    FAIL();
  } catch (const DataError& e) {
    EXPECT_EQ(e.file(), root / "odd/mav0/cam0/data.csv");
    EXPECT_NE(e.message().find("found a directory"), std::string::npos);
  }
}

TEST(IoDataset, NoFramesIsAnError) {
  const fs::path root = testing::make_temp_dir("io-noframes");
  write_file(root / "euroc/mav0/cam0/data.csv", "#timestamp [ns],filename\n");
  EXPECT_THROW(open_dataset(root / "euroc"), DataError);
  write_file(root / "kitti/times.txt", "# nothing\n");
  EXPECT_THROW(open_dataset(root / "kitti"), DataError);
  OpenOptions lenient;
  lenient.strict = false;
  write_file(root / "kitti2/times.txt", "abc\n");
  try {
    open_dataset(root / "kitti2", lenient);
    FAIL();
  } catch (const DataError& e) {
    // Its only row is bad: more than half of the file, before "no usable frames".
    EXPECT_NE(e.message().find("1 of its 1 rows are bad"), std::string::npos) << e.what();
  }
}

TEST(IoDataset, IssueText) {
  EXPECT_EQ((DataIssue{"a/b.csv", 12, "bad"}).to_string(), "a/b.csv:12: bad");
  EXPECT_EQ((DataIssue{"a/b.csv", 0, "bad"}).to_string(), "a/b.csv: bad");
}

TEST(IoDataset, OutOfRangeFrame) {
  const fs::path root = testing::make_temp_dir("io-range");
  cv::imwrite((root / "x.png").string(), cv::Mat(4, 4, CV_8UC1, cv::Scalar(1.0)));
  const auto d = open_dataset(root);
  EXPECT_THROW(d->frame_t_ns(1), std::out_of_range);
  EXPECT_THROW(d->load_image(1), std::out_of_range);
  EXPECT_THROW(d->ground_truth_T_w_b(1), std::out_of_range);
}

TEST(IoDataset, ConcurrentLoadsAgree) {
  const fs::path root = testing::make_temp_dir("io-threads");
  constexpr int kImages = 24;
  for (int i = 0; i < kImages; ++i) {
    cv::Mat image(30, 40, CV_8UC1);
    cv::randu(image, 0, 255);
    image.at<unsigned char>(0, 0) = static_cast<unsigned char>(i);
    cv::imwrite((root / std::string("f").append(std::to_string(i)).append(".png")).string(), image);
  }
  const auto d = open_dataset(root);
  std::atomic<int> wrong{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int k = 0; k < kImages; ++k) {
        const int i = (k + t * 7) % kImages;
        if (d->load_image(static_cast<std::size_t>(i)).at<unsigned char>(0, 0) != i) ++wrong;
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(wrong.load(), 0);
}

}  // namespace
}  // namespace loopgate
