#include "stages/seqslam/seqslam_preprocess.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>

namespace loopgate {

namespace {

// MATLAB rgb2gray coefficients.
constexpr double kGreyWeightR = 0.298936021293775;
constexpr double kGreyWeightG = 0.587043074451121;
constexpr double kGreyWeightB = 0.114020904255103;
constexpr double kLanczosLobes = 3.0;  // Lanczos-3 support is [-3, 3]
constexpr double kMatlabEps = std::numeric_limits<double>::epsilon();

std::uint8_t saturate_round(double value) {
  if (std::isnan(value)) return 0;           // MATLAB casts NaN to 0
  const double rounded = std::round(value);  // half away from zero, as MATLAB
  return static_cast<std::uint8_t>(std::clamp(rounded, 0.0, 255.0));
}

// MATLAB's lanczos3 kernel, eps terms included.
double lanczos3(double x) {
  if (!(std::abs(x) < kLanczosLobes)) return 0.0;
  const double pi = std::numbers::pi;
  return (std::sin(pi * x) * std::sin(pi * x / kLanczosLobes) + kMatlabEps) /
         ((pi * pi * x * x / kLanczosLobes) + kMatlabEps);
}

struct Contributions {
  int taps = 0;
  std::vector<double> weights;  // out_length x taps
  std::vector<int> indices;     // 0-based input indices, out_length x taps
};

// MATLAB imresize 'contributions' for one dimension.
Contributions contributions(int in_length, int out_length) {
  const double scale = static_cast<double>(out_length) / static_cast<double>(in_length);
  double kernel_width = 2.0 * kLanczosLobes;
  const bool antialias = scale < 1.0;
  if (antialias) kernel_width /= scale;
  Contributions c;
  c.taps = static_cast<int>(std::ceil(kernel_width)) + 2;
  c.weights.assign(static_cast<std::size_t>(out_length) * static_cast<std::size_t>(c.taps), 0.0);
  c.indices.assign(c.weights.size(), 0);
  const int period = 2 * in_length;  // symmetric padding: 1..n, n..1
  for (int i = 0; i < out_length; ++i) {
    const double x = static_cast<double>(i + 1);
    const double u = x / scale + 0.5 * (1.0 - 1.0 / scale);
    const double left = std::floor(u - kernel_width / 2.0);
    double sum = 0.0;
    const std::size_t base = static_cast<std::size_t>(i) * static_cast<std::size_t>(c.taps);
    for (int k = 0; k < c.taps; ++k) {
      const double index_1 = left + static_cast<double>(k);  // 1-based, may be out of range
      const double d = u - index_1;
      const double w = antialias ? scale * lanczos3(scale * d) : lanczos3(d);
      c.weights[base + static_cast<std::size_t>(k)] = w;
      sum += w;
      int m = static_cast<int>(index_1) - 1;  // 0-based
      m = ((m % period) + period) % period;
      c.indices[base + static_cast<std::size_t>(k)] = m < in_length ? m : period - 1 - m;
    }
    for (int k = 0; k < c.taps; ++k) c.weights[base + static_cast<std::size_t>(k)] /= sum;
  }
  return c;
}

// Resizes along columns (x) when along_x, else along rows (y).
cv::Mat resize_along(const cv::Mat& in, int out_length, bool along_x) {
  const int in_length = along_x ? in.cols : in.rows;
  const Contributions c = contributions(in_length, out_length);
  cv::Mat out(along_x ? in.rows : out_length, along_x ? out_length : in.cols, CV_8UC1);
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      const int i = along_x ? x : y;
      const std::size_t base = static_cast<std::size_t>(i) * static_cast<std::size_t>(c.taps);
      double acc = 0.0;
      for (int k = 0; k < c.taps; ++k) {
        const double w = c.weights[base + static_cast<std::size_t>(k)];
        if (w == 0.0) continue;  // MATLAB drops all-zero taps; a zero weight adds nothing
        const int m = c.indices[base + static_cast<std::size_t>(k)];
        const std::uint8_t p = along_x ? in.at<std::uint8_t>(y, m) : in.at<std::uint8_t>(m, x);
        acc += w * static_cast<double>(p);
      }
      out.at<std::uint8_t>(y, x) = saturate_round(acc);
    }
  }
  return out;
}

}  // namespace

