// End-to-end tests of `loopgate run --mode full` and of the two-sequence mode (--reference/--query): the
// real binary on generated KITTI-layout sequences that revisit their places.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

using testing::read_csv;
using testing::read_file;

// KITTI layout, `laps` x `period` frames at 10 Hz around a circle of radius 30 m in the x-z plane: frame k
// shows place k % period (a smooth random texture seeded by the place) plus per-frame noise (`noise_seed`).
fs::path make_revisit_dataset(int period, int laps, int noise_seed) {
  const fs::path dir = testing::make_temp_dir("e2e-full-kitti");
  fs::create_directories(dir / "image_0");
  std::ofstream times(dir / "times.txt");
  std::ofstream poses(dir / "poses.txt");
  for (int k = 0; k < period * laps; ++k) {
    const int place = k % period;
    cv::Mat small(8, 16, CV_8UC1);
    cv::RNG place_rng(0x9e3779b9u + static_cast<std::uint64_t>(place));
    place_rng.fill(small, cv::RNG::UNIFORM, 0, 256);
    cv::Mat image;
    cv::resize(small, image, cv::Size(64, 32), 0, 0, cv::INTER_LINEAR);
    cv::Mat noise(image.size(), CV_16SC1);
    cv::RNG noise_rng(static_cast<std::uint64_t>(7919 * k + 104729 * noise_seed + 1));
    noise_rng.fill(noise, cv::RNG::UNIFORM, -6, 7);
    cv::Mat noisy;
    image.convertTo(noisy, CV_16SC1);
    noisy += noise;
    noisy.convertTo(image, CV_8UC1);
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", k);
    cv::imwrite((dir / "image_0" / name).string(), image);
    const double theta = 2.0 * M_PI * place / period;
    times << std::scientific << 0.1 * k << "\n";
    poses << "1 0 0 " << 30 * std::sin(theta) << " 0 1 0 0 0 0 1 " << 30 * (1 - std::cos(theta)) << "\n";
  }
  return dir;
}

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " " + args, &output);
  return output;
}

constexpr int kPeriod = 100;
const std::string kMatchSettings =
    " --set match.margin=30 --set match.sequence_length=10 --set match.nms_half_window=20"
    " --set odometry.heading_axis=y";

TEST(E2eFullMode, GeneratedRevisitsGiveLoopsAndEveryFrameOneStatus) {
  const fs::path dataset = make_revisit_dataset(kPeriod, 3, 0);
  const fs::path out = testing::make_temp_dir("e2e-full-out");
  int status = -1;
  const std::string output = run("run --mode full --dataset " + dataset.string() + " --out " + out.string() +
                                     kMatchSettings + " --threads 2 --set output.progress=off",
                                 &status);
  ASSERT_EQ(status, 0) << output;
  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  ASSERT_EQ(rows.size(), 3u * kPeriod) << output;
  ASSERT_EQ(header.back(), "detection_reason");
  const std::size_t detection = header.size() - 4;
  ASSERT_EQ(header[detection], "detection");
  std::size_t loop_frames = 0;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    ASSERT_EQ(rows[k].size(), header.size());
    EXPECT_EQ(rows[k][1], std::to_string(k));
    EXPECT_EQ(rows[k][header.size() - 5], "y");  // descriptor computed
    const std::string& d = rows[k][detection];
    EXPECT_TRUE(d == "no candidate" || d == "below threshold" || d == "suppressed" || d == "loop") << d;
    if (d == "loop") ++loop_frames;
  }
  const auto loops = read_csv(out / "loops.csv");
  ASSERT_GT(loops.size(), 0u);
  EXPECT_GE(loop_frames, static_cast<std::size_t>(kPeriod));  // most of laps 2 and 3
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["loops"].get<std::size_t>(), loops.size());
  EXPECT_EQ(summary["descriptors_computed"].get<std::size_t>(), 3u * kPeriod);
  // Ground truth is in the dataset: every detection lies on a revisit (within the default accept radius,
  // r_true = 2 m).
  EXPECT_EQ(summary["evaluation"]["loop_truth"]["loops_true"].get<std::size_t>(), loops.size());
  EXPECT_EQ(summary["config"]["run"]["mode"].get<std::string>(), "full");
}

