// No silent failures, end to end: a run that went through every frame and got nothing usable (no
// odometry, no image, no detection possible) says so on the console, naming the file and what it expected,
// and exits non-zero, with every output written (they show what happened frame by frame). The real binary on
// KITTI-layout data the test generates.
#include <gtest/gtest.h>

#include <cmath>
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

const std::string kConfig = std::string(LOOPGATE_SOURCE_DIR) + "/configs/kitti00-thumbs.yaml";

// image_0/NNNNNN.png (64 x 32), times.txt (10 Hz from t = 0), poses.txt (a drive along z); `broken`: every
// image file holds text, not a PNG.
fs::path make_kitti(int frames, bool broken = false) {
  const fs::path dir = testing::make_temp_dir("silent-kitti");
  fs::create_directories(dir / "image_0");
  std::ofstream times(dir / "times.txt");
  std::ofstream poses(dir / "poses.txt");
  for (int i = 0; i < frames; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    if (broken) {
      std::ofstream(dir / "image_0" / name) << "not an image";
    } else {
      cv::Mat image(32, 64, CV_8UC1);
      for (int r = 0; r < image.rows; ++r)
        for (int c = 0; c < image.cols; ++c)
          image.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>((r * 9 + c * 5 + i) % 200);
      cv::imwrite((dir / "image_0" / name).string(), image);
    }
    times << 0.1 * i << "\n";
    poses << "1 0 0 " << 0.05 * std::sin(0.1 * i) << " 0 1 0 0 0 0 1 " << 1.0 * i << "\n";
  }
  return dir;
}

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command("timeout 120 " + testing::loopgate_binary().string() + " run --config " +
                                     kConfig + " --set output.progress=off " + args,
                                 &output);
  return output;
}

// Every output is there, whole, one frames.csv row per frame, and summary.json says the run failed and why.
nlohmann::json expect_outputs_written(const fs::path& out, std::size_t frames, const std::string& problem) {
  for (const char* name : {"frames.csv", "timing.csv", "trajectory.tum", "summary.json"})
    EXPECT_TRUE(fs::is_regular_file(out / name)) << name;
  EXPECT_EQ(read_csv(out / "frames.csv").size(), frames);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["failed"].get<bool>());
  EXPECT_NE(summary["error"].get<std::string>().find(problem), std::string::npos) << summary["error"];
  EXPECT_FALSE(summary["problems"].empty());
  return summary;
}

TEST(E2eSilentFailures, ATrajectoryOfAnotherSequenceIsNoOdometry) {
  const fs::path dataset = make_kitti(30);
  const fs::path dir = testing::make_temp_dir("silent-odometry");
  // Another sequence's times: no frame (t = 0 .. 2.9 s) within odometry.file_max_gap_s of them.
  const fs::path elsewhere = dir / "elsewhere.tum";
  std::ofstream(elsewhere) << "900 0 0 0 0 0 0 1\n901 0 0 1 0 0 0 1\n";
  int status = -1;
  std::string output =
      run("--dataset " + dataset.string() + " --out " + (dir / "out").string() +
              " --mode full --set match.margin=4 --set odometry.source=file --set odometry.file=" +
              elsewhere.string(),
          &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(
      output.find("[error] run failed: no odometry: none of the 30 frames got a pose from odometry.source "
                  "file; expected poses in " +
                  elsewhere.string() + " within odometry.file_max_gap_s = 0.5 s of the frame times"),
      std::string::npos)
      << output;
  EXPECT_NE(output.find("poses at t = 900.000 .. 901.000 s, the dataset's 30 frames at t = 0.000 .. 2.900 s"),
            std::string::npos)
      << output;
  const auto summary = expect_outputs_written(dir / "out", 30, "no odometry");
  EXPECT_EQ(read_file(dir / "out" / "trajectory.tum"), "");  // no pose was estimated
  EXPECT_EQ(summary["loops"].get<int>(), 0);

  // A trajectory whose span holds the frames, with no pose near any of them: the same, frame by frame.
  const fs::path sparse = dir / "sparse.tum";
  std::ofstream(sparse) << "-100 0 0 0 0 0 0 1\n100 0 0 1 0 0 0 1\n";
  output = run("--dataset " + dataset.string() + " --out " + (dir / "out2").string() +
                   " --mode full --set match.margin=4 --set odometry.source=file --set odometry.file=" +
                   sparse.string(),
               &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(
      output.find("(first frame: frame 0: odometry lost: trajectory file has no pose within file_max_gap_s "
                  "of the frame)"),
      std::string::npos)
      << output;
  expect_outputs_written(dir / "out2", 30, "no odometry");
}

TEST(E2eSilentFailures, NoReadableImageIsSaid) {
  const fs::path dataset = make_kitti(30, true);
  const fs::path out = testing::make_temp_dir("silent-image");
  int status = -1;
  const std::string output =
      run("--dataset " + dataset.string() + " --out " + out.string() + " --mode full --set match.margin=4",
          &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(
      output.find("[error] run failed: no image: none of the 30 frames whose pixels the run needed could "
                  "be read from " +
                  dataset.string()),
      std::string::npos)
      << output;
  EXPECT_NE(output.find("(first: frame 0: image: " + (dataset / "image_0" / "000000.png").string()),
            std::string::npos)
      << output;
  expect_outputs_written(out, 30, "no image");
  EXPECT_TRUE(fs::is_regular_file(out / "loops.csv"));
}

TEST(E2eSilentFailures, ARunShorterThanTheMarginCannotDetect) {
  const fs::path dataset = make_kitti(30);
  const fs::path out = testing::make_temp_dir("silent-margin");
  int status = -1;
  std::string output =
      run("--dataset " + dataset.string() + " --out " + out.string(), &status);  // margin 200
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("[error] run failed: no detection possible: the run has 30 frames, and run.method "
                        "dird-seqslam compares a frame only with frames at least match.margin = 200 frames "
                        "before it"),
            std::string::npos)
      << output;
  expect_outputs_written(out, 30, "no detection possible");
  // SeqSLAM names its own margin.
  output = run("--dataset " + dataset.string() + " --out " + (out / "seqslam").string() + " --method seqslam",
               &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("at least seqslam.exclusion_margin_frames = 200 frames before it"), std::string::npos)
      << output;
  // Without loop detection, the same frames are a good run.
  output = run("--dataset " + dataset.string() + " --out " + (out / "odometry").string() +
                   " --mode odometry --method dird",
               &status);
  EXPECT_EQ(status, 0) << output;
}

}  // namespace
}  // namespace loopgate
