#include "stages/dird/dird_codes.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "core/error.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LOOPGATE_CODES_SIMD_DISPATCH 1
#endif

namespace loopgate {

namespace {

void require_sigma(const char* key, double sigma) {
  if (!(std::isfinite(sigma) && sigma > 0.0 && sigma <= 4.0)) {
    throw ConfigError(std::string("dird_seqslam.") + key + ": must be in (0, 4] standard deviations (got " +
                      std::to_string(sigma) + ")");
  }
}

}  // namespace

void DirdCodeConfig::validate() const {
  require_sigma("ternary_threshold_sigma", ternary_threshold_sigma);
  require_sigma("int2_threshold_sigma", int2_threshold_sigma);
}

std::size_t code_words(DirdCode code) {
  switch (code) {
    case DirdCode::kSign: return kCodePlaneWords;
    case DirdCode::kTernary:
    case DirdCode::kInt2: return 2 * kCodePlaneWords;
    case DirdCode::kInt8: break;
  }
  return 0;
}

int code_threshold(double sigma, double clamp_sigma) {
  return std::max(1, static_cast<int>(std::lround(kStandardCodeMax * sigma / clamp_sigma)));
}

std::int32_t make_compact_code(const DirdCodeConfig& config, double clamp_sigma, const Descriptor& standard,
                               std::uint64_t* out) {
  const std::size_t words = code_words(config.code);
  if (words == 0) throw std::invalid_argument("make_compact_code: int8 is not a compact code");
  std::memset(out, 0, words * sizeof(std::uint64_t));
  if (config.code == DirdCode::kSign) {
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      if (standard[k] > kStandardCodeZero) out[k / 64] |= std::uint64_t{1} << (k % 64);
    }
    return static_cast<std::int32_t>(kDirdBytes);
  }
  // Thresholds in code units (at least 1, so code 0 is never a plus, a minus or a large magnitude).
  const bool ternary = config.code == DirdCode::kTernary;
  const int threshold =
      code_threshold(ternary ? config.ternary_threshold_sigma : config.int2_threshold_sigma, clamp_sigma);
  std::uint64_t* first = out;                     // ternary: plus; int2: sign
  std::uint64_t* second = out + kCodePlaneWords;  // ternary: minus; int2: magnitude
  std::int32_t count = 0;
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    const int c = static_cast<int>(standard[k]) - kStandardCodeZero;
    const std::uint64_t bit = std::uint64_t{1} << (k % 64);
    if (ternary) {
      if (c >= threshold) {
        first[k / 64] |= bit;
        ++count;
      } else if (c <= -threshold) {
        second[k / 64] |= bit;
        ++count;
      }
    } else {
      if (c > 0) first[k / 64] |= bit;
      if (c >= threshold || c <= -threshold) {
        second[k / 64] |= bit;
        ++count;
      }
    }
  }
  return count;
}

// ---------------------------------------------------------------------------------------------------------
// Kernels

std::int32_t hamming_words_portable(const std::uint64_t* a, const std::uint64_t* b, std::size_t words) {
  std::int32_t sum = 0;
  for (std::size_t k = 0; k < words; ++k) sum += std::popcount(a[k] ^ b[k]);
  return sum;
}

std::int32_t ternary_dot_portable(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words) {
  const std::uint64_t* ap = a;
  const std::uint64_t* am = a + plane_words;
  const std::uint64_t* bp = b;
  const std::uint64_t* bm = b + plane_words;
  std::int32_t same = 0, opposite = 0;
  for (std::size_t k = 0; k < plane_words; ++k) {
    same += std::popcount((ap[k] & bp[k]) | (am[k] & bm[k]));
    opposite += std::popcount((ap[k] & bm[k]) | (am[k] & bp[k]));
  }
  return same - opposite;
}

