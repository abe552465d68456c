#include "core/klt.hpp"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define LOOPGATE_KLT_X86 1
#endif

namespace loopgate {

namespace {

// One row of the derivatives. `above`, `row`, `below`: the image rows y - 1, y, y + 1 (reflected at the
// edges); `smooth` and `diff`: scratch of cols + 2 entries, index 0 standing for column -1; `out`: the row's
// (x, y) derivative pairs. Vertical pass first (3 10 3 down the column, and below - above), then the
// horizontal one (right - left of the smoothed column; 3 10 3 across the differences). Every value fits
// int16 (at most 16 x 255), so any order of these integer operations gives the same result.
void vertical_from(const std::uint8_t* above, const std::uint8_t* row, const std::uint8_t* below,
                   std::int16_t* smooth, std::int16_t* diff, int from, int cols) {
  for (int x = from; x < cols; ++x) {
    smooth[x] = static_cast<std::int16_t>((above[x] + below[x]) * 3 + row[x] * 10);
    diff[x] = static_cast<std::int16_t>(below[x] - above[x]);
  }
}

void horizontal_from(const std::int16_t* smooth, const std::int16_t* diff, std::int16_t* out, int from,
                     int cols) {
  for (int x = from; x < cols; ++x) {
    out[2 * x] = static_cast<std::int16_t>(smooth[x + 1] - smooth[x - 1]);
    out[2 * x + 1] = static_cast<std::int16_t>((diff[x + 1] + diff[x - 1]) * 3 + diff[x] * 10);
  }
}

// Column -1 is column 1 and column `cols` is column cols - 2 (BORDER_REFLECT_101; a single column reflects
// onto itself).
void reflect_ends(std::int16_t* values, int cols) {
  values[-1] = values[cols > 1 ? 1 : 0];
  values[cols] = values[cols > 1 ? cols - 2 : 0];
}

void scharr_row_generic(const std::uint8_t* above, const std::uint8_t* row, const std::uint8_t* below,
                        std::int16_t* smooth, std::int16_t* diff, std::int16_t* out, int cols) {
  vertical_from(above, row, below, smooth, diff, 0, cols);
  reflect_ends(smooth, cols);
  reflect_ends(diff, cols);
  horizontal_from(smooth, diff, out, 0, cols);
}

// Whether the CPU runs AVX2 (a plain check, not an ifunc: ifunc resolvers run before the sanitizers' runtimes
// start). The AVX2 code and the portable code give the same bits.
bool has_avx2() {
#ifdef LOOPGATE_KLT_X86
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
#else
  return false;
#endif
}

#ifdef LOOPGATE_KLT_X86
[[gnu::target("avx2")]] inline __m256i load8(const std::uint8_t* p) {
  return _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
}
[[gnu::target("avx2")]] inline __m256i load16(const std::int16_t* p) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}
[[gnu::target("avx2")]] inline void store16(std::int16_t* p, __m256i v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), v);
}

// The same, 16 pixels at a time.
[[gnu::target("avx2")]] void scharr_row_avx2(const std::uint8_t* above, const std::uint8_t* row,
                                             const std::uint8_t* below, std::int16_t* smooth,
                                             std::int16_t* diff, std::int16_t* out, int cols) {
  const __m256i three = _mm256_set1_epi16(3);
  const __m256i ten = _mm256_set1_epi16(10);
  int x = 0;
  for (; x + 16 <= cols; x += 16) {
    const __m256i a = load8(above + x);
    const __m256i r = load8(row + x);
    const __m256i b = load8(below + x);
    store16(smooth + x,
            _mm256_add_epi16(_mm256_mullo_epi16(_mm256_add_epi16(a, b), three), _mm256_mullo_epi16(r, ten)));
    store16(diff + x, _mm256_sub_epi16(b, a));
  }
  vertical_from(above, row, below, smooth, diff, x, cols);
  reflect_ends(smooth, cols);
  reflect_ends(diff, cols);
  x = 0;
  for (; x + 16 <= cols; x += 16) {
    const __m256i dx = _mm256_sub_epi16(load16(smooth + x + 1), load16(smooth + x - 1));
    const __m256i dy = _mm256_add_epi16(
        _mm256_mullo_epi16(_mm256_add_epi16(load16(diff + x - 1), load16(diff + x + 1)), three),
        _mm256_mullo_epi16(load16(diff + x), ten));
    // Interleave to (dx, dy) pairs: the unpacks work within each 128-bit half, the permutes put the halves
    // back in order (pixels 0-7, then 8-15).
    const __m256i low = _mm256_unpacklo_epi16(dx, dy);
    const __m256i high = _mm256_unpackhi_epi16(dx, dy);
    store16(out + 2 * x, _mm256_permute2x128_si256(low, high, 0x20));
    store16(out + 2 * x + 16, _mm256_permute2x128_si256(low, high, 0x31));
  }
  horizontal_from(smooth, diff, out, x, cols);
}
#endif