TEST(E2eFullMode, UnknownModeNamesTheModes) {
  const fs::path dataset = make_revisit_dataset(10, 1, 0);
  const fs::path out = testing::make_temp_dir("e2e-full-bad-mode");
  int status = -1;
  const std::string output =
      run("run --mode bogus --dataset " + dataset.string() + " --out " + out.string(), &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(output.find("run.mode"), std::string::npos) << output;
  EXPECT_NE(output.find("gated|full|odometry"), std::string::npos) << output;
}

TEST(E2eFullMode, TwoSequencesReferenceAndQuery) {
  const fs::path reference = make_revisit_dataset(kPeriod, 1, 1);
  const fs::path query = make_revisit_dataset(kPeriod, 1, 2);
  const fs::path out = testing::make_temp_dir("e2e-two-seq-out");
  int status = -1;
  const std::string output =
      run("run --reference " + reference.string() + " --query " + query.string() + " --out " + out.string() +
              kMatchSettings + " --set eval.aligned_tolerance_frames=1",
          &status);
  ASSERT_EQ(status, 0) << output;
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), static_cast<std::size_t>(kPeriod));
  const auto loops = read_csv(out / "loops.csv");
  ASSERT_GT(loops.size(), 0u);
  for (const auto& row : loops) EXPECT_LE(std::abs(std::stol(row[0]) - std::stol(row[1])), 1);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["mode"].get<std::string>(), "two-sequence");
  EXPECT_GE(summary["aligned"]["best_match_within_tolerance"].get<std::size_t>(), kPeriod * 8u / 10u);
}

// The "must show": KITTI 00 thumbnails, drift odometry, calibrated l2 constants (the config):
// full mode finds the revisits. Measured at the time of writing: 12231 detections, 3056 within 10 m of
// ground truth; 1632 query frames with a detection, the best-scoring one within 10 m for 707; above DP
// 8, 2886 of 2903 detections are within 10 m.
TEST(E2eFullMode, KittiThumbsFindsTheRevisits) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/thumbs");
  const fs::path out = testing::make_temp_dir("e2e-full-kitti00");
  int status = -1;
  const std::string output = run("run --config " + std::string(LOOPGATE_SOURCE_DIR) +
                                     "/configs/kitti00-thumbs.yaml --method dird --mode full --dataset " +
                                     (testing::shared_data_dir() / "kitti/00/thumbs").string() + " --out " +
                                     out.string() + " --set output.progress=off",
                                 &status);
  ASSERT_EQ(status, 0) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["descriptors_computed"].get<std::size_t>(), 4540u);
  EXPECT_EQ(summary["similarities_computed"].get<std::size_t>(), 4340u * 4341u / 2u);  // i - j >= 200
  const auto& truth = summary["evaluation"]["loop_truth"];
  EXPECT_GE(truth["loops_true"].get<std::size_t>(), 2500u);
  EXPECT_GE(truth["query_best_loop_true"].get<std::size_t>(), 600u);
  // Confident detections are nearly all true.
  std::size_t confident = 0, confident_within = 0;
  const auto loops = read_csv(out / "loops.csv");
  std::ifstream poses(testing::shared_data_dir() / "kitti/00/thumbs/poses.txt");
  std::vector<std::array<double, 3>> positions;
  std::array<double, 12> p{};
  while (poses >> p[0] >> p[1] >> p[2] >> p[3] >> p[4] >> p[5] >> p[6] >> p[7] >> p[8] >> p[9] >> p[10] >>
         p[11])
    positions.push_back({p[3], p[7], p[11]});
  ASSERT_EQ(positions.size(), 4540u);
  for (const auto& row : loops) {
    if (std::stod(row[4]) <= 8.0) continue;
    ++confident;
    const auto& a = positions.at(std::stoul(row[0]));
    const auto& b = positions.at(std::stoul(row[1]));
    if (std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]) <= 10.0) ++confident_within;
  }
  EXPECT_GE(confident, 2000u);
  EXPECT_GE(static_cast<double>(confident_within), 0.98 * static_cast<double>(confident));
}

}  // namespace
}  // namespace loopgate