namespace {

std::int32_t int2_pair_term_portable(const std::uint64_t* a, const std::uint64_t* b,
                                     std::size_t plane_words) {
  const std::uint64_t* as = a;
  const std::uint64_t* am = a + plane_words;
  const std::uint64_t* bs = b;
  const std::uint64_t* bm = b + plane_words;
  std::int32_t both = 0, d = 0, d_one = 0, d_both = 0;
  for (std::size_t k = 0; k < plane_words; ++k) {
    const std::uint64_t differ = as[k] ^ bs[k];
    const std::uint64_t mab = am[k] & bm[k];
    both += std::popcount(mab);
    d += std::popcount(differ);
    d_one += std::popcount(differ & am[k]) + std::popcount(differ & bm[k]);
    d_both += std::popcount(differ & mab);
  }
  return 4 * both - 2 * d - 4 * d_one - 8 * d_both;
}

#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
// ---- AVX2: bit counts of the 32 bytes of x by a 16-entry table of nibble counts looked up with pshufb for
// the low and the high nibble of every byte; psadbw against zero adds the byte counts (at most 8 each) into
// the 64-bit lanes: no overflow at any length.
__attribute__((target("avx2"))) inline __m256i byte_popcounts(__m256i x) {
  const __m256i table = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2, 1, 2, 2,
                                         3, 1, 2, 2, 3, 2, 3, 3, 4);
  const __m256i low_mask = _mm256_set1_epi8(0x0f);
  const __m256i lo = _mm256_and_si256(x, low_mask);
  const __m256i hi = _mm256_and_si256(_mm256_srli_epi16(x, 4), low_mask);
  return _mm256_add_epi8(_mm256_shuffle_epi8(table, lo), _mm256_shuffle_epi8(table, hi));
}

__attribute__((target("avx2"))) inline __m256i lane_counts(__m256i x) {
  return _mm256_sad_epu8(byte_popcounts(x), _mm256_setzero_si256());
}

// Sum of the four 64-bit lanes.
__attribute__((target("avx2"))) inline std::int64_t lane_sum(__m256i v) {
  alignas(32) std::int64_t lanes[4];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), v);
  return lanes[0] + lanes[1] + lanes[2] + lanes[3];
}

__attribute__((target("avx2"))) inline __m256i load(const std::uint64_t* p) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}

__attribute__((target("avx2"))) std::int32_t hamming_words_avx2(const std::uint64_t* a,
                                                                const std::uint64_t* b, std::size_t words) {
  __m256i acc = _mm256_setzero_si256();
  for (std::size_t k = 0; k < words; k += 4)
    acc = _mm256_add_epi64(acc, lane_counts(_mm256_xor_si256(load(a + k), load(b + k))));
  return static_cast<std::int32_t>(lane_sum(acc));
}

__attribute__((target("avx2"))) std::int32_t ternary_dot_avx2(const std::uint64_t* a, const std::uint64_t* b,
                                                              std::size_t plane_words) {
  __m256i same_acc = _mm256_setzero_si256();
  __m256i opposite_acc = _mm256_setzero_si256();
  for (std::size_t k = 0; k < plane_words; k += 4) {
    const __m256i ap = load(a + k), am = load(a + plane_words + k);
    const __m256i bp = load(b + k), bm = load(b + plane_words + k);
    const __m256i same = _mm256_or_si256(_mm256_and_si256(ap, bp), _mm256_and_si256(am, bm));
    const __m256i opposite = _mm256_or_si256(_mm256_and_si256(ap, bm), _mm256_and_si256(am, bp));
    same_acc = _mm256_add_epi64(same_acc, lane_counts(same));
    opposite_acc = _mm256_add_epi64(opposite_acc, lane_counts(opposite));
  }
  return static_cast<std::int32_t>(lane_sum(same_acc) - lane_sum(opposite_acc));
}

__attribute__((target("avx2"))) std::int32_t int2_pair_term_avx2(const std::uint64_t* a,
                                                                 const std::uint64_t* b,
                                                                 std::size_t plane_words) {
  __m256i both = _mm256_setzero_si256(), d = both, d_one = both, d_both = both;
  for (std::size_t k = 0; k < plane_words; k += 4) {
    const __m256i am = load(a + plane_words + k), bm = load(b + plane_words + k);
    const __m256i differ = _mm256_xor_si256(load(a + k), load(b + k));
    const __m256i mab = _mm256_and_si256(am, bm);
    both = _mm256_add_epi64(both, lane_counts(mab));
    d = _mm256_add_epi64(d, lane_counts(differ));
    d_one = _mm256_add_epi64(d_one, lane_counts(_mm256_and_si256(differ, am)));
    d_one = _mm256_add_epi64(d_one, lane_counts(_mm256_and_si256(differ, bm)));
    d_both = _mm256_add_epi64(d_both, lane_counts(_mm256_and_si256(differ, mab)));
  }
  return static_cast<std::int32_t>(4 * lane_sum(both) - 2 * lane_sum(d) - 4 * lane_sum(d_one) -
                                   8 * lane_sum(d_both));
}

