// SeqSLAM step 1: grey conversion, Lanczos-3 resize, patch normalisation.
#include "stages/seqslam/seqslam_preprocess.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

cv::Mat make_grey(int rows, int cols, std::initializer_list<int> values) {
  cv::Mat m(rows, cols, CV_8UC1);
  auto it = values.begin();
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) m.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(*it++);
  return m;
}

TEST(SeqSlamPreprocess, PatchNormalisationHandComputed) {
  // Block [10 20; 30 40]: mean 25, sample std sqrt(500 / 3) = 12.91; z = -1.16, -0.39, 0.39, 1.16.
  cv::Mat m = make_grey(2, 2, {10, 20, 30, 40});
  seqslam_patch_normalise(m, 2, 127.0);
  EXPECT_EQ(m.at<std::uint8_t>(0, 0), 126);
  EXPECT_EQ(m.at<std::uint8_t>(0, 1), 127);
  EXPECT_EQ(m.at<std::uint8_t>(1, 0), 127);
  EXPECT_EQ(m.at<std::uint8_t>(1, 1), 128);
}

TEST(SeqSlamPreprocess, RoundsHalfAwayFromZero) {
  // Block [0 0; 0 8]: mean 2, std 4 exactly; z = -0.5 (-> -1) and 1.5 (-> 2).
  cv::Mat m = make_grey(2, 2, {0, 0, 0, 8});
  seqslam_patch_normalise(m, 2, 127.0);
  EXPECT_EQ(m.at<std::uint8_t>(0, 0), 126);
  EXPECT_EQ(m.at<std::uint8_t>(0, 1), 126);
  EXPECT_EQ(m.at<std::uint8_t>(1, 0), 126);
  EXPECT_EQ(m.at<std::uint8_t>(1, 1), 129);
}

TEST(SeqSlamPreprocess, SaturatesAt255) {
  cv::Mat m = make_grey(2, 2, {0, 0, 0, 8});
  seqslam_patch_normalise(m, 2, 254.0);
  EXPECT_EQ(m.at<std::uint8_t>(0, 0), 253);
  EXPECT_EQ(m.at<std::uint8_t>(1, 1), 255);  // 254 + 2 saturated
}

TEST(SeqSlamPreprocess, FlatBlockBecomesZeroAndIncompleteBorderBlocksStay) {
  // 3 x 5 image, 2 x 2 blocks: complete blocks at columns 0-1 and 2-3 of rows 0-1; column 4 and row 2
  // untouched.
  cv::Mat m = make_grey(3, 5,
                        {50, 50, 10, 20, 99,  //
                         50, 50, 30, 40, 98,  //
                         97, 96, 95, 94, 93});
  seqslam_patch_normalise(m, 2, 127.0);
  const cv::Mat expected = make_grey(3, 5,
                                     {0, 0, 126, 127, 99,  //
                                      0, 0, 127, 128, 98,  //
                                      97, 96, 95, 94, 93});
  EXPECT_EQ(cv::countNonZero(m != expected), 0) << m;
}

TEST(SeqSlamPreprocess, GreyUsesMatlabWeights) {
  cv::Mat bgr(1, 2, CV_8UC3);
  bgr.at<cv::Vec3b>(0, 0) = {0, 0, 255};  // pure red: 0.298936 * 255 = 76.23
  bgr.at<cv::Vec3b>(0, 1) = {255, 0, 0};  // pure blue: 0.114021 * 255 = 29.08
  const cv::Mat grey = seqslam_to_grey(bgr);
  EXPECT_EQ(grey.at<std::uint8_t>(0, 0), 76);
  EXPECT_EQ(grey.at<std::uint8_t>(0, 1), 29);
  EXPECT_THROW(seqslam_to_grey(cv::Mat(2, 2, CV_16UC1)), std::invalid_argument);
}

TEST(SeqSlamPreprocess, LanczosKeepsConstantsAndShrinksStructure) {
  const cv::Mat flat(376, 1241, CV_8UC1, cv::Scalar(77));
  const cv::Mat small = seqslam_resize_lanczos3(flat, 64, 32);
  ASSERT_EQ(small.cols, 64);
  ASSERT_EQ(small.rows, 32);
  EXPECT_EQ(cv::countNonZero(small != 77), 0);
  // Left half dark, right half bright: the halves stay dark / bright, the edge is in the middle.
  cv::Mat step(64, 128, CV_8UC1, cv::Scalar(20));
  step(cv::Rect(64, 0, 64, 64)).setTo(200);
  const cv::Mat half = seqslam_resize_lanczos3(step, 64, 32);
  EXPECT_EQ(half.at<std::uint8_t>(10, 5), 20);
  EXPECT_EQ(half.at<std::uint8_t>(10, 60), 200);
  EXPECT_LT(half.at<std::uint8_t>(10, 31), half.at<std::uint8_t>(10, 32));
}

