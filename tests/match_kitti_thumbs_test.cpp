// Full mode on the KITTI 00 thumbnails: every frame against every earlier frame beyond the margin, l2
// normalisation with the logistic constants `loopgate calibrate --normalization l2` derives there
// (mu 48477.5, sigma 1796.78), then the streaming DP + NMS with the KITTI reference values.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

struct Position {
  double x = 0, y = 0, z = 0;
};

std::vector<Position> read_positions(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::vector<Position> positions;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    double v[12];
    for (double& value : v) row >> value;
    if (!row) break;
    positions.push_back({v[3], v[7], v[11]});
  }
  return positions;
}

TEST(MatchKittiThumbs, FullModeFindsRevisits) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/thumbs/poses.txt");
  const auto dir = testing::shared_data_dir() / "kitti/00/thumbs";
  const std::vector<Position> positions = read_positions(dir / "poses.txt");
  ASSERT_EQ(positions.size(), 4540u);

  DirdConfig dird;
  dird.normalization = DirdNormalization::kL2;
  dird.mu = 48477.5;
  dird.sigma = 1796.7769;
  const DirdExtractor extractor(dird);
  const DirdSimilarity similarity(dird);
  std::vector<Descriptor> descriptors;
  for (std::size_t f = 0; f < positions.size(); ++f) {
    char name[48];
    std::snprintf(name, sizeof name, "image_0/%06zu.png", f);
    const cv::Mat image = cv::imread((dir / name).string(), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty()) << name;
    descriptors.push_back(extractor.extract(image));
  }

  const MatchConfig config;  // margin 200, L 20, tau3 0.05, steps 0..3, W 59
  SequenceMatcher matcher(config);
  MatchOutput out;
  std::vector<std::vector<SimilarityEntry>> column(1);
  std::size_t stored = 0;
  for (std::size_t i = 0; i < descriptors.size(); ++i) {
    similarity.sparse_columns(descriptors, config.margin, i, i + 1, column);
    stored += column[0].size();
    matcher.push(static_cast<std::int64_t>(i), column[0], out);
    ASSERT_LE(matcher.pending_frames(), 119u);
  }
  matcher.flush(out);
  ASSERT_EQ(out.frames.size(), descriptors.size());

  std::size_t within_10m = 0;
  for (const LoopClosure& loop : out.loops) {
    const Position& a = positions[static_cast<std::size_t>(loop.i)];
    const Position& b = positions[static_cast<std::size_t>(loop.j)];
    const double gap_m =
        std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) + (a.z - b.z) * (a.z - b.z));
    within_10m += gap_m < 10.0;
  }
  for (double threshold : {1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0}) {
    std::size_t n = 0, good = 0;
    for (const LoopClosure& loop : out.loops) {
      if (loop.score <= threshold) continue;
      ++n;
      const Position& a = positions[static_cast<std::size_t>(loop.i)];
      const Position& b = positions[static_cast<std::size_t>(loop.j)];
      good += std::hypot(a.x - b.x, a.y - b.y, a.z - b.z) < 10.0;
    }
    std::printf("  score > %4.1f: %zu loops, %zu within 10 m\n", threshold, n, good);
    if (threshold == 8.0) {
      // Confident detections are real revisits (precision-recall sweeps this score).
      EXPECT_GT(n, 2000u);
      EXPECT_GT(static_cast<double>(good), 0.95 * static_cast<double>(n));
    }
  }
  std::size_t outcomes[4] = {0, 0, 0, 0};
  for (const FrameMatchStatus& f : out.frames) ++outcomes[static_cast<int>(f.outcome)];
  std::printf(
      "stored similarities %zu; loop closures %zu, %zu within 10 m of ground truth, %zu not; frames: "
      "%zu no candidate, %zu below threshold, %zu suppressed, %zu loop\n",
      stored, out.loops.size(), within_10m, out.loops.size() - within_10m, outcomes[0], outcomes[1],
      outcomes[2], outcomes[3]);
  EXPECT_GT(within_10m, 2500u);
  // Every frame gets exactly one outcome; KITTI 00 revisits roughly a third of its frames.
  EXPECT_GT(outcomes[static_cast<int>(FrameOutcome::kLoop)], 1000u);
}

}  // namespace
}  // namespace loopgate
