#include "core/klt.hpp"

#include <cstdint>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <vector>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define LOOPGATE_KLT_PYRAMID_X86 1
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

#ifdef LOOPGATE_KLT_PYRAMID_X86
[[gnu::target("avx2")]] inline __m256i load8(const std::uint8_t* p) {
  return _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
}
[[gnu::target("avx2")]] inline __m256i load16(const std::int16_t* p) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}
[[gnu::target("avx2")]] inline void store16(std::int16_t* p, __m256i v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), v);
}

// The same, 16 pixels at a time. (A plain CPU check picks it, not an ifunc: ifunc resolvers run before the
// sanitizers' runtimes start.)
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
#ifdef LOOPGATE_KLT_PYRAMID_X86
  static const bool has_avx2 = __builtin_cpu_supports("avx2");
  if (has_avx2) return scharr_row_avx2;
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
  // Scratch rows with one entry of margin on each side (index 1 is column 0) and room for 16-wide loads.
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
  for (int level = 0; level <= max_level; ++level) {
    const cv::Rect inner(bw, bh, size.width, size.height);
    cv::Mat image;
    if (level == 0) {
      // A view with enough image around it is used as it is (OpenCV's tryReuseInputImage).
      cv::Size whole;
      cv::Point offset;
      grey.locateROI(whole, offset);
      if (grey.isSubmatrix() && offset.x >= bw && offset.y >= bh &&
          offset.x + grey.cols + bw <= whole.width && offset.y + grey.rows + bh <= whole.height) {
        image = grey;
      } else {
        cv::Mat buffer(size.height + 2 * bh, size.width + 2 * bw, CV_8UC1);
        cv::copyMakeBorder(grey, buffer, bh, bh, bw, bw, cv::BORDER_REFLECT_101);
        image = buffer(inner);
      }
    } else {
      cv::Mat buffer(size.height + 2 * bh, size.width + 2 * bw, CV_8UC1);
      image = buffer(inner);
      cv::pyrDown(previous, image, size);
      cv::copyMakeBorder(image, buffer, bh, bh, bw, bw, cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
    }
    cv::Mat deriv_buffer(size.height + 2 * bh, size.width + 2 * bw, CV_16SC2);
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

}  // namespace loopgate
