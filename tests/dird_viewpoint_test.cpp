// The viewpoint tolerance's warps (stages/dird/viewpoint.hpp): the rule for their number, a warped image
// matched better with the warps than without, and the configuration's errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/error.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/viewpoint.hpp"

namespace loopgate {
namespace {

// A street-like picture: random blocks of texture over the whole frame (seeded).
cv::Mat textured(int width, int height) {
  cv::Mat image(height, width, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(image, cv::RNG::UNIFORM, 0, 255);
  cv::Mat blocks;
  cv::resize(image(cv::Rect(0, 0, width / 16, height / 8)), blocks, image.size(), 0, 0, cv::INTER_NEAREST);
  cv::GaussianBlur(blocks, blocks, cv::Size(5, 5), 1.5);
  return blocks;
}

TEST(DirdViewpoint, WarpCountFollowsTheRule) {
  ViewpointConfig config;
  EXPECT_TRUE(viewpoint_offsets(config, 640).empty());  // off by default
  config.lateral_m = 3.5;
  config.side_distance_m = 8.0;
  config.max_warps_per_side = 16;
  // ceil(12 * 3.5 / 8) = 6 per side, evenly spaced up to +-3.5 / 8.
  const std::vector<double> offsets = viewpoint_offsets(config, 640);
  ASSERT_EQ(offsets.size(), 12u);
  EXPECT_DOUBLE_EQ(offsets[5], 3.5 / 8.0);
  EXPECT_DOUBLE_EQ(offsets[11], -3.5 / 8.0);
  config.max_warps_per_side = 3;
  EXPECT_EQ(viewpoint_offsets(config, 640).size(), 6u);
  config.lateral_m = 0.3;  // ceil(0.45) = 1 per side
  EXPECT_EQ(viewpoint_offsets(config, 640).size(), 2u);
}

TEST(DirdViewpoint, WarpedImageMatchesItsOriginalBetterWithTheTolerance) {
  const cv::Mat reference = textured(640, 200);
  const double cx = 319.5;
  const cv::Mat query = warp_lateral(reference, 0.3, cx);  // seen from 0.3 x the side distance to the right
  DirdConfig dird;
  dird.normalization = DirdNormalization::kL2;
  dird.resize = DirdResize::kArea;
  const DirdExtractor extractor(dird);
  const Descriptor r = extractor.extract(reference);
  const double without = static_cast<double>(l1_distance(extractor.extract(query), r));
  ViewpointConfig config;
  config.lateral_m = 3.0;
  config.side_distance_m = 8.0;
  double with = without;
  for (const double offset : viewpoint_offsets(config, query.cols))
    with = std::min(with,
                    static_cast<double>(l1_distance(extractor.extract(warp_lateral(query, offset, cx)), r)));
  EXPECT_LT(with, 0.7 * without) << "with " << with << " without " << without;
  // And an unwarped image is its own best match.
  EXPECT_EQ(l1_distance(extractor.extract(warp_lateral(reference, 0.0, cx)), r), 0);
}

TEST(DirdViewpoint, ConfigErrorsNameTheKey) {
  const auto message = [](const ViewpointConfig& c) {
    try {
      c.validate();
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  ViewpointConfig c;
  c.lateral_m = -1.0;
  EXPECT_NE(message(c).find("dird_seqslam.viewpoint_lateral_m"), std::string::npos);
  c = ViewpointConfig{};
  c.lateral_m = 8.0;  // as far as the sides: the camera would go through them
  EXPECT_NE(message(c).find("dird_seqslam.viewpoint_lateral_m"), std::string::npos);
  c = ViewpointConfig{};
  c.side_distance_m = 0.0;
  EXPECT_NE(message(c).find("dird_seqslam.viewpoint_side_distance_m"), std::string::npos);
  c = ViewpointConfig{};
  c.max_warps_per_side = 0;
  EXPECT_NE(message(c).find("dird_seqslam.viewpoint_max_warps_per_side"), std::string::npos);
  EXPECT_TRUE(message(ViewpointConfig{}).empty());
  EXPECT_THROW(warp_lateral(textured(64, 32), 1.0, 31.5), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