using RowFunction = void (*)(const std::uint8_t*, const std::uint8_t*, const std::uint8_t*, std::int16_t*,
                             std::int16_t*, std::int16_t*, int);

RowFunction scharr_row() {
#ifdef LOOPGATE_KLT_X86
  if (has_avx2()) return scharr_row_avx2;
#endif
  return scharr_row_generic;
}

// The border of `buffer` outside `inner` (a view inside it) set to zero bytes.
void clear_border(cv::Mat& buffer, const cv::Rect& inner) {
  const std::size_t pixel = buffer.elemSize();
  for (int y = 0; y < buffer.rows; ++y) {
    std::uint8_t* p = buffer.ptr<std::uint8_t>(y);
    if (y < inner.y || y >= inner.y + inner.height) {
      std::memset(p, 0, pixel * static_cast<std::size_t>(buffer.cols));
      continue;
    }
    std::memset(p, 0, pixel * static_cast<std::size_t>(inner.x));
    const int right = inner.x + inner.width;
    std::memset(p + pixel * static_cast<std::size_t>(right), 0,
                pixel * static_cast<std::size_t>(buffer.cols - right));
  }
}

}  // namespace

void scharr_derivatives(const cv::Mat& grey, cv::Mat& deriv) {
  if (grey.empty() || grey.type() != CV_8UC1 || deriv.type() != CV_16SC2 || deriv.size() != grey.size())
    throw std::invalid_argument(
        "scharr_derivatives: expected a CV_8UC1 image and a CV_16SC2 output of its size");
  const int rows = grey.rows;
  const int cols = grey.cols;
  // Scratch rows with one entry of margin on each side (index 1 is column 0): the reflected columns.
  std::vector<std::int16_t> smooth(static_cast<std::size_t>(cols) + 2);
  std::vector<std::int16_t> diff(static_cast<std::size_t>(cols) + 2);
  const RowFunction row_function = scharr_row();
  for (int y = 0; y < rows; ++y) {
    const int up = y > 0 ? y - 1 : (rows > 1 ? 1 : 0);
    const int down = y < rows - 1 ? y + 1 : (rows > 1 ? rows - 2 : 0);
    row_function(grey.ptr<std::uint8_t>(up), grey.ptr<std::uint8_t>(y), grey.ptr<std::uint8_t>(down),
                 smooth.data() + 1, diff.data() + 1, deriv.ptr<std::int16_t>(y), cols);
  }
}