cv::Mat seqslam_to_grey(const cv::Mat& image) {
  if (image.depth() != CV_8U) throw std::invalid_argument("SeqSLAM expects 8-bit images");
  if (image.channels() == 1) return image;
  if (image.channels() != 3 && image.channels() != 4) {
    throw std::invalid_argument("SeqSLAM expects 1, 3 or 4 channels, got " +
                                std::to_string(image.channels()));
  }
  cv::Mat grey(image.rows, image.cols, CV_8UC1);
  const int channels = image.channels();
  for (int y = 0; y < image.rows; ++y) {
    const std::uint8_t* src = image.ptr<std::uint8_t>(y);
    std::uint8_t* dst = grey.ptr<std::uint8_t>(y);
    for (int x = 0; x < image.cols; ++x) {
      const std::uint8_t* px = src + static_cast<std::ptrdiff_t>(x) * channels;  // BGR(A)
      dst[x] = saturate_round(kGreyWeightR * px[2] + kGreyWeightG * px[1] + kGreyWeightB * px[0]);
    }
  }
  return grey;
}

cv::Mat seqslam_resize_lanczos3(const cv::Mat& grey, int width_px, int height_px) {
  if (grey.type() != CV_8UC1) throw std::invalid_argument("seqslam_resize_lanczos3 expects 8-bit grey");
  if (width_px <= 0 || height_px <= 0 || grey.empty()) throw std::invalid_argument("empty resize");
  const double scale_x = static_cast<double>(width_px) / grey.cols;
  const double scale_y = static_cast<double>(height_px) / grey.rows;
  // MATLAB sorts the dimensions by scale (stable): rows first unless columns shrink more.
  if (scale_x < scale_y) return resize_along(resize_along(grey, width_px, true), height_px, false);
  return resize_along(resize_along(grey, height_px, false), width_px, true);
}

void seqslam_patch_normalise(cv::Mat& grey, int patch_px, double mean_grey) {
  if (grey.type() != CV_8UC1) throw std::invalid_argument("seqslam_patch_normalise expects 8-bit grey");
  if (patch_px <= 1) return;
  const int n = patch_px * patch_px;
  std::vector<double> block(static_cast<std::size_t>(n));
  for (int by = 0; by + patch_px <= grey.rows; by += patch_px) {
    for (int bx = 0; bx + patch_px <= grey.cols; bx += patch_px) {
      // Column-major order within the block, as MATLAB's p(:).
      std::size_t k = 0;
      for (int x = bx; x < bx + patch_px; ++x)
        for (int y = by; y < by + patch_px; ++y) block[k++] = grey.at<std::uint8_t>(y, x);
      double sum = 0.0;
      for (const double p : block) sum += p;
      const double mean = sum / n;
      double ss = 0.0;
      for (const double p : block) ss += (p - mean) * (p - mean);
      const double sd = std::sqrt(ss / (n - 1));
      k = 0;
      for (int x = bx; x < bx + patch_px; ++x) {
        for (int y = by; y < by + patch_px; ++y, ++k) {
          // std = 0 gives NaN in MATLAB, cast to 0 in uint8.
          grey.at<std::uint8_t>(y, x) =
              sd == 0.0 ? std::uint8_t{0} : saturate_round(mean_grey + std::round((block[k] - mean) / sd));
        }
      }
    }
  }
}

std::vector<std::uint8_t> seqslam_preprocess(const cv::Mat& image, const SeqSlamConfig& config) {
  const cv::Mat grey = seqslam_to_grey(image);
  cv::Mat small;
  if (config.input_preprocessed) {
    if (grey.cols != config.image_width_px || grey.rows != config.image_height_px) {
      throw std::invalid_argument("SeqSLAM: preprocessed input of " + std::to_string(grey.cols) + " x " +
                                  std::to_string(grey.rows) + " px, expected " +
                                  std::to_string(config.image_width_px) + " x " +
                                  std::to_string(config.image_height_px));
    }
    small = grey;
  } else if (grey.cols == config.image_width_px && grey.rows == config.image_height_px) {
    small = grey.clone();
  } else if (config.resize_method == SeqSlamResize::kArea) {
    cv::resize(grey, small, cv::Size(config.image_width_px, config.image_height_px), 0, 0, cv::INTER_AREA);
  } else {
    small = seqslam_resize_lanczos3(grey, config.image_width_px, config.image_height_px);
  }
  if (!config.input_preprocessed)
    seqslam_patch_normalise(small, config.patch_size_px, config.patch_mean_grey);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(small.rows) *
                                  static_cast<std::size_t>(small.cols));
  for (int y = 0; y < small.rows; ++y) {
    const std::uint8_t* row = small.ptr<std::uint8_t>(y);
    std::copy(row, row + small.cols, bytes.begin() + static_cast<std::ptrdiff_t>(y) * small.cols);
  }
  return bytes;
}

}  // namespace loopgate
