// SeqSLAM step 1: grey conversion, resize to 64 x 32, 8 x 8 patch normalisation (OpenSeqSLAM).
#pragma once

#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "stages/seqslam/seqslam_config.hpp"

namespace loopgate {

// 8-bit grey from 8-bit grey, BGR or BGRA, with MATLAB rgb2gray weights, rounded.
// Throws std::invalid_argument for other pixel types.
cv::Mat seqslam_to_grey(const cv::Mat& image);

// MATLAB imresize(img, [height width], 'lanczos3') of an 8-bit grey image: antialiased Lanczos-3
// (kernel stretched by 1/scale when shrinking), symmetric border, one dimension at a time (the
// one with the smaller scale first), each pass rounded and saturated to 8 bits.
cv::Mat seqslam_resize_lanczos3(const cv::Mat& grey, int width_px, int height_px);

// Patch normalisation in place on an 8-bit grey image: each complete patch x patch block becomes
// mean_grey + round_half_away((p - mean) / std) (sample std, n - 1), saturated to 0..255; a flat
// block (std = 0) becomes all 0; pixels of incomplete border blocks are left unchanged.
void seqslam_patch_normalise(cv::Mat& grey, int patch_px, double mean_grey);

// All of step 1 per the config; returns the image as row-major bytes (width * height). With
// config.input_preprocessed the grey image is returned as it is, and must already have the
// configured size (std::invalid_argument otherwise).
std::vector<std::uint8_t> seqslam_preprocess(const cv::Mat& image, const SeqSlamConfig& config);

}  // namespace loopgate