int build_klt_pyramid(const cv::Mat& grey, cv::Size window, int max_level, std::vector<cv::Mat>& pyramid) {
  if (grey.empty() || grey.type() != CV_8UC1)
    throw std::invalid_argument("build_klt_pyramid: expected a non-empty CV_8UC1 image");
  if (window.width <= 2 || window.height <= 2 || max_level < 0)
    throw std::invalid_argument("build_klt_pyramid: window must exceed 2 x 2 and max_level be >= 0");
  const int bw = window.width;
  const int bh = window.height;
  pyramid.assign(static_cast<std::size_t>(max_level + 1) * 2, cv::Mat());
  cv::Size size = grey.size();
  cv::Mat previous;
  // A buffer with the border and one more row (track_klt's slack), and the bordered part of it.
  const auto bordered = [&](int type) {
    const cv::Mat storage(size.height + 2 * bh + 1, size.width + 2 * bw, type);
    return storage(cv::Rect(0, 0, size.width + 2 * bw, size.height + 2 * bh));
  };
  for (int level = 0; level <= max_level; ++level) {
    const cv::Rect inner(bw, bh, size.width, size.height);
    cv::Mat buffer = bordered(CV_8UC1);
    cv::Mat image = buffer(inner);
    if (level == 0) {
      cv::copyMakeBorder(grey, buffer, bh, bh, bw, bw, cv::BORDER_REFLECT_101);
    } else {
      cv::pyrDown(previous, image, size);
      cv::copyMakeBorder(image, buffer, bh, bh, bw, bw, cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
    }
    cv::Mat deriv_buffer = bordered(CV_16SC2);
    cv::Mat deriv = deriv_buffer(inner);
    scharr_derivatives(image, deriv);
    clear_border(deriv_buffer, inner);
    pyramid[static_cast<std::size_t>(2 * level)] = image;
    pyramid[static_cast<std::size_t>(2 * level + 1)] = deriv;
    size = cv::Size((size.width + 1) / 2, (size.height + 1) / 2);
    if (size.width <= bw || size.height <= bh) {
      pyramid.resize(static_cast<std::size_t>(level + 1) * 2);
      return level;
    }
    previous = image;
  }
  return max_level;
}

namespace {

constexpr int kWeightBits = 14;                // bilinear weights in 1 / 2^14
constexpr int kImageShift = kWeightBits - 5;   // window values of the image: 32 x grey
constexpr float kSumScale = 1.0F / (1 << 20);  // OpenCV's scale of the window sums (32 x 32 x 1024)
constexpr float kMinEigenvalue = 1e-4F;        // cv::calcOpticalFlowPyrLK's default minEigThreshold

struct Weights {
  int w00 = 0, w01 = 0, w10 = 0, w11 = 0;
};

// The bilinear weights of a position's fractional part (a, b), rounded to 14 bits and summing to 2^14.
Weights weights_of(float a, float b) {
  Weights w;
  w.w00 = cvRound((1.F - a) * (1.F - b) * (1 << kWeightBits));
  w.w01 = cvRound(a * (1.F - b) * (1 << kWeightBits));
  w.w10 = cvRound((1.F - a) * b * (1 << kWeightBits));
  w.w11 = (1 << kWeightBits) - w.w00 - w.w01 - w.w10;
  return w;
}

inline int descale(int value, int bits) {
  return (value + (1 << (bits - 1))) >> bits;
}

// One pyramid level's views and steps.
struct Level {
  const std::uint8_t* image = nullptr;  // the previous image (I) or the next one (J), at (0, 0)
  const std::int16_t* deriv = nullptr;  // I's derivative pairs at (0, 0)
  std::ptrdiff_t image_step = 0;        // bytes
  std::ptrdiff_t deriv_step = 0;        // int16 elements
  int cols = 0, rows = 0;
};

// A window's template: I, Ix and Iy at the window's pixels (rows of `padded` values, the pixels past the
// window's width zero in Ix and Iy, so that they add nothing), and the structure tensor's exact sums.
struct Template {
  int width = 0, height = 0, padded = 0;
  std::vector<std::int16_t> value, ix, iy;
  std::int64_t a11 = 0, a12 = 0, a22 = 0;
};

// The portable code: the template at the integer position (x0, y0) of I with the weights w, and the sums
// b = (sum diff Ix, sum diff Iy) of the window of J at (x0, y0) with w, diff = J - I.
void template_portable(const Level& I, int x0, int y0, const Weights& w, Template& t) {
  t.a11 = t.a12 = t.a22 = 0;
  for (int y = 0; y < t.height; ++y) {
    const std::uint8_t* src = I.image + (y0 + y) * I.image_step + x0;
    const std::int16_t* d = I.deriv + (y0 + y) * I.deriv_step + 2 * x0;
    const auto row = static_cast<std::size_t>(y) * static_cast<std::size_t>(t.padded);
    for (int x = 0; x < t.padded; ++x) {
      const auto k = row + static_cast<std::size_t>(x);
      if (x >= t.width) {
        t.value[k] = t.ix[k] = t.iy[k] = 0;
        continue;
      }
      t.value[k] = static_cast<std::int16_t>(descale(src[x] * w.w00 + src[x + 1] * w.w01 +
                                                         src[x + I.image_step] * w.w10 +
                                                         src[x + I.image_step + 1] * w.w11,
                                                     kImageShift));
      const std::int16_t* p = d + 2 * x;
      const std::int16_t* q = p + I.deriv_step;
      const int ix = descale(p[0] * w.w00 + p[2] * w.w01 + q[0] * w.w10 + q[2] * w.w11, kWeightBits);
      const int iy = descale(p[1] * w.w00 + p[3] * w.w01 + q[1] * w.w10 + q[3] * w.w11, kWeightBits);
      t.ix[k] = static_cast<std::int16_t>(ix);
      t.iy[k] = static_cast<std::int16_t>(iy);
      t.a11 += static_cast<std::int64_t>(ix) * ix;
      t.a12 += static_cast<std::int64_t>(ix) * iy;
      t.a22 += static_cast<std::int64_t>(iy) * iy;
    }
  }
}

void mismatch_portable(const Level& J, int x0, int y0, const Weights& w, const Template& t, std::int64_t& b1,
                       std::int64_t& b2) {
  b1 = b2 = 0;
  for (int y = 0; y < t.height; ++y) {
    const std::uint8_t* src = J.image + (y0 + y) * J.image_step + x0;
    const auto row = static_cast<std::size_t>(y) * static_cast<std::size_t>(t.padded);
    for (int x = 0; x < t.width; ++x) {
      const auto k = row + static_cast<std::size_t>(x);
      const int diff = descale(src[x] * w.w00 + src[x + 1] * w.w01 + src[x + J.image_step] * w.w10 +
                                   src[x + J.image_step + 1] * w.w11,
                               kImageShift) -
                       t.value[k];
      b1 += static_cast<std::int64_t>(diff) * t.ix[k];
      b2 += static_cast<std::int64_t>(diff) * t.iy[k];
    }
  }
}

#ifdef LOOPGATE_KLT_X86
// The same, 16 pixels of a row at a time: every value is an exact integer, so the sums are those of the
// portable code whatever the order.

// 16 bilinear values from the int16 values of the four corners (a0 at p, a1 at p + 1, c0 and c1 a row
// below), the pairs (p, p + 1) against (w00, w01) and (w10, w11): lanes 0-3 | 8-11 and 4-7 | 12-15, which the
// pack puts back in order; rounded and shifted right by `shift`.
[[gnu::target("avx2")]] inline __m256i bilinear(__m256i a0, __m256i a1, __m256i c0, __m256i c1, __m256i w0,
                                                __m256i w1, __m256i round, int shift) {
  __m256i low = _mm256_add_epi32(_mm256_madd_epi16(_mm256_unpacklo_epi16(a0, a1), w0),
                                 _mm256_madd_epi16(_mm256_unpacklo_epi16(c0, c1), w1));
  __m256i high = _mm256_add_epi32(_mm256_madd_epi16(_mm256_unpackhi_epi16(a0, a1), w0),
                                  _mm256_madd_epi16(_mm256_unpackhi_epi16(c0, c1), w1));
  low = _mm256_srai_epi32(_mm256_add_epi32(low, round), shift);
  high = _mm256_srai_epi32(_mm256_add_epi32(high, round), shift);
  return _mm256_packs_epi32(low, high);
}

// 16 pixels of an image row.
[[gnu::target("avx2")]] inline __m256i bilinear16(const std::uint8_t* top, std::ptrdiff_t step, __m256i w0,
                                                  __m256i w1, __m256i round, int shift) {
  return bilinear(load8(top), load8(top + 1), load8(top + step), load8(top + step + 1), w0, w1, round, shift);
}

// 8 derivative pairs (x, y) of a row: the pairs of pixels p and p + 1 are 2 elements apart.
[[gnu::target("avx2")]] inline __m256i bilinear_pairs8(const std::int16_t* top, std::ptrdiff_t step,
                                                       __m256i w0, __m256i w1, __m256i round) {
  return bilinear(load16(top), load16(top + 2), load16(top + step), load16(top + step + 2), w0, w1, round,
                  kWeightBits);
}

[[gnu::target("avx2")]] inline __m256i pair_weights(int first, int second) {
  return _mm256_set1_epi32(
      static_cast<int>((static_cast<unsigned>(second) << 16) | (static_cast<unsigned>(first) & 0xFFFFU)));
}

// The 8 int32 lanes of v added into the 4 int64 lanes of sum.
[[gnu::target("avx2")]] inline __m256i add_wide(__m256i sum, __m256i v) {
  sum = _mm256_add_epi64(sum, _mm256_cvtepi32_epi64(_mm256_castsi256_si128(v)));
  return _mm256_add_epi64(sum, _mm256_cvtepi32_epi64(_mm256_extracti128_si256(v, 1)));
}

[[gnu::target("avx2")]] inline std::int64_t total(__m256i v) {
  alignas(32) std::int64_t lanes[4];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), v);
  return lanes[0] + lanes[1] + lanes[2] + lanes[3];
}

