#include "io/png_grey.hpp"

#include <libdeflate.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <utility>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace loopgate {

namespace {

constexpr std::array<unsigned char, 8> kSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
// Larger images go the general way (no fast-path allocation is ever larger than this).
constexpr std::uint64_t kMaxPixels = std::uint64_t{1} << 28;

std::uint32_t read_be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

bool is_type(const unsigned char* p, const char* name) {
  return std::memcmp(p, name, 4) == 0;
}

// Ancillary chunks that cannot change the pixels OpenCV's decoder returns for an 8-bit grey image: text,
// time and physical pixel size. Any other chunk (tRNS, sBIT, gAMA, iCCP, ...) sends the file the general way.
bool harmless_ancillary(const unsigned char* type) {
  return is_type(type, "tEXt") || is_type(type, "zTXt") || is_type(type, "iTXt") || is_type(type, "tIME") ||
         is_type(type, "pHYs");
}

struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};

// Per thread: the decompressor (about 10 KB of tables) and the buffers, reused from frame to frame (a
// 752 x 480 image inflates to 361 KB, which malloc would otherwise map and unmap for every frame).
struct Scratch {
  std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> decompressor{libdeflate_alloc_decompressor()};
  std::vector<unsigned char> idat;      // the IDAT chunks joined, when there are several
  std::vector<unsigned char> filtered;  // the inflated rows, each led by its filter type byte
  std::vector<unsigned char> band;      // 8 or 16 unfiltered rows with margins (unfilter_bands())
};

Scratch& scratch() {
  thread_local Scratch s;
  return s;
}

// The Paeth predictor of a (left), b (up), c (up-left), without branches: the rows' bytes make the three
// outcomes about equally likely, so a branch would be mispredicted often. p - a = b - c does not depend on a,
// which keeps the serial chain through a (the pixel just decoded) short.
inline unsigned paeth(unsigned a, unsigned b, unsigned c) {
  const int b_c = static_cast<int>(b) - static_cast<int>(c);
  const int a_c = static_cast<int>(a) - static_cast<int>(c);
  const int pa = std::abs(b_c);        // |p - a|
  const int pb = std::abs(a_c);        // |p - b|
  const int pc = std::abs(a_c + b_c);  // |p - c|
  // Selections by mask (all ones or zero), which compilers keep free of branches.
  const unsigned take_c = 0U - static_cast<unsigned>(pb > pc);
  const unsigned b_or_c = b ^ ((b ^ c) & take_c);
  const unsigned take_b_or_c = 0U - static_cast<unsigned>(pa > std::min(pb, pc));
  return a ^ ((a ^ b_or_c) & take_b_or_c);
}

// One pixel of a row with filter type Type (PNG spec § 9.2): the filtered byte and its left, up and up-left
// neighbours, already unfiltered (0 outside the image).
template <int Type>
inline unsigned unfilter_pixel(unsigned in, unsigned left, unsigned up, unsigned up_left) {
  if constexpr (Type == 0) return in;
  if constexpr (Type == 1) return (in + left) & 0xffU;
  if constexpr (Type == 2) return (in + up) & 0xffU;
  if constexpr (Type == 3) return (in + ((left + up) >> 1U)) & 0xffU;
  if constexpr (Type == 4) return (in + paeth(left, up, up_left)) & 0xffU;
}

// Two consecutive rows at once (`in0`/`out0` below `prior`, `in1`/`out1` below out0), the second one pixel
// behind the first. Each Sub, Average and Paeth row is a serial chain through the pixel to its left; the two
// chains are independent, so the processor runs them side by side instead of waiting on one. The pixel to the
// left is kept in a local, not read back from the output (which may alias the input for the compiler).
template <int Type0, int Type1>
void unfilter_rows(const unsigned char* in0, const unsigned char* in1, const unsigned char* prior,
                   unsigned char* out0, unsigned char* out1, std::size_t width) {
  unsigned left0 = unfilter_pixel<Type0>(in0[0], 0, prior[0], 0);
  out0[0] = static_cast<unsigned char>(left0);
  unsigned left1 = 0, up_left1 = 0;
  for (std::size_t x = 1; x < width; ++x) {
    const unsigned up1 = left0;  // out0[x - 1]
    left0 = unfilter_pixel<Type0>(in0[x], left0, prior[x], prior[x - 1]);
    out0[x] = static_cast<unsigned char>(left0);
    left1 = unfilter_pixel<Type1>(in1[x - 1], left1, up1, up_left1);
    out1[x - 1] = static_cast<unsigned char>(left1);
    up_left1 = up1;
  }
  out1[width - 1] = static_cast<unsigned char>(unfilter_pixel<Type1>(in1[width - 1], left1, left0, up_left1));
}

