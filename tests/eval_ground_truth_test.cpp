// Ground-truth loops from positions (radius, gap, plane) and from pairs.
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <limits>
#include <random>
#include <set>
#include <sstream>

#include "core/error.hpp"
#include "eval/ground_truth.hpp"
#include "eval/loop_files.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

// Out along x (frames 0..9 at x = 0..9) and back (frames 10..19 at x = 9..0).
std::vector<Eigen::Vector3d> out_and_back(double y_step = 0.0) {
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < 10; ++i) p.emplace_back(i, y_step * i, 0.0);
  for (int k = 0; k < 10; ++k) p.emplace_back(9 - k, y_step * (10 + k), 0.0);
  return p;
}

TEST(EvalGroundTruth, OutAndBackHandComputed) {
  GroundTruthConfig config;
  config.radius_m = 0.5;
  config.gap_frames = 3;
  const auto gt = LoopGroundTruth::from_positions(out_and_back(), config);
  ASSERT_EQ(gt.frame_count(), 20u);
  // Frame 10 (x = 9) only meets frame 9, closer than the gap; frames 11..19 meet frames 8..0.
  EXPECT_EQ(gt.positive_count(), 9u);
  EXPECT_FALSE(gt.is_positive(10));
  for (std::size_t i = 11; i < 20; ++i) {
    ASSERT_TRUE(gt.is_positive(i)) << i;
    EXPECT_EQ(gt.true_references(i), std::vector<std::size_t>{19 - i}) << i;
  }
  EXPECT_TRUE(gt.is_true_match(15, 4));
  EXPECT_FALSE(gt.is_true_match(15, 5));  // 1 m apart
  EXPECT_TRUE(gt.is_true_match(10, 9));   // within r_accept even if closer than the gap
  EXPECT_EQ(gt.pairs().size(), 9u);
}

TEST(EvalGroundTruth, PlaneChoiceAndAcceptRadius) {
  GroundTruthConfig config;
  config.radius_m = 0.5;
  config.gap_frames = 3;
  // Height grows by 10 m per frame: invisible in the x-z plane... only if it is along y.
  const auto climbing = out_and_back(10.0);
  EXPECT_EQ(LoopGroundTruth::from_positions(climbing, config).positive_count(), 9u);  // "xz" ignores y
  config.plane = CoordinatePlane::kXyz;
  EXPECT_EQ(LoopGroundTruth::from_positions(climbing, config).positive_count(), 0u);
  config.plane = CoordinatePlane::kXy;
  EXPECT_EQ(LoopGroundTruth::from_positions(climbing, config).positive_count(), 0u);
  config.plane = CoordinatePlane::kXz;
  config.accept_radius_m = 1.5;
  const auto gt = LoopGroundTruth::from_positions(out_and_back(), config);
  EXPECT_EQ(gt.positive_count(), 9u);    // positives use r_true
  EXPECT_TRUE(gt.is_true_match(15, 5));  // detections use r_accept
  EXPECT_FALSE(gt.is_true_match(15, 6));
}

TEST(EvalGroundTruth, GridEqualsBruteForce) {
  std::mt19937 rng(5);
  std::normal_distribution<double> step(0.0, 1.0);
  std::vector<Eigen::Vector3d> p{Eigen::Vector3d::Zero()};
  for (int i = 1; i < 1500; ++i) p.push_back(p.back() + Eigen::Vector3d(step(rng), step(rng), step(rng)));
  GroundTruthConfig config;
  config.radius_m = 3.0;
  config.gap_frames = 20;
  config.plane = CoordinatePlane::kXyz;
  const auto gt = LoopGroundTruth::from_positions(p, config);
  std::size_t total = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::vector<std::size_t> expected;
    for (std::size_t j = 0; j + 20 <= i; ++j)
      if ((p[i] - p[j]).norm() <= 3.0) expected.push_back(j);
    ASSERT_EQ(gt.true_references(i), expected) << i;
    total += expected.size();
  }
  EXPECT_GT(total, 100u);  // the walk does revisit places
}

TEST(EvalGroundTruth, FramesWithoutGroundTruthAreSkipped) {
  GroundTruthConfig config;
  config.radius_m = 0.5;
  config.gap_frames = 3;
  auto p = out_and_back();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  p[4] = Eigen::Vector3d(nan, nan, nan);   // partner of frame 15
  p[12] = Eigen::Vector3d(nan, nan, nan);  // a would-be positive
  const auto gt = LoopGroundTruth::from_positions(p, config);
  EXPECT_EQ(gt.positive_count(), 7u);
  EXPECT_FALSE(gt.is_positive(15));
  EXPECT_FALSE(gt.is_positive(12));
  EXPECT_FALSE(gt.is_true_match(15, 4));
  EXPECT_TRUE(gt.is_positive(16));
}