[[gnu::target("avx2")]] void template_avx2(const Level& I, int x0, int y0, const Weights& w, Template& t) {
  const __m256i w0 = pair_weights(w.w00, w.w01);
  const __m256i w1 = pair_weights(w.w10, w.w11);
  const __m256i round_image = _mm256_set1_epi32(1 << (kImageShift - 1));
  const __m256i round_deriv = _mm256_set1_epi32(1 << (kWeightBits - 1));
  const __m256i lane = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  __m256i a11 = _mm256_setzero_si256(), a12 = a11, a22 = a11;
  for (int y = 0; y < t.height; ++y) {
    const std::uint8_t* src = I.image + (y0 + y) * I.image_step + x0;
    const std::int16_t* d = I.deriv + (y0 + y) * I.deriv_step + 2 * x0;
    std::int16_t* value = t.value.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(t.padded);
    std::int16_t* out_x = t.ix.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(t.padded);
    std::int16_t* out_y = t.iy.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(t.padded);
    for (int x = 0; x < t.padded; x += 16) {
      store16(value + x, bilinear16(src + x, I.image_step, w0, w1, round_image, kImageShift));
      const __m256i first = bilinear_pairs8(d + 2 * x, I.deriv_step, w0, w1, round_deriv);  // pixels 0-7
      const __m256i second = bilinear_pairs8(d + 2 * x + 16, I.deriv_step, w0, w1, round_deriv);  // 8-15
      // Split the pairs: x in the low halves of the 32-bit lanes, y in the high ones; the pack interleaves
      // the two registers by 64 bits, the permute puts pixels 0-15 in order.
      const __m256i gx = _mm256_packs_epi32(_mm256_srai_epi32(_mm256_slli_epi32(first, 16), 16),
                                            _mm256_srai_epi32(_mm256_slli_epi32(second, 16), 16));
      const __m256i gy = _mm256_packs_epi32(_mm256_srai_epi32(first, 16), _mm256_srai_epi32(second, 16));
      const __m256i inside = _mm256_cmpgt_epi16(_mm256_set1_epi16(static_cast<short>(t.width - x)), lane);
      const __m256i ix = _mm256_and_si256(_mm256_permute4x64_epi64(gx, 0xD8), inside);
      const __m256i iy = _mm256_and_si256(_mm256_permute4x64_epi64(gy, 0xD8), inside);
      store16(out_x + x, ix);
      store16(out_y + x, iy);
      a11 = add_wide(a11, _mm256_madd_epi16(ix, ix));
      a12 = add_wide(a12, _mm256_madd_epi16(ix, iy));
      a22 = add_wide(a22, _mm256_madd_epi16(iy, iy));
    }
  }
  t.a11 = total(a11);
  t.a12 = total(a12);
  t.a22 = total(a22);
}

