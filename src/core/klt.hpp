// The pyramid of Lucas-Kanade tracking: the image pyramid cv::calcOpticalFlowPyrLK tracks on, built as
// cv::buildOpticalFlowPyramid(grey, pyramid, window, max_level) builds it (derivatives on, borders
// BORDER_REFLECT_101 for the images and BORDER_CONSTANT for the derivatives), byte for byte, in less time: the
// Scharr derivatives of each level are computed 16 pixels at a time (AVX2, where the CPU has it) straight into
// their bordered buffer, and only the border is then cleared, where OpenCV computes them 8 at a time and copies
// the whole level onto itself to make the border. The images (the level 0 copy, pyrDown) are OpenCV's own calls.
#pragma once

#include <opencv2/core/mat.hpp>
#include <vector>

namespace loopgate {

// `grey`: CV_8UC1, not empty. Fills `pyramid` with (image, derivatives) per level, each a view inside a
// buffer with `window` of border on every side, as cv::buildOpticalFlowPyramid does; returns the number of
// the highest level built (fewer than max_level when a level would be no larger than the window).
int build_klt_pyramid(const cv::Mat& grey, cv::Size window, int max_level, std::vector<cv::Mat>& pyramid);

// The Scharr derivatives of a CV_8UC1 image into `deriv` (CV_16SC2, same size: x then y derivative per pixel,
// unscaled: 3 10 3 smoothing, -1 0 1 difference), reflecting the image at its edges (BORDER_REFLECT_101, as
// OpenCV's pyramid code does). `deriv` must already have that size and type; it may be a view.
void scharr_derivatives(const cv::Mat& grey, cv::Mat& deriv);

}  // namespace loopgate