// ---- AVX-512 (VPOPCNTDQ): eight words per step; a last step of four words through a masked load.
// GCC 12's avx512fintrin.h builds _mm512_setzero_si512 and the masked loads from an "undefined" vector that
// -Wuninitialized reports (GCC bug 105593, a false positive): silenced for these kernels only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#define LOOPGATE_AVX512_TARGET __attribute__((target("avx512f,avx512vpopcntdq")))

LOOPGATE_AVX512_TARGET inline __m512i load8(const std::uint64_t* p, std::size_t k, std::size_t words) {
  if (k + 8 <= words) return _mm512_loadu_si512(p + k);
  return _mm512_maskz_loadu_epi64(static_cast<__mmask8>(0x0f), p + k);
}

LOOPGATE_AVX512_TARGET std::int32_t hamming_words_avx512(const std::uint64_t* a, const std::uint64_t* b,
                                                         std::size_t words) {
  __m512i acc = _mm512_setzero_si512();
  for (std::size_t k = 0; k < words; k += 8)
    acc =
        _mm512_add_epi64(acc, _mm512_popcnt_epi64(_mm512_xor_si512(load8(a, k, words), load8(b, k, words))));
  return static_cast<std::int32_t>(_mm512_reduce_add_epi64(acc));
}

LOOPGATE_AVX512_TARGET std::int32_t ternary_dot_avx512(const std::uint64_t* a, const std::uint64_t* b,
                                                       std::size_t plane_words) {
  __m512i same_acc = _mm512_setzero_si512(), opposite_acc = same_acc;
  const std::uint64_t* am_ = a + plane_words;
  const std::uint64_t* bm_ = b + plane_words;
  for (std::size_t k = 0; k < plane_words; k += 8) {
    const __m512i ap = load8(a, k, plane_words), am = load8(am_, k, plane_words);
    const __m512i bp = load8(b, k, plane_words), bm = load8(bm_, k, plane_words);
    const __m512i same = _mm512_or_si512(_mm512_and_si512(ap, bp), _mm512_and_si512(am, bm));
    const __m512i opposite = _mm512_or_si512(_mm512_and_si512(ap, bm), _mm512_and_si512(am, bp));
    same_acc = _mm512_add_epi64(same_acc, _mm512_popcnt_epi64(same));
    opposite_acc = _mm512_add_epi64(opposite_acc, _mm512_popcnt_epi64(opposite));
  }
  return static_cast<std::int32_t>(_mm512_reduce_add_epi64(same_acc) - _mm512_reduce_add_epi64(opposite_acc));
}

LOOPGATE_AVX512_TARGET std::int32_t int2_pair_term_avx512(const std::uint64_t* a, const std::uint64_t* b,
                                                          std::size_t plane_words) {
  // One accumulator of the weighted counts: 4 |mab| - 2 |d| - 4 |d&ma| - 4 |d&mb| - 8 |d&mab| per lane.
  __m512i acc = _mm512_setzero_si512();
  const std::uint64_t* am_ = a + plane_words;
  const std::uint64_t* bm_ = b + plane_words;
  for (std::size_t k = 0; k < plane_words; k += 8) {
    const __m512i am = load8(am_, k, plane_words), bm = load8(bm_, k, plane_words);
    const __m512i differ = _mm512_xor_si512(load8(a, k, plane_words), load8(b, k, plane_words));
    const __m512i mab = _mm512_and_si512(am, bm);
    const __m512i plus = _mm512_slli_epi64(_mm512_popcnt_epi64(mab), 2);
    const __m512i minus = _mm512_add_epi64(
        _mm512_slli_epi64(_mm512_popcnt_epi64(differ), 1),
        _mm512_add_epi64(
            _mm512_slli_epi64(_mm512_add_epi64(_mm512_popcnt_epi64(_mm512_and_si512(differ, am)),
                                               _mm512_popcnt_epi64(_mm512_and_si512(differ, bm))),
                              2),
            _mm512_slli_epi64(_mm512_popcnt_epi64(_mm512_and_si512(differ, mab)), 3)));
    acc = _mm512_add_epi64(acc, _mm512_sub_epi64(plus, minus));
  }
  return static_cast<std::int32_t>(_mm512_reduce_add_epi64(acc));
}

