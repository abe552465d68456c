// Pyramidal Lucas-Kanade tracking (the ekf tracker's and the verifier's fallback), loopgate's own
// (docs/decisions.md, "The tracker's KLT and corner response"):
// - build_klt_pyramid(): cv::buildOpticalFlowPyramid's pyramid byte for byte (derivatives on, borders
//   BORDER_REFLECT_101 for the images and BORDER_CONSTANT for the derivatives), in less time: the Scharr
//   derivatives of each level are computed 16 pixels at a time (AVX2, where the CPU has it) straight into
//   their bordered buffer and only the border is then cleared, where OpenCV computes them 8 at a time and
//   copies the whole level onto itself to make the border. The images (the level 0 copy, pyrDown) are
//   OpenCV's own calls.
// - track_klt(): cv::calcOpticalFlowPyrLK's method with exact integer window sums, about twice as fast.
#pragma once

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>
#include <vector>

namespace loopgate {

// `grey`: CV_8UC1, not empty. Fills `pyramid` with (image, derivatives) per level, each a view inside a
// buffer with `window` of border on every side, as cv::buildOpticalFlowPyramid does; returns the number of
// the highest level built (fewer than max_level when a level would be no larger than the window). Unlike
// OpenCV it always copies level 0 (never tracks on a view of the caller's image) and leaves one more row
// below each buffer, which track_klt() may read into past a window's last column.
int build_klt_pyramid(const cv::Mat& grey, cv::Size window, int max_level, std::vector<cv::Mat>& pyramid);

// The Scharr derivatives of a CV_8UC1 image into `deriv` (CV_16SC2, same size: x then y derivative per pixel,
// unscaled: 3 10 3 smoothing, -1 0 1 difference), reflecting the image at its edges (BORDER_REFLECT_101, as
// OpenCV's pyramid code does). `deriv` must already have that size and type; it may be a view.
void scharr_derivatives(const cv::Mat& grey, cv::Mat& deriv);

// Pyramidal Lucas-Kanade (Bouguet's iteration, as cv::calcOpticalFlowPyrLK(previous, next, points, found,
// status, noArray(), window, max_level, criteria, flags, 1e-4) runs it) on two pyramids of
// build_klt_pyramid() with the same window: `found` gets each point's position in the next image (its initial
// value is the start when `use_initial_flow`), `status` 1 where it was tracked. The same window sampling
// (14-bit bilinear weights, the image scaled by 32), the same stopping rules (criteria's count and epsilon, a
// step that undoes the previous one) and the same losses (the window leaves the image, the structure tensor's
// smaller eigenvalue below 1e-4 per pixel). What differs: the sums over the window are exact integers (OpenCV
// adds them as floats, in an order its SIMD width decides), so a point's position can differ from OpenCV's in
// its last bits, and is the same on every CPU; and 16 pixels of a window row at a time (AVX2, where the CPU
// has it; OpenCV 8 and the rest one by one). The 2 x 2 solve from those sums is in float, as OpenCV's: its
// thresholds then drop the same nearly flat windows.
void track_klt(const std::vector<cv::Mat>& previous, const std::vector<cv::Mat>& next,
               const std::vector<cv::Point2f>& points, std::vector<cv::Point2f>& found,
               std::vector<unsigned char>& status, cv::Size window, int max_level,
               const cv::TermCriteria& criteria, bool use_initial_flow);

// Test seam: the same without AVX2 (the portable code, which every CPU without it runs).
void track_klt_portable(const std::vector<cv::Mat>& previous, const std::vector<cv::Mat>& next,
                        const std::vector<cv::Point2f>& points, std::vector<cv::Point2f>& found,
                        std::vector<unsigned char>& status, cv::Size window, int max_level,
                        const cv::TermCriteria& criteria, bool use_initial_flow);

}  // namespace loopgate
