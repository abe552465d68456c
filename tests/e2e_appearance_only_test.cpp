// Appearance-only runs: an image folder with no poses at all runs loop detection on every frame
// (odometry.source none, or auto finding no odometry), evaluated against published (query, reference) pairs;
// the pose gate needs poses, so gated mode is a clear error, and compare runs the full methods only. The real
// binary on a folder the test generates, and on RTAB-Map's real indoor loop (../shared/data/rtabmap-samples,
// skipped when absent).
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

using testing::read_csv;
using testing::read_file;

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(
      "timeout 300 " + testing::loopgate_binary().string() + " --log-level warn " + args, &output);
  return output;
}

// img0.png .. img79.png (96 x 48): a route of 50 places, then places 0..29 again (frames 50..79 revisit
// 0..29); and gt.csv, the pairs (50 + k, k).
fs::path make_folder(const fs::path& root) {
  const fs::path dir = root / "images";
  fs::create_directories(dir);
  const auto place = [](int p) {
    cv::Mat image(48, 96, CV_8UC1);
    std::uint32_t state = 2654435761u * static_cast<std::uint32_t>(p + 1);
    for (int r = 0; r < image.rows; r += 4) {
      for (int c = 0; c < image.cols; c += 4) {
        state = state * 1664525u + 1013904223u;
        image(cv::Rect(c, r, 4, 4)).setTo(static_cast<int>(state >> 24));
      }
    }
    return image;
  };
  for (int i = 0; i < 80; ++i)
    cv::imwrite((dir / ("img" + std::to_string(i) + ".png")).string(), place(i < 50 ? i : i - 50));
  std::ofstream pairs(root / "gt.csv");
  pairs << "query,reference\n";
  for (int k = 0; k < 30; ++k) pairs << 50 + k << "," << k << "\n";
  return dir;
}

TEST(E2eAppearanceOnly, FullRunsWithoutAnyPose) {
  const fs::path root = testing::make_temp_dir("appearance-only");
  const fs::path images = make_folder(root);
  const std::string base =
      "run --dataset " + images.string() + " --set output.progress=off " +
      "--set match.margin=20 --set match.sequence_length=5 --set standardize.warm_up=10 " +
      "--set seqslam.exclusion_margin_frames=20 --set seqslam.sequence_length_frames=6 " +
      "--set eval.truth_pairs_file=" + (root / "gt.csv").string();
  for (const char* method : {"dird-seqslam", "seqslam", "dird"}) {
    SCOPED_TRACE(method);
    for (const char* source : {"none", "auto"}) {  // auto finds no odometry in a folder: none
      SCOPED_TRACE(source);
      const fs::path out = root / (std::string(method) + "-" + source);
      int status = -1;
      const std::string output = run(base + " --mode full --method " + method +
                                         " --set odometry.source=" + source + " --out " + out.string(),
                                     &status);
      ASSERT_EQ(status, 0) << output;
      std::vector<std::string> header;
      const auto rows = read_csv(out / "frames.csv", &header);
      ASSERT_EQ(rows.size(), 80u);
      const std::size_t odom = testing::column_index(header, "odom_status");
      for (const auto& row : rows) EXPECT_EQ(row[odom], "none");
      EXPECT_EQ(read_file(out / "trajectory.tum"), "");
      const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
      EXPECT_FALSE(summary["failed"].get<bool>());
      EXPECT_EQ(summary["descriptors_computed"].get<int>(), 80);
      const auto& evaluation = summary["evaluation"];
      ASSERT_TRUE(evaluation["available"].get<bool>());
      EXPECT_EQ(evaluation["truth"]["positives"], 30);
      if (std::string(method) == "dird-seqslam") {  // the revisit's pixels are the same: found
        EXPECT_GE(evaluation["loop_truth"]["loops_true"].get<int>(), 20) << evaluation["loop_truth"];
        EXPECT_GT(evaluation["precision_recall"]["average_precision"].get<double>(), 0.8);
      }
    }
  }
  // The pose gate needs poses: refused before anything is written, saying what to use.
  int status = -1;
  std::string output =
      run(base + " --mode gated --set odometry.source=none --out " + (root / "gated").string(), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("run.mode: 'gated' needs poses for the pose gate, and odometry.source is none"),
            std::string::npos)
      << output;
  output = run(base + " --mode gated --out " + (root / "gated-auto").string(), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("odometry.source auto found no odometry for dataset " + images.string()),
            std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(root / "gated-auto" / "frames.csv"));

  // compare: the full methods only (the gated ones need the gate), the pairs named in its header.
  output = run("compare --dataset " + images.string() + " --no-plots --out " + (root / "compare").string() +
                   " --set run.mode=full --set match.margin=20 --set match.sequence_length=5 "
                   "--set seqslam.exclusion_margin_frames=20 --set eval.truth_pairs_file=" +
                   (root / "gt.csv").string(),
               &status);
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find("ground-truth loops: the 30 pairs of " + (root / "gt.csv").string()),
            std::string::npos)
      << output;
  const auto compare = nlohmann::json::parse(read_file(root / "compare" / "compare.json"));
  EXPECT_EQ(compare["methods"], nlohmann::json({"full", "seqslam", "std-full", "dird-seqslam"}));
}

// RTAB-Map's real indoor loop with its published pairs, with the shipped configs/rtabmap-samples.yaml:
// dird-seqslam finds the revisit (measured: AP 0.955, recall 0.955 at 100% precision).
TEST(E2eAppearanceOnly, RtabmapSamplesWithItsPublishedPairs) {
  LOOPGATE_REQUIRE_SHARED_DATA("rtabmap-samples/loop_gt.csv");
  const fs::path data = testing::shared_data_dir() / "rtabmap-samples";
  const fs::path out = testing::make_temp_dir("appearance-rtabmap");
  int status = -1;
  const std::string output =
      run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/rtabmap-samples.yaml --dataset " +
              (data / "images").string() + " --set eval.truth_pairs_file=" + (data / "loop_gt.csv").string() +
              " --set output.progress=off --out " + out.string(),
          &status);
  ASSERT_EQ(status, 0) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  const auto& evaluation = summary["evaluation"];
  EXPECT_EQ(evaluation["truth"]["pairs"], 228);
  EXPECT_EQ(evaluation["truth"]["positives"], 44);
  EXPECT_GT(evaluation["precision_recall"]["average_precision"].get<double>(), 0.9);
  EXPECT_GT(evaluation["precision_recall"]["recall_at_100"].get<double>(), 0.9);
}

}  // namespace
}  // namespace loopgate