// eval.min_travel_m: hovering is not a loop. Out along x to x = 9 (frames 0..9), hovering there
// with millimetre jitter for 40 frames (10..49), then back to x = 0 (frames 50..59).
TEST(EvalGroundTruth, ARevisitNeedsTravelInBetween) {
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < 10; ++i) p.emplace_back(i, 0.0, 0.0);
  for (int k = 0; k < 40; ++k) p.emplace_back(9.0 + 0.001 * (k % 2), 0.0, 1.0);
  for (int k = 0; k < 10; ++k) p.emplace_back(9 - k, 0.0, 1.0);
  GroundTruthConfig config;
  config.radius_m = 0.5;
  config.gap_frames = 20;
  config.plane = CoordinatePlane::kXy;
  const auto hovering = LoopGroundTruth::from_positions(p, config);
  EXPECT_TRUE(hovering.is_positive(35));  // 20+ frames of hovering within 0.5 m: a "loop" without the rule
  EXPECT_TRUE(hovering.is_true_match(35, 12));
  config.revisit.min_travel_m = 2.0;
  const auto gt = LoopGroundTruth::from_positions(p, config);
  for (std::size_t i = 0; i < 50; ++i) EXPECT_FALSE(gt.is_positive(i)) << i;
  EXPECT_FALSE(gt.is_true_match(35, 12));
  // The same place without travel: not a true loop, and not judged either (neither true nor false).
  EXPECT_TRUE(gt.is_same_place_without_travel(35, 12));
  EXPECT_FALSE(gt.is_same_place_without_travel(35, 3));         // 6 m apart: a plain false match
  EXPECT_FALSE(gt.is_same_place_without_travel(55, 4));         // a true loop
  EXPECT_FALSE(hovering.is_same_place_without_travel(35, 12));  // no travel rule: judged (true)
  // The way back revisits the way out (the hover's 1 m climb does not count in xy): 9 m and more of travel.
  for (std::size_t i = 51; i < 60; ++i) {
    ASSERT_TRUE(gt.is_positive(i)) << i;
    EXPECT_EQ(gt.true_references(i), std::vector<std::size_t>{59 - i}) << i;
  }
  // Frame 50 (x = 9) only meets the hover and frame 9, less than 2 m of path back (1 m up, 1 m down and the
  // jitter): not a loop.
  EXPECT_FALSE(gt.is_positive(50));
  EXPECT_TRUE(gt.is_true_match(55, 4));
  EXPECT_TRUE(gt.is_true_match(4, 55));  // either order
  // A frame without ground truth: the path crosses it in a straight line.
  p[30].setConstant(std::numeric_limits<double>::quiet_NaN());
  EXPECT_EQ(LoopGroundTruth::from_positions(p, config).true_references(55), std::vector<std::size_t>{4});
}

TEST(EvalGroundTruth, FromPairs) {
  const auto gt = LoopGroundTruth::from_pairs(10, {{5, 0}, {5, 1}, {7, 2}, {5, 0}});
  EXPECT_EQ(gt.positive_count(), 2u);
  EXPECT_TRUE(gt.is_true_match(5, 1));
  EXPECT_FALSE(gt.is_true_match(5, 2));
  EXPECT_FALSE(gt.is_true_match(2, 7));  // pairs are directed: (query, reference)
  EXPECT_EQ(gt.true_references(5), (std::vector<std::size_t>{0, 1}));
  EXPECT_THROW(LoopGroundTruth::from_pairs(10, {{10, 0}}), std::out_of_range);
}

std::vector<Eigen::Vector3d> read_positions(const std::filesystem::path& poses) {
  std::ifstream in(poses);
  std::vector<Eigen::Vector3d> p;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    double v[12];
    for (double& x : v) ss >> x;
    p.emplace_back(v[3], v[7], v[11]);
  }
  return p;
}

// KITTI 00 with the authors' parameters (2 m in x-z, gap 20) against their own true-loop list
// (one earlier frame per current frame). Ours has 28 more positives: frames 549..570, where the car
// stands still for over 20 frames (a "loop" with itself a gap later; larger gaps drop them), and the
// last six frames 4535..4540, which the authors' frame range did not include.
TEST(EvalGroundTruth, KittiAgreesWithTheAuthorsTrueLoops) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/poses.txt");
  LOOPGATE_REQUIRE_SHARED_DATA("reference/vio-dird/kitti00_true_loops.csv");
  const auto data = testing::shared_data_dir();
  const auto p = read_positions(data / "kitti/00/poses.txt");
  ASSERT_EQ(p.size(), 4541u);
  const auto gt = LoopGroundTruth::from_positions(p, GroundTruthConfig{});
  const auto theirs = read_vio_dird_true_loops(data / "reference/vio-dird/kitti00_true_loops.csv");
  std::size_t agree_positive = 0, agree_pair = 0;
  for (const auto& [q, r] : theirs) {
    agree_positive += gt.is_positive(q);
    agree_pair += gt.is_true_match(q, r);
  }
  spdlog::info(
      "KITTI 00 GT (2 m x-z, gap 20): {} positive queries, {} pairs; authors: {} queries, {} of them "
      "positive here, {} of their pairs within 2 m",
      gt.positive_count(), gt.pairs().size(), theirs.size(), agree_positive, agree_pair);
  EXPECT_EQ(theirs.size(), 749u);
  EXPECT_EQ(agree_positive, theirs.size());
  EXPECT_EQ(agree_pair, theirs.size());
  EXPECT_EQ(gt.positive_count(), 777u);
  EXPECT_TRUE(gt.is_positive(560));
  EXPECT_TRUE(gt.is_positive(4540));
}

}  // namespace
}  // namespace loopgate