template <int Type>
void unfilter_row(const unsigned char* in, const unsigned char* prior, unsigned char* out,
                  std::size_t width) {
  unsigned left = unfilter_pixel<Type>(in[0], 0, prior[0], 0);
  out[0] = static_cast<unsigned char>(left);
  for (std::size_t x = 1; x < width; ++x) {
    left = unfilter_pixel<Type>(in[x], left, prior[x], prior[x - 1]);
    out[x] = static_cast<unsigned char>(left);
  }
}

using RowPair = void (*)(const unsigned char*, const unsigned char*, const unsigned char*, unsigned char*,
                         unsigned char*, std::size_t);
using Row = void (*)(const unsigned char*, const unsigned char*, unsigned char*, std::size_t);

template <int Type0, int... Type1>
constexpr std::array<RowPair, 5> pair_row(std::integer_sequence<int, Type1...> /*types*/) {
  return {&unfilter_rows<Type0, Type1>...};
}

template <int... Type>
constexpr std::array<std::array<RowPair, 5>, 5> pair_table(std::integer_sequence<int, Type...> types) {
  return {pair_row<Type>(types)...};
}

constexpr auto kRowPairs = pair_table(std::make_integer_sequence<int, 5>{});
constexpr std::array<Row, 5> kRows = {&unfilter_row<0>, &unfilter_row<1>, &unfilter_row<2>, &unfilter_row<3>,
                                      &unfilter_row<4>};

#if defined(__SSE2__)
// Eight rows at once in the eight 16-bit lanes of an SSE2 register: lane k holds row y0 + k, one pixel behind
// lane k - 1 (a diagonal wavefront), so that at each step every lane has its left neighbour (its own previous
// value), its up neighbour (lane k - 1's previous value) and its up-left one (lane k - 1's value two steps
// back) at hand. The eight serial chains of the rows then advance together in one chain of vector operations,
// where unfilter_rows() advances two. Every filter type is computed in every lane and each lane keeps its
// row's; integer arithmetic, so the pixels are exactly those of the scalar code. Steps come in blocks of
// eight: the filtered bytes of the eight rows, loaded each shifted by its lane (the diagonal), are transposed
// into eight step vectors, and the eight result vectors are transposed back into row order (Band8 below;
// unfilter_bands() runs one or two bands and says how far they read and write).
inline void transpose8x16(__m128i v[8]) {
  const __m128i t0 = _mm_unpacklo_epi16(v[0], v[1]);
  const __m128i t1 = _mm_unpackhi_epi16(v[0], v[1]);
  const __m128i t2 = _mm_unpacklo_epi16(v[2], v[3]);
  const __m128i t3 = _mm_unpackhi_epi16(v[2], v[3]);
  const __m128i t4 = _mm_unpacklo_epi16(v[4], v[5]);
  const __m128i t5 = _mm_unpackhi_epi16(v[4], v[5]);
  const __m128i t6 = _mm_unpacklo_epi16(v[6], v[7]);
  const __m128i t7 = _mm_unpackhi_epi16(v[6], v[7]);
  const __m128i u0 = _mm_unpacklo_epi32(t0, t2);
  const __m128i u1 = _mm_unpackhi_epi32(t0, t2);
  const __m128i u2 = _mm_unpacklo_epi32(t1, t3);
  const __m128i u3 = _mm_unpackhi_epi32(t1, t3);
  const __m128i u4 = _mm_unpacklo_epi32(t4, t6);
  const __m128i u5 = _mm_unpackhi_epi32(t4, t6);
  const __m128i u6 = _mm_unpacklo_epi32(t5, t7);
  const __m128i u7 = _mm_unpackhi_epi32(t5, t7);
  v[0] = _mm_unpacklo_epi64(u0, u4);
  v[1] = _mm_unpackhi_epi64(u0, u4);
  v[2] = _mm_unpacklo_epi64(u1, u5);
  v[3] = _mm_unpackhi_epi64(u1, u5);
  v[4] = _mm_unpacklo_epi64(u2, u6);
  v[5] = _mm_unpackhi_epi64(u2, u6);
  v[6] = _mm_unpacklo_epi64(u3, u7);
  v[7] = _mm_unpackhi_epi64(u3, u7);
}