[[gnu::target("avx2")]] void mismatch_avx2(const Level& J, int x0, int y0, const Weights& w,
                                           const Template& t, std::int64_t& b1, std::int64_t& b2) {
  const __m256i w0 = pair_weights(w.w00, w.w01);
  const __m256i w1 = pair_weights(w.w10, w.w11);
  const __m256i round_image = _mm256_set1_epi32(1 << (kImageShift - 1));
  __m256i sum1 = _mm256_setzero_si256(), sum2 = sum1;
  // A lane of a madd holds two products of at most 8160 x 4080 (diff x derivative): 32 of them per 32-bit
  // lane stay below 2^31, so the rows are summed in 32 bits in blocks of that many and then widened.
  const int chunks = t.padded / 16;
  const int block = std::max(1, 16 / chunks);
  for (int y0_block = 0; y0_block < t.height; y0_block += block) {
    __m256i part1 = _mm256_setzero_si256(), part2 = part1;
    const int y_end = std::min(t.height, y0_block + block);
    for (int y = y0_block; y < y_end; ++y) {
      const std::uint8_t* src = J.image + (y0 + y) * J.image_step + x0;
      const auto row = static_cast<std::size_t>(y) * static_cast<std::size_t>(t.padded);
      const std::int16_t* value = t.value.data() + row;
      const std::int16_t* gx = t.ix.data() + row;
      const std::int16_t* gy = t.iy.data() + row;
      for (int x = 0; x < t.padded; x += 16) {
        const __m256i diff = _mm256_sub_epi16(
            bilinear16(src + x, J.image_step, w0, w1, round_image, kImageShift), load16(value + x));
        part1 = _mm256_add_epi32(part1, _mm256_madd_epi16(diff, load16(gx + x)));
        part2 = _mm256_add_epi32(part2, _mm256_madd_epi16(diff, load16(gy + x)));
      }
    }
    sum1 = add_wide(sum1, part1);
    sum2 = add_wide(sum2, part2);
  }
  b1 = total(sum1);
  b2 = total(sum2);
}
#endif

