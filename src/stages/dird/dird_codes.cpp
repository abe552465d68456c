#include "stages/dird/dird_codes.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "core/error.hpp"
#include "stages/dird/dird_standardize.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LOOPGATE_CODES_AVX2_DISPATCH 1
#endif

namespace loopgate {

void DirdCodeConfig::validate() const {
  if (!(std::isfinite(ternary_threshold_sigma) && ternary_threshold_sigma > 0.0 &&
        ternary_threshold_sigma <= 4.0)) {
    throw ConfigError("dird_seqslam.ternary_threshold_sigma: must be in (0, 4] standard deviations (got " +
                      std::to_string(ternary_threshold_sigma) + ")");
  }
}

std::size_t code_words(DirdCode code) {
  switch (code) {
    case DirdCode::kSign: return kCodePlaneWords;
    case DirdCode::kTernary: return 2 * kCodePlaneWords;
    case DirdCode::kInt8: break;
  }
  return 0;
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
  // Ternary: |code| >= the threshold in code units (at least 1, so code 0 is never a plus or a minus).
  const int threshold = std::max(
      1, static_cast<int>(std::lround(kStandardCodeMax * config.ternary_threshold_sigma / clamp_sigma)));
  std::uint64_t* plus = out;
  std::uint64_t* minus = out + kCodePlaneWords;
  std::int32_t nonzero = 0;
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    const int c = static_cast<int>(standard[k]) - kStandardCodeZero;
    const std::uint64_t bit = std::uint64_t{1} << (k % 64);
    if (c >= threshold) {
      plus[k / 64] |= bit;
      ++nonzero;
    } else if (c <= -threshold) {
      minus[k / 64] |= bit;
      ++nonzero;
    }
  }
  return nonzero;
}

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

#if defined(LOOPGATE_CODES_AVX2_DISPATCH)
// Bit counts of the 32 bytes of x: a 16-entry table of nibble counts looked up with pshufb for the low and
// the high nibble of every byte.
__attribute__((target("avx2"))) inline __m256i byte_popcounts(__m256i x) {
  const __m256i table = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2, 1, 2, 2,
                                         3, 1, 2, 2, 3, 2, 3, 3, 4);
  const __m256i low_mask = _mm256_set1_epi8(0x0f);
  const __m256i lo = _mm256_and_si256(x, low_mask);
  const __m256i hi = _mm256_and_si256(_mm256_srli_epi16(x, 4), low_mask);
  return _mm256_add_epi8(_mm256_shuffle_epi8(table, lo), _mm256_shuffle_epi8(table, hi));
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

// psadbw against zero adds the byte counts (at most 8 each) into the 64-bit lanes: no overflow at any length.
__attribute__((target("avx2"))) std::int32_t hamming_words_avx2(const std::uint64_t* a,
                                                                const std::uint64_t* b, std::size_t words) {
  const __m256i zero = _mm256_setzero_si256();
  __m256i acc = _mm256_setzero_si256();
  for (std::size_t k = 0; k < words; k += 4) {
    const __m256i counts = byte_popcounts(_mm256_xor_si256(load(a + k), load(b + k)));
    acc = _mm256_add_epi64(acc, _mm256_sad_epu8(counts, zero));
  }
  return static_cast<std::int32_t>(lane_sum(acc));
}

__attribute__((target("avx2"))) std::int32_t ternary_dot_avx2(const std::uint64_t* a, const std::uint64_t* b,
                                                              std::size_t plane_words) {
  const __m256i zero = _mm256_setzero_si256();
  __m256i same_acc = _mm256_setzero_si256();
  __m256i opposite_acc = _mm256_setzero_si256();
  for (std::size_t k = 0; k < plane_words; k += 4) {
    const __m256i ap = load(a + k), am = load(a + plane_words + k);
    const __m256i bp = load(b + k), bm = load(b + plane_words + k);
    const __m256i same = _mm256_or_si256(_mm256_and_si256(ap, bp), _mm256_and_si256(am, bm));
    const __m256i opposite = _mm256_or_si256(_mm256_and_si256(ap, bm), _mm256_and_si256(am, bp));
    same_acc = _mm256_add_epi64(same_acc, _mm256_sad_epu8(byte_popcounts(same), zero));
    opposite_acc = _mm256_add_epi64(opposite_acc, _mm256_sad_epu8(byte_popcounts(opposite), zero));
  }
  return static_cast<std::int32_t>(lane_sum(same_acc) - lane_sum(opposite_acc));
}