TEST(SeqSlamPreprocess, PreprocessedInputPassesThrough) {
  SeqSlamConfig config;
  config.input_preprocessed = true;
  cv::Mat thumb(32, 64, CV_8UC1, cv::Scalar(120));
  thumb.at<std::uint8_t>(3, 5) = 135;
  const auto bytes = seqslam_preprocess(thumb, config);
  ASSERT_EQ(bytes.size(), 2048u);
  EXPECT_EQ(bytes[3 * 64 + 5], 135);
  EXPECT_EQ(bytes[0], 120);  // not normalised again (a flat block would become 0)
  EXPECT_THROW(seqslam_preprocess(cv::Mat(40, 64, CV_8UC1, cv::Scalar(0)), config), std::invalid_argument);
  config.input_preprocessed = false;
  const auto normalised = seqslam_preprocess(thumb, config);
  EXPECT_EQ(normalised[8], 0);                 // flat 8 x 8 block -> 0
  EXPECT_EQ(normalised[3 * 64 + 5], 127 + 8);  // the one bright pixel of its block: z = 63 / 8 = 7.875
}

TEST(SeqSlamPreprocess, ConfigValidation) {
  SeqSlamConfig config;
  EXPECT_NO_THROW(config.validate());
  EXPECT_EQ(config.moves(), (std::vector<int>{8, 9, 10, 11, 12}));
  config.sequence_length_frames = 9;
  EXPECT_THROW(config.validate(), ConfigError);
  config = {};
  config.sequence_length_frames = 9;
  EXPECT_THROW(config.validate(), ConfigError);
}

// The authors' thumbnails were made with MATLAB imresize lanczos3 + patch normalisation; ours are
// bit-identical. Note the naming: thumbs/NNNNNN.png is the full frame NNNNNN + 1 (thumbs/000999.png
// is frames/001000.png); frames/000000.png has no thumbnail.
TEST(SeqSlamPreprocess, RealKittiFramesGiveTheAuthorsThumbnailsBitExactly) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/frames/image_0/001000.png");
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/thumbs/image_0/000999.png");
  const auto data = testing::shared_data_dir();
  const SeqSlamConfig config;
  for (const char* cam : {"image_0", "image_1"}) {
    for (const auto& [frame, thumb_name] :
         {std::pair{"001000.png", "000999.png"}, std::pair{"002000.png", "001999.png"}}) {
      const cv::Mat full =
          cv::imread((data / "kitti/00/frames" / cam / frame).string(), cv::IMREAD_UNCHANGED);
      const cv::Mat thumb =
          cv::imread((data / "kitti/00/thumbs" / cam / thumb_name).string(), cv::IMREAD_GRAYSCALE);
      ASSERT_FALSE(full.empty());
      ASSERT_EQ(thumb.cols, 64);
      ASSERT_EQ(thumb.rows, 32);
      const auto ours = seqslam_preprocess(full, config);
      ASSERT_EQ(ours.size(), 2048u);
      int equal = 0;
      for (int i = 0; i < 2048; ++i)
        equal += ours[static_cast<std::size_t>(i)] == thumb.at<std::uint8_t>(i / 64, i % 64);
      EXPECT_EQ(equal, 2048) << cam << "/" << frame;
      // Area averaging (the documented substitute) is close but not identical.
      SeqSlamConfig area = config;
      area.resize_method = SeqSlamResize::kArea;
      const auto approx = seqslam_preprocess(full, area);
      int equal_area = 0;
      for (int i = 0; i < 2048; ++i) {
        equal_area += approx[static_cast<std::size_t>(i)] == thumb.at<std::uint8_t>(i / 64, i % 64);
      }
      EXPECT_GT(equal_area, 1800) << cam << "/" << frame;
      EXPECT_LT(equal_area, 2048) << cam << "/" << frame;
    }
  }
}

}  // namespace
}  // namespace loopgate