using TemplateFunction = void (*)(const Level&, int, int, const Weights&, Template&);
using MismatchFunction = void (*)(const Level&, int, int, const Weights&, const Template&, std::int64_t&,
                                  std::int64_t&);

Level level_of(const cv::Mat& image, const cv::Mat* deriv) {
  Level l;
  l.image = image.ptr<std::uint8_t>();
  l.image_step = static_cast<std::ptrdiff_t>(image.step[0]);
  l.cols = image.cols;
  l.rows = image.rows;
  if (deriv != nullptr) {
    l.deriv = deriv->ptr<std::int16_t>();
    l.deriv_step = static_cast<std::ptrdiff_t>(deriv->step[0] / sizeof(std::int16_t));
  }
  return l;
}

// The pyramid's levels checked: images CV_8UC1 and derivatives CV_16SC2 of the same size, each a view with
// the window's border around it and build_klt_pyramid()'s extra row below. Returns its highest level.
int checked_levels(const std::vector<cv::Mat>& pyramid, cv::Size window, const char* which) {
  if (pyramid.empty() || pyramid.size() % 2 != 0)
    throw std::invalid_argument(std::string("track_klt: the ") + which +
                                " pyramid must hold (image, derivatives) pairs (build_klt_pyramid)");
  for (std::size_t k = 0; k < pyramid.size(); ++k) {
    const cv::Mat& m = pyramid[k];
    const bool image = k % 2 == 0;
    cv::Size whole;
    cv::Point offset;
    if (!m.empty()) m.locateROI(whole, offset);
    if (m.empty() || m.type() != (image ? CV_8UC1 : CV_16SC2) ||
        (!image && m.size() != pyramid[k - 1].size()) || offset.x < window.width ||
        offset.y < window.height || offset.x + m.cols + window.width > whole.width ||
        offset.y + m.rows + window.height + 1 > whole.height)
      throw std::invalid_argument(std::string("track_klt: the ") + which + " pyramid's level " +
                                  std::to_string(k / 2) +
                                  " is not one of build_klt_pyramid() with this window");
  }
  return static_cast<int>(pyramid.size() / 2) - 1;
}