inline __m128i abs16(__m128i x) {
  return _mm_max_epi16(x, _mm_sub_epi16(_mm_setzero_si128(), x));
}

inline __m128i select16(__m128i mask, __m128i if_set, __m128i if_clear) {
  return _mm_or_si128(_mm_and_si128(mask, if_set), _mm_andnot_si128(mask, if_clear));
}

// Eight rows (`first` .. first + 7 of `filtered`, stride width + 1, filter byte first; types known valid)
// unfiltered into `out` (8 rows of stride out_stride, pixel x of row k at out + k * out_stride + x).
class Band8 {
 public:
  Band8(const unsigned char* filtered, std::size_t width, std::size_t first, unsigned char* out,
        std::size_t out_stride)
      : out_(out), out_stride_(out_stride) {
    std::array<std::int16_t, 8> sub{}, up{}, avg{}, paeth{};
    for (std::size_t k = 0; k < 8; ++k) {
      const unsigned char* row = filtered + (first + k) * (width + 1);
      sub[k] = static_cast<std::int16_t>(row[0] == 1 ? -1 : 0);
      up[k] = static_cast<std::int16_t>(row[0] == 2 ? -1 : 0);
      avg[k] = static_cast<std::int16_t>(row[0] == 3 ? -1 : 0);
      paeth[k] = static_cast<std::int16_t>(row[0] == 4 ? -1 : 0);
      rows_[k] = row + 1;
    }
    const auto load = [](const std::array<std::int16_t, 8>& m) {
      return _mm_loadu_si128(reinterpret_cast<const __m128i*>(m.data()));
    };
    m_sub_ = load(sub);
    m_up_ = load(up);
    m_avg_ = load(avg);
    m_paeth_ = load(paeth);
  }

  // The filtered bytes of steps s0 .. s0 + 7: lane k of v_[j] is row k's byte at x = s0 + j - k (x < 0 reads
  // the row above's tail, x >= width the next rows' head: those lanes are zeroed or never stored).
  void load(std::size_t s0) {
    for (std::size_t k = 0; k < 8; ++k)
      v_[k] = _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(rows_[k] + s0 - k)),
                                _mm_setzero_si128());
    transpose8x16(v_);
  }

  // Step s0 + j: `up_lane0` holds, in lane 0, the pixel above row 0 at x = s0 + j (0 elsewhere).
  template <bool kLeftEdge>
  void step(int j, __m128i up_lane0) {
    const __m128i a = prev_;
    const __m128i b = _mm_or_si128(_mm_slli_si128(prev_, 2), up_lane0);
    const __m128i c = up_prev_;
    const __m128i a_c = _mm_sub_epi16(a, c);
    const __m128i b_c = _mm_sub_epi16(b, c);
    const __m128i pa = abs16(b_c);
    const __m128i pb = abs16(a_c);
    const __m128i pc = abs16(_mm_add_epi16(a_c, b_c));
    const __m128i b_or_c = select16(_mm_cmpgt_epi16(pb, pc), c, b);
    const __m128i paeth = select16(_mm_cmpgt_epi16(pa, _mm_min_epi16(pb, pc)), b_or_c, a);
    const __m128i avg = _mm_srli_epi16(_mm_add_epi16(a, b), 1);
    const __m128i predictor =
        _mm_or_si128(_mm_or_si128(_mm_and_si128(m_sub_, a), _mm_and_si128(m_up_, b)),
                     _mm_or_si128(_mm_and_si128(m_avg_, avg), _mm_and_si128(m_paeth_, paeth)));
    __m128i value = _mm_and_si128(_mm_add_epi16(v_[j], predictor), _mm_set1_epi16(0xff));
    if constexpr (kLeftEdge) {
      // The first block: lane k > j is a pixel left of the image (x < 0), kept 0.
      const __m128i lane = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7);
      value = _mm_andnot_si128(_mm_cmpgt_epi16(lane, _mm_set1_epi16(static_cast<short>(j))), value);
    }
    v_[j] = value;
    prev_ = value;
    up_prev_ = b;
  }

  // Row 7's pixel at x = s - 7 where s is the last step taken, in lane 0: the up neighbour of the band below
  // at that x.
  __m128i last_row_lane0() const { return _mm_srli_si128(prev_, 14); }

  void store(std::size_t s0) {
    transpose8x16(v_);  // v_[k]: row k's pixels at x = s0 - k .. s0 - k + 7
    for (std::size_t k = 0; k < 8; ++k)
      _mm_storel_epi64(reinterpret_cast<__m128i*>(out_ + k * out_stride_ + s0 - k),
                       _mm_packus_epi16(v_[k], v_[k]));
  }

 private:
  const unsigned char* rows_[8];
  unsigned char* out_;
  std::size_t out_stride_;
  __m128i m_sub_, m_up_, m_avg_, m_paeth_;
  __m128i v_[8];
  __m128i prev_ = _mm_setzero_si128();     // every lane's value at the previous step (its left neighbour now)
  __m128i up_prev_ = _mm_setzero_si128();  // the up neighbours of the previous step (the up-left ones now)
};