#pragma GCC diagnostic pop

const bool kHasAvx2 = __builtin_cpu_supports("avx2");
const bool kHasAvx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vpopcntdq");
#endif

void require_multiple_of_4(std::size_t words) {
  if (words % 4 != 0) throw std::invalid_argument("compact code kernels: words must be a multiple of 4");
}

void require_available(PopcountKernel kernel) {
  if (!popcount_kernel_available(kernel)) {
    throw std::invalid_argument(std::string("compact code kernels: this CPU does not run the ") +
                                std::string(enum_name(kernel)) + " kernel");
  }
}

const PopcountKernel kBest = [] {
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
  if (kHasAvx512) return PopcountKernel::kAvx512;
  if (kHasAvx2) return PopcountKernel::kAvx2;
#endif
  return PopcountKernel::kPortable;
}();

}  // namespace

PopcountKernel best_popcount_kernel() {
  return kBest;
}

bool popcount_kernel_available(PopcountKernel kernel) {
  switch (kernel) {
    case PopcountKernel::kPortable: return true;
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
    case PopcountKernel::kAvx2: return kHasAvx2;
    case PopcountKernel::kAvx512: return kHasAvx512;
#else
    default: return false;
#endif
  }
  return false;
}

bool compact_codes_use_avx2() {
  return kBest != PopcountKernel::kPortable;
}

std::int32_t hamming_words(const std::uint64_t* a, const std::uint64_t* b, std::size_t words,
                           PopcountKernel kernel) {
  require_multiple_of_4(words);
  require_available(kernel);
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
  if (kernel == PopcountKernel::kAvx512) return hamming_words_avx512(a, b, words);
  if (kernel == PopcountKernel::kAvx2) return hamming_words_avx2(a, b, words);
#endif
  return hamming_words_portable(a, b, words);
}

std::int32_t ternary_dot(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words,
                         PopcountKernel kernel) {
  require_multiple_of_4(plane_words);
  require_available(kernel);
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
  if (kernel == PopcountKernel::kAvx512) return ternary_dot_avx512(a, b, plane_words);
  if (kernel == PopcountKernel::kAvx2) return ternary_dot_avx2(a, b, plane_words);
#endif
  return ternary_dot_portable(a, b, plane_words);
}

std::int32_t int2_pair_term(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words,
                            PopcountKernel kernel) {
  require_multiple_of_4(plane_words);
  require_available(kernel);
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
  if (kernel == PopcountKernel::kAvx512) return int2_pair_term_avx512(a, b, plane_words);
  if (kernel == PopcountKernel::kAvx2) return int2_pair_term_avx2(a, b, plane_words);
#endif
  return int2_pair_term_portable(a, b, plane_words);
}

std::int32_t hamming_words(const std::uint64_t* a, const std::uint64_t* b, std::size_t words) {
  return hamming_words(a, b, words, kBest);
}

std::int32_t ternary_dot(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words) {
  return ternary_dot(a, b, plane_words, kBest);
}

namespace {

// The distances of every code from its kernel's integers (one definition for the pair and the row paths).
inline double cosine_from(double dot, double norm2_a, double norm2_b) {
  const double c = dot / std::sqrt(norm2_a * norm2_b);
  return 1.0 - std::clamp(c, -1.0, 1.0);
}

inline double sign_distance_of(std::int32_t hamming) {
  return 2.0 * hamming / static_cast<double>(kDirdBytes);
}

inline double ternary_distance_of(std::int32_t dot, std::int32_t nonzero_a, std::int32_t nonzero_b) {
  if (nonzero_a == 0 || nonzero_b == 0) return 1.0;
  return cosine_from(dot, static_cast<double>(nonzero_a), static_cast<double>(nonzero_b));
}

inline double int2_norm2(std::int32_t magnitude) {
  return static_cast<double>(kDirdBytes) + 8.0 * magnitude;
}

inline double int2_distance_of(std::int32_t pair_term, std::int32_t magnitude_a, std::int32_t magnitude_b) {
  const std::int64_t dot = static_cast<std::int64_t>(kDirdBytes) +
                           2 * static_cast<std::int64_t>(magnitude_a) +
                           2 * static_cast<std::int64_t>(magnitude_b) + pair_term;
  return cosine_from(static_cast<double>(dot), int2_norm2(magnitude_a), int2_norm2(magnitude_b));
}

}  // namespace