void track(const std::vector<cv::Mat>& previous, const std::vector<cv::Mat>& next,
           const std::vector<cv::Point2f>& points, std::vector<cv::Point2f>& found,
           std::vector<unsigned char>& status, cv::Size window, int max_level,
           const cv::TermCriteria& criteria, bool use_initial_flow, TemplateFunction make_template,
           MismatchFunction mismatch) {
  if (window.width <= 2 || window.height <= 2 || max_level < 0)
    throw std::invalid_argument("track_klt: window must exceed 2 x 2 and max_level be >= 0");
  const int levels = std::min(
      {max_level, checked_levels(previous, window, "previous"), checked_levels(next, window, "next")});
  if (use_initial_flow && found.size() != points.size())
    throw std::invalid_argument("track_klt: use_initial_flow needs a start for every point");
  if (!use_initial_flow) found = points;
  status.assign(points.size(), 1);
  if (points.empty()) return;
  // cv::calcOpticalFlowPyrLK's reading of the criteria: 30 iterations and 0.01 px when not given, at most
  // 100 and 10 px; the step is compared squared.
  const int max_iterations =
      (criteria.type & cv::TermCriteria::COUNT) != 0 ? std::clamp(criteria.maxCount, 0, 100) : 30;
  const double epsilon =
      (criteria.type & cv::TermCriteria::EPS) != 0 ? std::clamp(criteria.epsilon, 0.0, 10.0) : 0.01;
  const double epsilon2 = epsilon * epsilon;
  const cv::Point2f half((static_cast<float>(window.width) - 1.F) * 0.5F,
                         (static_cast<float>(window.height) - 1.F) * 0.5F);
  Template t;
  t.width = window.width;
  t.height = window.height;
  t.padded = (window.width + 15) / 16 * 16;
  const auto cells = static_cast<std::size_t>(t.padded) * static_cast<std::size_t>(t.height);
  t.value.assign(cells, 0);
  t.ix.assign(cells, 0);
  t.iy.assign(cells, 0);
  const auto area2 = static_cast<float>(2 * window.width * window.height);
  for (int level = levels; level >= 0; --level) {
    const auto l = static_cast<std::size_t>(level);
    const Level I = level_of(previous[2 * l], &previous[2 * l + 1]);
    const Level J = level_of(next[2 * l], nullptr);
    if (J.cols != I.cols || J.rows != I.rows)
      throw std::invalid_argument("track_klt: the two pyramids' level " + std::to_string(level) +
                                  " differ in size");
    const float scale = static_cast<float>(1.0 / (1 << level));
    // A window whose corner (x, y) leaves the bordered level: the point is lost (at level 0) or not refined
    // here.
    const auto off_level = [&](int x, int y) {
      return x < -window.width || x >= I.cols || y < -window.height || y >= I.rows;
    };
    for (std::size_t k = 0; k < points.size(); ++k) {
      cv::Point2f from = points[k] * scale;
      cv::Point2f to;
      if (level == levels) {
        to = use_initial_flow ? found[k] * scale : from;
      } else {
        to = found[k] * 2.F;
      }
      found[k] = to;
      from -= half;
      const int fx = cvFloor(from.x);
      const int fy = cvFloor(from.y);
      if (off_level(fx, fy)) {
        if (level == 0) status[k] = 0;
        continue;
      }
      make_template(I, fx, fy, weights_of(from.x - static_cast<float>(fx), from.y - static_cast<float>(fy)),
                    t);
      // The exact sums scaled to floats, and the 2 x 2 solve in float as OpenCV does it: in double, the
      // determinant and the smaller eigenvalue of a nearly flat window (dark, noisy images) are no longer
      // rounded to their thresholds as often, and such windows are kept where OpenCV drops them (the
      // night-loop preset's EKF odometry ATE, 32 draws of ekf.klt_epsilon: median 0.749 m with a double
      // solve, 0.632 m in float, 0.641 m with OpenCV's KLT; docs/decisions.md).
      const float a11 = static_cast<float>(t.a11) * kSumScale;
      const float a12 = static_cast<float>(t.a12) * kSumScale;
      const float a22 = static_cast<float>(t.a22) * kSumScale;
      const float det = a11 * a22 - a12 * a12;
      const float min_eig = (a22 + a11 - std::sqrt((a11 - a22) * (a11 - a22) + 4.F * a12 * a12)) / area2;
      if (min_eig < kMinEigenvalue || det < FLT_EPSILON) {
        if (level == 0) status[k] = 0;
        continue;
      }
      const float inverse = 1.F / det;
      to -= half;
      cv::Point2f previous_step;
      for (int j = 0; j < max_iterations; ++j) {
        const int tx = cvFloor(to.x);
        const int ty = cvFloor(to.y);
        if (off_level(tx, ty)) {
          if (level == 0) status[k] = 0;
          break;
        }
        std::int64_t b1 = 0;
        std::int64_t b2 = 0;
        mismatch(J, tx, ty, weights_of(to.x - static_cast<float>(tx), to.y - static_cast<float>(ty)), t, b1,
                 b2);
        const float s1 = static_cast<float>(b1) * kSumScale;
        const float s2 = static_cast<float>(b2) * kSumScale;
        const cv::Point2f step((a12 * s2 - a22 * s1) * inverse, (a12 * s1 - a11 * s2) * inverse);
        to += step;
        found[k] = to + half;
        if (static_cast<double>(step.x) * step.x + static_cast<double>(step.y) * step.y <= epsilon2) break;
        if (j > 0 && std::abs(step.x + previous_step.x) < 0.01F &&
            std::abs(step.y + previous_step.y) < 0.01F) {
          found[k] -= step * 0.5F;  // oscillating between two positions: take the middle
          break;
        }
        previous_step = step;
      }
    }
  }
}

}  // namespace

void track_klt(const std::vector<cv::Mat>& previous, const std::vector<cv::Mat>& next,
               const std::vector<cv::Point2f>& points, std::vector<cv::Point2f>& found,
               std::vector<unsigned char>& status, cv::Size window, int max_level,
               const cv::TermCriteria& criteria, bool use_initial_flow) {
#ifdef LOOPGATE_KLT_X86
  if (has_avx2()) {
    track(previous, next, points, found, status, window, max_level, criteria, use_initial_flow, template_avx2,
          mismatch_avx2);
    return;
  }
#endif
  track(previous, next, points, found, status, window, max_level, criteria, use_initial_flow,
        template_portable, mismatch_portable);
}

void track_klt_portable(const std::vector<cv::Mat>& previous, const std::vector<cv::Mat>& next,
                        const std::vector<cv::Point2f>& points, std::vector<cv::Point2f>& found,
                        std::vector<unsigned char>& status, cv::Size window, int max_level,
                        const cv::TermCriteria& criteria, bool use_initial_flow) {
  track(previous, next, points, found, status, window, max_level, criteria, use_initial_flow,
        template_portable, mismatch_portable);
}

}  // namespace loopgate