// `bands` (1 or 2) bands of eight rows from row y0 of `filtered` below `prior` into `image`, through
// `scratch` (rows with margins: a block's stores reach 15 bytes left and 23 bytes right of a row). Two bands
// run side by side, the lower one a block of eight steps behind, so that its row 0 finds the upper band's row
// 7 at the same x in the register (last_row_lane0()): two independent chains of dependent steps, which the
// processor overlaps. Reads up to 23 bytes past a band's last row in `filtered` and past `prior`'s width.
void unfilter_bands(const unsigned char* filtered, const unsigned char* prior, int y0, int bands,
                    cv::Mat& image, std::vector<unsigned char>& scratch) {
  const auto width = static_cast<std::size_t>(image.cols);
  constexpr std::size_t kLeft = 16;
  const std::size_t stride = width + kLeft + 32;
  const std::size_t rows = 8 * static_cast<std::size_t>(bands);
  scratch.resize(rows * stride);
  const auto first = static_cast<std::size_t>(y0);
  Band8 upper(filtered, width, first, scratch.data() + kLeft, stride);
  const std::size_t blocks = (width + 7 + 7) / 8;  // steps 0 .. width + 6
  const auto upper_block = [&]<bool kLeftEdge>(std::size_t s0) {
    upper.load(s0);
    for (int j = 0; j < 8; ++j)
      upper.template step<kLeftEdge>(j, _mm_cvtsi32_si128(prior[s0 + static_cast<std::size_t>(j)]));
    upper.store(s0);
  };
  if (bands == 1) {
    upper_block.template operator()<true>(0);
    for (std::size_t n = 1; n < blocks; ++n) upper_block.template operator()<false>(8 * n);
  } else {
    Band8 lower(filtered, width, first + 8, scratch.data() + 8 * stride + kLeft, stride);
    // Block n of the upper band with block n - 1 of the lower one: at step j the lower band takes the upper
    // band's row 7 from before the upper band's step j (x = lower's step).
    const auto both = [&]<bool kUpperEdge, bool kLowerEdge>(std::size_t n) {
      const std::size_t s0 = 8 * n;
      upper.load(s0);
      lower.load(s0 - 8);
      for (int j = 0; j < 8; ++j) {
        lower.template step<kLowerEdge>(j, upper.last_row_lane0());
        upper.template step<kUpperEdge>(j, _mm_cvtsi32_si128(prior[s0 + static_cast<std::size_t>(j)]));
      }
      upper.store(s0);
      lower.store(s0 - 8);
    };
    upper_block.template operator()<true>(0);
    both.template operator()<false, true>(1);
    // One block past the upper band's last: its steps are right of the image (computed, stored in the
    // margin).
    for (std::size_t n = 2; n <= blocks; ++n) both.template operator()<false, false>(n);
  }
  for (std::size_t k = 0; k < rows; ++k)
    std::memcpy(image.ptr<unsigned char>(y0 + static_cast<int>(k)), scratch.data() + k * stride + kLeft,
                width);
}
#endif