double sign_code_distance(const std::uint64_t* a, const std::uint64_t* b) {
  return sign_distance_of(hamming_words(a, b, kCodePlaneWords));
}

double ternary_code_distance(const std::uint64_t* a, std::int32_t nonzero_a, const std::uint64_t* b,
                             std::int32_t nonzero_b) {
  if (nonzero_a == 0 || nonzero_b == 0) return 1.0;
  return ternary_distance_of(ternary_dot(a, b, kCodePlaneWords), nonzero_a, nonzero_b);
}

double int2_code_distance(const std::uint64_t* a, std::int32_t magnitude_a, const std::uint64_t* b,
                          std::int32_t magnitude_b) {
  return int2_distance_of(int2_pair_term(a, b, kCodePlaneWords, kBest), magnitude_a, magnitude_b);
}

// ---------------------------------------------------------------------------------------------------------
// CompactCodeMatrix

CompactCodeMatrix::CompactCodeMatrix(const DirdCodeConfig& config, double clamp_sigma, std::size_t capacity)
    : config_(config),
      clamp_sigma_(clamp_sigma),
      capacity_(capacity),
      words_(code_words(config.code)),
      kernel_(best_popcount_kernel()),
      bits_(new std::uint64_t[capacity * words_]),
      count_(new std::int32_t[config.code == DirdCode::kSign ? 0 : capacity]),
      row_of_(new std::uint32_t[capacity]) {
  config_.validate();
  if (words_ == 0) throw std::invalid_argument("CompactCodeMatrix: int8 is not a compact code");
  if (capacity >= kNoRow) throw std::invalid_argument("CompactCodeMatrix: capacity beyond 2^32 - 1 frames");
  std::fill_n(row_of_.get(), capacity, kNoRow);
}

std::size_t CompactCodeMatrix::row_index(std::size_t seq, bool create) {
  if (seq >= capacity_) {
    throw std::out_of_range("CompactCodeMatrix: seq " + std::to_string(seq) + " beyond capacity " +
                            std::to_string(capacity_));
  }
  if (row_of_[seq] == kNoRow) {
    if (!create) throw std::logic_error("CompactCodeMatrix: seq " + std::to_string(seq) + " not coded");
    row_of_[seq] = static_cast<std::uint32_t>(rows_++);
  }
  return row_of_[seq];
}

std::size_t CompactCodeMatrix::row_index(std::size_t seq) const {
  if (seq >= capacity_ || row_of_[seq] == kNoRow)
    throw std::logic_error("CompactCodeMatrix: seq " + std::to_string(seq) + " not coded");
  return row_of_[seq];
}

void CompactCodeMatrix::store_count(std::size_t row, std::int32_t count) {
  if (config_.code != DirdCode::kSign) count_[row] = count;
}

void CompactCodeMatrix::set(std::size_t seq, const Descriptor& standard) {
  const std::size_t row = row_index(seq, true);
  store_count(row, make_compact_code(config_, clamp_sigma_, standard, bits_.get() + row * words_));
}

void CompactCodeMatrix::set(std::size_t seq, CausalCompactCoder& coder, std::int64_t frame,
                            const Descriptor& raw) {
  const std::size_t row = row_index(seq, true);
  store_count(row, coder.code(frame, raw, bits_.get() + row * words_));
}

double CompactCodeMatrix::distance(std::size_t a, const CompactCodeMatrix& other, std::size_t b) const {
  const std::size_t ra = row_index(a), rb = other.row_index(b);
  const std::uint64_t* ca = bits_.get() + ra * words_;
  const std::uint64_t* cb = other.bits_.get() + rb * other.words_;
  switch (config_.code) {
    case DirdCode::kSign: return sign_distance_of(hamming_words(ca, cb, kCodePlaneWords, kernel_));
    case DirdCode::kTernary: {
      if (count_[ra] == 0 || other.count_[rb] == 0) return 1.0;
      return ternary_distance_of(ternary_dot(ca, cb, kCodePlaneWords, kernel_), count_[ra], other.count_[rb]);
    }
    case DirdCode::kInt2:
      return int2_distance_of(int2_pair_term(ca, cb, kCodePlaneWords, kernel_), count_[ra], other.count_[rb]);
    case DirdCode::kInt8: break;
  }
  return 1.0;
}

