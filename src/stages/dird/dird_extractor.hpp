// DIRD extraction (docs/detection.md § DIRD, the descriptor): an 8-bit image of any size -> 3456 bytes.
//
// Only the 1728 distinct sample positions of the pooling stage are evaluated, from the integral image of
// the 192 x 192 nearest-neighbour working image; the per-thread workspace is reused across calls (no
// allocation per call after the first on a thread). Results are bit-identical to the full-image
// formulation of the spec (tests/dird_extractor_test.cpp checks the spec's test vectors).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <opencv2/core/mat.hpp>

#include "stages/dird/dird_config.hpp"

namespace loopgate {

constexpr std::size_t kDirdBytes = 3456;
// Picture layout of a descriptor (paper Fig. 3): the 3456 bytes row-major as 54 rows x 64 columns.
constexpr int kDirdPictureRows = 54;
constexpr int kDirdPictureCols = 64;
// Side of the working image the input is resized to.
constexpr int kDirdWorkingSize = 192;

using Descriptor = std::array<std::uint8_t, kDirdBytes>;

// Grey value of a colour pixel, BT.601 weights 0.299/0.587/0.114, rounded to nearest (exact integer
// arithmetic: (299 R + 587 G + 114 B + 500) / 1000).
inline std::uint8_t bt601_grey(std::uint8_t r, std::uint8_t g, std::uint8_t b) {
  return static_cast<std::uint8_t>((299u * r + 587u * g + 114u * b + 500u) / 1000u);
}

// Converts CV_8UC1 (copied), CV_8UC3 (BGR, OpenCV order) or CV_8UC4 (BGRA) to CV_8UC1 with bt601_grey().
// Throws std::invalid_argument for empty images or other types.
cv::Mat to_grey_bt601(const cv::Mat& image);

// The 192 x 192 working image of docs/detection.md § DIRD (after the optional vertical flip and grey
// conversion): work[v][u] = src[int(v * sy)][int(u * sx)], sx = float(W) / 192, sy = float(H) / 192.
// Reference path for tests and pictures; extract() computes the same pixels without building it.
cv::Mat dird_working_image(const cv::Mat& image, bool flip_vertical = false);

// Stateless extractor: configuration only, safe to call concurrently from many threads.
class DirdExtractor {
 public:
  explicit DirdExtractor(const DirdConfig& config = {});

  // `image`: CV_8UC1, CV_8UC3 (BGR) or CV_8UC4 (BGRA), any size >= 1 x 1. Throws std::invalid_argument
  // for empty images or other pixel types.
  Descriptor extract(const cv::Mat& image) const;
  void extract(const cv::Mat& image, Descriptor& out) const;

  const DirdConfig& config() const { return config_; }

 private:
  DirdConfig config_;
  bool l2_normalization_ = false;
};

// The descriptor as a 54 x 64 CV_8UC1 picture (row-major reshape of the 3456 bytes).
cv::Mat descriptor_picture(const Descriptor& descriptor);

}  // namespace loopgate