// Rows of `filtered` (filter byte + width bytes each, followed by at least 32 bytes of slack) into `image`:
// sixteen or eight at a time where SSE2 is there (every x86-64), the rest two at a time; false on an unknown
// filter type.
bool unfilter(const unsigned char* filtered, cv::Mat& image, std::vector<unsigned char>& band) {
  const auto width = static_cast<std::size_t>(image.cols);
  // The row above the first row (and the bytes unfilter_bands() may read past a row).
  const std::vector<unsigned char> zeros(width + 32, 0);
  const unsigned char* prior = zeros.data();
  const auto row_in = [&](int y) { return filtered + static_cast<std::size_t>(y) * (width + 1); };
  int y = 0;
#if defined(__SSE2__)
  while (y + 8 <= image.rows) {
    const int bands = y + 16 <= image.rows ? 2 : 1;
    for (int k = 0; k < 8 * bands; ++k)
      if (row_in(y + k)[0] > 4) return false;
    unfilter_bands(filtered, prior, y, bands, image, band);
    y += 8 * bands;
    prior = image.ptr<unsigned char>(y - 1);
  }
#else
  (void)band;
#endif
  for (; y + 1 < image.rows; y += 2) {
    const unsigned char* in0 = row_in(y);
    const unsigned char* in1 = row_in(y + 1);
    if (in0[0] > 4 || in1[0] > 4) return false;
    unsigned char* out0 = image.ptr<unsigned char>(y);
    unsigned char* out1 = image.ptr<unsigned char>(y + 1);
    kRowPairs[in0[0]][in1[0]](in0 + 1, in1 + 1, prior, out0, out1, width);
    prior = out1;
  }
  if (y < image.rows) {
    const unsigned char* in = row_in(y);
    if (in[0] > 4) return false;
    kRows[in[0]](in + 1, prior, image.ptr<unsigned char>(y), width);
  }
  return true;
}

}  // namespace

cv::Mat decode_png_grey8(const unsigned char* bytes, std::size_t size) {
  if (bytes == nullptr || size < kSignature.size() ||
      std::memcmp(bytes, kSignature.data(), kSignature.size()) != 0)
    return {};
  Scratch& s = scratch();
  if (!s.decompressor) return {};
  std::size_t pos = kSignature.size();
  std::uint32_t width = 0, height = 0;
  bool header = false, end = false;
  const unsigned char* single_idat = nullptr;  // the only IDAT chunk's data, when there is one
  std::size_t idat_size = 0;
  int idat_chunks = 0;
  bool idat_done = false;  // a chunk followed the IDAT run (IDATs must be consecutive)
  s.idat.clear();
  while (!end) {
    if (size - pos < 12) return {};  // truncated: no room for length, type and CRC
    const std::uint32_t length = read_be32(bytes + pos);
    const unsigned char* type = bytes + pos + 4;
    if (length > 0x7fffffffU || size - pos - 12 < length) return {};
    const unsigned char* data = type + 4;
    if (read_be32(data + length) != libdeflate_crc32(0, type, std::size_t{length} + 4)) return {};
    if (!header) {
      if (!is_type(type, "IHDR") || length != 13) return {};
      width = read_be32(data);
      height = read_be32(data + 4);
      // bit depth 8, colour type 0 (grey), compression 0, filter method 0, no interlace
      if (data[8] != 8 || data[9] != 0 || data[10] != 0 || data[11] != 0 || data[12] != 0) return {};
      if (width == 0 || height == 0 || width > 0x7fffffffU || height > 0x7fffffffU ||
          std::uint64_t{width} * height > kMaxPixels)
        return {};
      header = true;
    } else if (is_type(type, "IDAT")) {
      if (idat_done) return {};
      ++idat_chunks;
      if (idat_chunks == 1) {
        single_idat = data;
      } else {
        if (idat_chunks == 2) s.idat.assign(single_idat, single_idat + idat_size);
        s.idat.insert(s.idat.end(), data, data + length);
      }
      idat_size += length;
    } else if (is_type(type, "IEND")) {
      end = true;
    } else if (harmless_ancillary(type)) {
      if (idat_chunks > 0) idat_done = true;
    } else {
      return {};  // IHDR twice, PLTE, tRNS, sBIT, gAMA, an unknown chunk: the general way
    }
    pos += std::size_t{length} + 12;
  }
  if (idat_chunks == 0) return {};
  const unsigned char* stream = idat_chunks == 1 ? single_idat : s.idat.data();
  const std::size_t filtered_size = std::size_t{height} * (std::size_t{width} + 1);
  s.filtered.resize(filtered_size + 32);  // unfilter_bands() reads up to 23 bytes past the last row
  // Exactly filtered_size bytes, and the stream's Adler-32 must match (libdeflate checks it).
  if (libdeflate_zlib_decompress(s.decompressor.get(), stream, idat_size, s.filtered.data(), filtered_size,
                                 nullptr) != LIBDEFLATE_SUCCESS)
    return {};
  cv::Mat image(static_cast<int>(height), static_cast<int>(width), CV_8UC1);
  if (!unfilter(s.filtered.data(), image, s.band)) return {};
  return image;
}

}  // namespace loopgate
