#pragma once
// The float canvas the texture painters draw on (texture_painters.cpp), addressed in metres.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "sim/render_random.hpp"

namespace loopgate::sim::texture_detail {

using render_detail::hash_combine;
using render_detail::Rng;
using render_detail::unit_from_bits;

// A float canvas addressed in metres (x along the width, y up from the bottom edge).
class Canvas {
 public:
  Canvas(int width_px, int height_px, double width_m, double height_m)
      : w_(width_px),
        h_(height_px),
        sx_(static_cast<double>(width_px) / width_m),
        sy_(static_cast<double>(height_px) / height_m),
        width_m_(width_m),
        height_m_(height_m),
        data_(static_cast<std::size_t>(width_px) * static_cast<std::size_t>(height_px), 0.5f) {}

  double width_m() const { return width_m_; }
  double height_m() const { return height_m_; }

  void fill(double value) { std::fill(data_.begin(), data_.end(), static_cast<float>(value)); }

  // Blends value into the rectangle [x0, x1] x [y0, y1] (metres) with area-coverage anti-aliasing.
  void rect(double x0, double y0, double x1, double y1, double value, double alpha = 1.0) {
    if (x1 < x0) std::swap(x0, x1);
    if (y1 < y0) std::swap(y0, y1);
    const double px0 = x0 * sx_, px1 = x1 * sx_, py0 = y0 * sy_, py1 = y1 * sy_;
    const int i0 = std::max(0, static_cast<int>(std::floor(px0)));
    const int i1 = std::min(w_ - 1, static_cast<int>(std::floor(px1)));
    const int j0 = std::max(0, static_cast<int>(std::floor(py0)));
    const int j1 = std::min(h_ - 1, static_cast<int>(std::floor(py1)));
    for (int j = j0; j <= j1; ++j) {
      const double cy = std::min(py1, j + 1.0) - std::max(py0, static_cast<double>(j));
      if (cy <= 0.0) continue;
      for (int i = i0; i <= i1; ++i) {
        const double cx = std::min(px1, i + 1.0) - std::max(px0, static_cast<double>(i));
        if (cx <= 0.0) continue;
        const double a = alpha * cx * cy;
        float& t = at(i, j);
        t = static_cast<float>(t * (1.0 - a) + value * a);
      }
    }
  }

  // Outline of a rectangle with the given line width.
  void frame(double x0, double y0, double x1, double y1, double line_m, double value) {
    rect(x0, y0, x1, y0 + line_m, value);
    rect(x0, y1 - line_m, x1, y1, value);
    rect(x0, y0, x0 + line_m, y1, value);
    rect(x1 - line_m, y0, x1, y1, value);
  }