const bool kHasAvx2 = __builtin_cpu_supports("avx2");
#endif

void require_multiple_of_4(std::size_t words) {
  if (words % 4 != 0) throw std::invalid_argument("compact code kernels: words must be a multiple of 4");
}

}  // namespace

std::int32_t hamming_words(const std::uint64_t* a, const std::uint64_t* b, std::size_t words) {
  require_multiple_of_4(words);
#if defined(LOOPGATE_CODES_AVX2_DISPATCH)
  if (kHasAvx2) return hamming_words_avx2(a, b, words);
#endif
  return hamming_words_portable(a, b, words);
}

std::int32_t ternary_dot(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words) {
  require_multiple_of_4(plane_words);
#if defined(LOOPGATE_CODES_AVX2_DISPATCH)
  if (kHasAvx2) return ternary_dot_avx2(a, b, plane_words);
#endif
  return ternary_dot_portable(a, b, plane_words);
}

bool compact_codes_use_avx2() {
#if defined(LOOPGATE_CODES_AVX2_DISPATCH)
  return kHasAvx2;
#else
  return false;
#endif
}

double sign_code_distance(const std::uint64_t* a, const std::uint64_t* b) {
  return 2.0 * hamming_words(a, b, kCodePlaneWords) / static_cast<double>(kDirdBytes);
}

double ternary_code_distance(const std::uint64_t* a, std::int32_t nonzero_a, const std::uint64_t* b,
                             std::int32_t nonzero_b) {
  if (nonzero_a == 0 || nonzero_b == 0) return 1.0;
  const double dot = ternary_dot(a, b, kCodePlaneWords);
  const double c = dot / std::sqrt(static_cast<double>(nonzero_a) * static_cast<double>(nonzero_b));
  return 1.0 - std::clamp(c, -1.0, 1.0);
}

CompactCodeMatrix::CompactCodeMatrix(const DirdCodeConfig& config, double clamp_sigma, std::size_t capacity)
    : config_(config),
      clamp_sigma_(clamp_sigma),
      capacity_(capacity),
      words_(code_words(config.code)),
      bits_(new std::uint64_t[capacity * words_]),
      nonzero_(new std::int32_t[config.code == DirdCode::kTernary ? capacity : 0]) {
  config_.validate();
  if (words_ == 0) throw std::invalid_argument("CompactCodeMatrix: int8 is not a compact code");
}

void CompactCodeMatrix::set(std::size_t seq, const Descriptor& standard) {
  if (seq >= capacity_) {
    throw std::out_of_range("CompactCodeMatrix: seq " + std::to_string(seq) + " beyond capacity " +
                            std::to_string(capacity_));
  }
  const std::int32_t nonzero = make_compact_code(config_, clamp_sigma_, standard, bits_.get() + seq * words_);
  if (config_.code == DirdCode::kTernary) nonzero_[seq] = nonzero;
}

double CompactCodeMatrix::distance(std::size_t a, const CompactCodeMatrix& other, std::size_t b) const {
  const std::uint64_t* ca = bits_.get() + a * words_;
  const std::uint64_t* cb = other.bits_.get() + b * other.words_;
  if (config_.code == DirdCode::kSign) return sign_code_distance(ca, cb);
  return ternary_code_distance(ca, nonzero_[a], cb, other.nonzero_[b]);
}

}  // namespace loopgate