namespace {

// One pass over the rows of frames [j_begin, j_end) of a matrix (row_of: the row of each frame): `pair` is
// the kernel of one (query, row) pair, given the row's code and index, inlined into the loop with the query's
// words staying in cache.
template <class Pair>
inline void row_pass(const std::uint64_t* bits, std::size_t words, const std::uint32_t* row_of,
                     std::size_t j_begin, std::size_t j_end, const std::uint8_t* coded, double* out,
                     Pair pair) {
  for (std::size_t j = j_begin; j < j_end; ++j) {
    if (!coded[j]) continue;
    const std::uint32_t r = row_of[j];
    if (r == 0xffffffffu)
      throw std::logic_error("CompactCodeMatrix::distances: seq " + std::to_string(j) + " not coded");
    out[j - j_begin] = pair(bits + static_cast<std::size_t>(r) * words, r);
  }
}

#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
LOOPGATE_AVX512_TARGET void row_avx512(DirdCode code, const std::uint64_t* bits, std::size_t words,
                                       const std::int32_t* count, const std::uint32_t* row_of, std::size_t qa,
                                       std::size_t j_begin, std::size_t j_end, const std::uint8_t* coded,
                                       double* out) {
  const std::uint64_t* q = bits + qa * words;
  switch (code) {
    case DirdCode::kSign:
      row_pass(bits, words, row_of, j_begin, j_end, coded, out, [&](const std::uint64_t* c, std::size_t) {
        return sign_distance_of(hamming_words_avx512(q, c, kCodePlaneWords));
      });
      break;
    case DirdCode::kTernary:
      row_pass(bits, words, row_of, j_begin, j_end, coded, out, [&](const std::uint64_t* c, std::size_t r) {
        if (count[qa] == 0 || count[r] == 0) return 1.0;
        return ternary_distance_of(ternary_dot_avx512(q, c, kCodePlaneWords), count[qa], count[r]);
      });
      break;
    case DirdCode::kInt2:
      row_pass(bits, words, row_of, j_begin, j_end, coded, out, [&](const std::uint64_t* c, std::size_t r) {
        return int2_distance_of(int2_pair_term_avx512(q, c, kCodePlaneWords), count[qa], count[r]);
      });
      break;
    case DirdCode::kInt8: break;
  }
}
#pragma GCC diagnostic pop
#endif

}  // namespace

void CompactCodeMatrix::distances(std::size_t a, std::size_t j_begin, std::size_t j_end,
                                  const std::uint8_t* coded, double* out) const {
  if (a >= capacity_ || j_end > capacity_)
    throw std::out_of_range("CompactCodeMatrix::distances: beyond capacity");
  const std::size_t qa = row_index(a);
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
  if (kernel_ == PopcountKernel::kAvx512) {
    row_avx512(config_.code, bits_.get(), words_, count_.get(), row_of_.get(), qa, j_begin, j_end, coded,
               out);
    return;
  }
#endif
  const std::uint64_t* q = bits_.get() + qa * words_;
  row_pass(
      bits_.get(), words_, row_of_.get(), j_begin, j_end, coded, out,
      [&](const std::uint64_t* c, std::size_t r) {
        switch (config_.code) {
          case DirdCode::kSign: return sign_distance_of(hamming_words(q, c, kCodePlaneWords, kernel_));
          case DirdCode::kTernary:
            if (count_[qa] == 0 || count_[r] == 0) return 1.0;
            return ternary_distance_of(ternary_dot(q, c, kCodePlaneWords, kernel_), count_[qa], count_[r]);
          case DirdCode::kInt2:
            return int2_distance_of(int2_pair_term(q, c, kCodePlaneWords, kernel_), count_[qa], count_[r]);
          case DirdCode::kInt8: break;
        }
        return 1.0;
      });
}

}  // namespace loopgate