  void disc(double cx_m, double cy_m, double r_m, double value) {
    const int i0 = std::max(0, static_cast<int>(std::floor((cx_m - r_m) * sx_)));
    const int i1 = std::min(w_ - 1, static_cast<int>(std::floor((cx_m + r_m) * sx_)));
    const int j0 = std::max(0, static_cast<int>(std::floor((cy_m - r_m) * sy_)));
    const int j1 = std::min(h_ - 1, static_cast<int>(std::floor((cy_m + r_m) * sy_)));
    const double r_px = r_m * sx_;
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const double dx = (i + 0.5) - cx_m * sx_;
        const double dy = ((j + 0.5) - cy_m * sy_) * (sx_ / sy_);
        const double d = std::sqrt(dx * dx + dy * dy);
        const double a = std::clamp(r_px - d + 0.5, 0.0, 1.0);
        if (a <= 0.0) continue;
        float& t = at(i, j);
        t = static_cast<float>(t * (1.0 - a) + value * a);
      }
    }
  }

  // Adds smooth value noise of the given amplitude and feature size (metres), optionally only inside a box.
  void noise(std::uint64_t seed, double amplitude, double scale_m, double x0 = -1e9, double y0 = -1e9,
             double x1 = 1e9, double y1 = 1e9) {
    const int i0 = std::max(0, static_cast<int>(std::floor(x0 * sx_)));
    const int i1 = std::min(w_ - 1, static_cast<int>(std::floor(x1 * sx_)));
    const int j0 = std::max(0, static_cast<int>(std::floor(y0 * sy_)));
    const int j1 = std::min(h_ - 1, static_cast<int>(std::floor(y1 * sy_)));
    const int wrap_x = wrap_ ? std::max(1, static_cast<int>(std::lround(width_m_ / scale_m))) : 0;
    const int wrap_y = wrap_ ? std::max(1, static_cast<int>(std::lround(height_m_ / scale_m))) : 0;
    const double gx_per_px = wrap_ ? static_cast<double>(wrap_x) / w_ : 1.0 / (scale_m * sx_);
    const double gy_per_px = wrap_ ? static_cast<double>(wrap_y) / h_ : 1.0 / (scale_m * sy_);
    for (int j = j0; j <= j1; ++j) {
      const double gy = (j + 0.5) * gy_per_px;
      for (int i = i0; i <= i1; ++i) {
        const double gx = (i + 0.5) * gx_per_px;
        at(i, j) += static_cast<float>(amplitude * (2.0 * value_noise(seed, gx, gy, wrap_x, wrap_y) - 1.0));
      }
    }
  }

  // Per-texel white noise (grain).
  void grain(std::uint64_t seed, double amplitude) {
    for (std::size_t k = 0; k < data_.size(); ++k) {
      data_[k] += static_cast<float>(amplitude * (2.0 * unit_from_bits(hash_combine(seed, k)) - 1.0));
    }
  }

  // Glyph-like blocks ("lettering") in the box: each glyph is a 3 x 5 grid of random cells.
  void lettering(Rng& rng, double x0, double y0, double x1, double y1, double value) {
    const double glyph_h = (y1 - y0);
    const double glyph_w = glyph_h * 0.62;
    const double gap = glyph_h * 0.22;
    for (double gx = x0; gx + glyph_w <= x1; gx += glyph_w + gap) {
      if (rng.chance(0.12)) continue;  // word space
      const double cell_w = glyph_w / 3.0;
      const double cell_h = glyph_h / 5.0;
      int cells = 0;
      for (int r = 0; r < 5; ++r) {
        for (int c = 0; c < 3; ++c) {
          if (rng.chance(0.55)) {
            rect(gx + c * cell_w, y0 + r * cell_h, gx + (c + 1) * cell_w, y0 + (r + 1) * cell_h, value);
            ++cells;
          }
        }
      }
      if (cells == 0) rect(gx, y0, gx + cell_w, y1, value);
    }
  }

  void set_wrap(bool wrap) { wrap_ = wrap; }

  std::vector<std::uint8_t> to_bytes() const {
    std::vector<std::uint8_t> out(data_.size());
    for (std::size_t k = 0; k < data_.size(); ++k) {
      const double v = std::clamp(static_cast<double>(data_[k]), 0.0, 1.0);
      out[k] = static_cast<std::uint8_t>(std::lround(v * 255.0));
    }
    return out;
  }

 private:
  float& at(int i, int j) { return data_[static_cast<std::size_t>(j) * static_cast<std::size_t>(w_) + i]; }

  static double lattice(std::uint64_t seed, long long ix, long long iy) {
    return unit_from_bits(
        hash_combine(seed, hash_combine(static_cast<std::uint64_t>(ix), static_cast<std::uint64_t>(iy))));
  }
  static double smooth(double t) { return t * t * (3.0 - 2.0 * t); }
  static double value_noise(std::uint64_t seed, double x, double y, int wrap_x, int wrap_y) {
    const double fx = std::floor(x), fy = std::floor(y);
    long long ix = static_cast<long long>(fx), iy = static_cast<long long>(fy);
    long long ix1 = ix + 1, iy1 = iy + 1;
    if (wrap_x > 0) {
      ix %= wrap_x;
      ix1 %= wrap_x;
    }
    if (wrap_y > 0) {
      iy %= wrap_y;
      iy1 %= wrap_y;
    }
    const double tx = smooth(x - fx), ty = smooth(y - fy);
    const double a = lattice(seed, ix, iy), b = lattice(seed, ix1, iy);
    const double c = lattice(seed, ix, iy1), d = lattice(seed, ix1, iy1);
    return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty;
  }

  int w_, h_;
  double sx_, sy_;
  double width_m_, height_m_;
  bool wrap_ = false;
  std::vector<float> data_;
};

}  // namespace loopgate::sim::texture_detail
