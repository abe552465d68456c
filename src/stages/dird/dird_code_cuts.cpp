// Coding from the raw descriptor (dird_codes.hpp): the cuts of a causal snapshot, the code of a raw
// descriptor from its cuts, and the causal coder that keeps the snapshots.
#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <stdexcept>
#include <string>

#include "stages/dird/dird_codes.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LOOPGATE_CODES_SIMD_DISPATCH 1
#endif

namespace loopgate {

// ---------------------------------------------------------------------------------------------------------
// Coding from the raw descriptor

std::size_t code_cuts(DirdCode code) {
  switch (code) {
    case DirdCode::kSign: return 1;
    case DirdCode::kTernary: return 2;
    case DirdCode::kInt2: return 3;
    case DirdCode::kInt8: break;
  }
  return 0;
}

namespace {

// For every dimension k, the first raw byte x in [0, 256] for which fires(k, code of x) holds, the predicate
// monotonic in x (false then true); 256 when none. A search in lockstep over all dimensions, each step one
// Standardization::apply of a probe descriptor: the codes are those of apply itself.
template <class Fires>
void first_firing(const Standardization& statistics, Fires fires,
                  std::array<std::uint16_t, kDirdBytes>& first) {
  std::array<std::uint16_t, kDirdBytes> lo{}, hi{};
  hi.fill(256);
  Descriptor probe, codes;
  for (int step = 0; step < 9; ++step) {
    for (std::size_t k = 0; k < kDirdBytes; ++k)
      probe[k] = static_cast<std::uint8_t>(std::min<int>(255, (lo[k] + hi[k]) / 2));
    statistics.apply(probe, codes);
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      if (lo[k] >= hi[k]) continue;
      const int mid = (lo[k] + hi[k]) / 2;  // < 256 while lo < hi
      if (fires(codes[k] - static_cast<int>(kStandardCodeZero)))
        hi[k] = static_cast<std::uint16_t>(mid);
      else
        lo[k] = static_cast<std::uint16_t>(mid + 1);
    }
  }
  for (std::size_t k = 0; k < kDirdBytes; ++k) first[k] = lo[k];
}

}  // namespace

void make_code_cuts(const Standardization& statistics, const DirdCodeConfig& config, std::uint8_t* out) {
  const std::size_t cuts = code_cuts(config.code);
  if (cuts == 0) throw std::invalid_argument("make_code_cuts: int8 is not a compact code");
  const double clamp_sigma = statistics.clamp_sigma();
  std::array<std::uint16_t, kDirdBytes> first{};
  // above cut u: the bit fires for x > u, u = first firing byte - 1 (the code of byte 0 is <= 0 < the
  // threshold: first >= 1, so u in [0, 255], 255 = never).
  const auto above = [&](int threshold, std::uint8_t* cut) {
    first_firing(
        statistics, [threshold](int c) { return c >= threshold; }, first);
    for (std::size_t k = 0; k < kDirdBytes; ++k) cut[k] = static_cast<std::uint8_t>(first[k] - 1);
  };
  // below cut w: the bit fires for x < w, w = first byte whose code is above -threshold (the code of byte
  // 255 is >= 0: w <= 255; 0 = never).
  const auto below = [&](int threshold, std::uint8_t* cut) {
    first_firing(
        statistics, [threshold](int c) { return c > -threshold; }, first);
    for (std::size_t k = 0; k < kDirdBytes; ++k) cut[k] = static_cast<std::uint8_t>(first[k]);
  };
  switch (config.code) {
    case DirdCode::kSign: above(1, out); break;
    case DirdCode::kTernary: {
      const int t = code_threshold(config.ternary_threshold_sigma, clamp_sigma);
      above(t, out);
      below(t, out + kDirdBytes);
      break;
    }
    case DirdCode::kInt2: {
      const int t = code_threshold(config.int2_threshold_sigma, clamp_sigma);
      above(1, out);
      above(t, out + kDirdBytes);
      below(t, out + 2 * kDirdBytes);
      break;
    }
    case DirdCode::kInt8: break;
  }
}

namespace {

// The bits of one plane: bit k = raw[k] > above[k] (above given), or raw[k] < below[k] (below given), or
// either. Portable: one dimension at a time.
void plane_portable(const Descriptor& raw, const std::uint8_t* above, const std::uint8_t* below,
                    std::uint64_t* out) {
  std::memset(out, 0, kCodePlaneWords * sizeof(std::uint64_t));
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    const bool fires = (above && raw[k] > above[k]) || (below && raw[k] < below[k]);
    if (fires) out[k / 64] |= std::uint64_t{1} << (k % 64);
  }
}

#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
// 32 dimensions at a time: unsigned byte comparisons as signed ones after flipping the top bit, movemask
// to 32 bits.
__attribute__((target("avx2"))) void plane_avx2(const Descriptor& raw, const std::uint8_t* above,
                                                const std::uint8_t* below, std::uint64_t* out) {
  std::memset(out, 0, kCodePlaneWords * sizeof(std::uint64_t));
  const __m256i flip = _mm256_set1_epi8(static_cast<char>(0x80));
  auto* out32 = reinterpret_cast<std::uint32_t*>(out);
  static_assert(kDirdBytes % 32 == 0);
  for (std::size_t k = 0; k < kDirdBytes; k += 32) {
    const __m256i x =
        _mm256_xor_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(raw.data() + k)), flip);
    __m256i fires = _mm256_setzero_si256();
    if (above) {
      const __m256i u =
          _mm256_xor_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(above + k)), flip);
      fires = _mm256_or_si256(fires, _mm256_cmpgt_epi8(x, u));
    }
    if (below) {
      const __m256i w =
          _mm256_xor_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(below + k)), flip);
      fires = _mm256_or_si256(fires, _mm256_cmpgt_epi8(w, x));
    }
    std::uint32_t bits = static_cast<std::uint32_t>(_mm256_movemask_epi8(fires));
    std::memcpy(out32 + k / 32, &bits, sizeof bits);  // little-endian: bit k of the plane
  }
}
#endif

std::int32_t plane_count(const std::uint64_t* plane) {
  std::int32_t n = 0;
  for (std::size_t k = 0; k < kCodePlaneWords; ++k) n += std::popcount(plane[k]);
  return n;
}

}  // namespace

std::int32_t code_from_cuts(DirdCode code, const std::uint8_t* cuts, const Descriptor& raw,
                            std::uint64_t* out, PopcountKernel kernel) {
  if (!popcount_kernel_available(kernel)) {
    throw std::invalid_argument(std::string("code_from_cuts: this CPU does not run the ") +
                                std::string(enum_name(kernel)) + " kernel");
  }
  auto plane = plane_portable;
#if defined(LOOPGATE_CODES_SIMD_DISPATCH)
  if (kernel != PopcountKernel::kPortable) plane = plane_avx2;
#endif
  switch (code) {
    case DirdCode::kSign: plane(raw, cuts, nullptr, out); return static_cast<std::int32_t>(kDirdBytes);
    case DirdCode::kTernary:
      plane(raw, cuts, nullptr, out);
      plane(raw, nullptr, cuts + kDirdBytes, out + kCodePlaneWords);
      return plane_count(out) + plane_count(out + kCodePlaneWords);
    case DirdCode::kInt2:
      plane(raw, cuts, nullptr, out);
      plane(raw, cuts + kDirdBytes, cuts + 2 * kDirdBytes, out + kCodePlaneWords);
      return plane_count(out + kCodePlaneWords);
    case DirdCode::kInt8: break;
  }
  throw std::invalid_argument("code_from_cuts: int8 is not a compact code");
}

std::int32_t code_from_cuts(DirdCode code, const std::uint8_t* cuts, const Descriptor& raw,
                            std::uint64_t* out) {
  return code_from_cuts(code, cuts, raw, out, best_popcount_kernel());
}

// ---------------------------------------------------------------------------------------------------------
// CausalCompactCoder

CausalCompactCoder::CausalCompactCoder(const StandardizeConfig& observations, const DirdCodeConfig& codes)
    : config_(observations),
      codes_(codes),
      schedule_(observations),
      moments_(observations.window),
      scratch_(code_cuts(codes.code) * kDirdBytes),
      cuts_(std::max<std::size_t>(1, scratch_.size())) {
  codes_.validate();
  if (scratch_.empty()) throw std::invalid_argument("CausalCompactCoder: int8 is not a compact code");
}

void CausalCompactCoder::observe(std::int64_t frame, const Descriptor& raw) {
  const bool snapshot = schedule_.observe(frame, moments_.added() + 1);
  moments_.add(raw);
  if (!snapshot) return;
  make_code_cuts(Standardization(moments_, config_), codes_, scratch_.data());
  cuts_.push(scratch_.data());
}

std::int32_t CausalCompactCoder::code(std::int64_t frame, const Descriptor& raw, std::uint64_t* out) {
  const std::size_t index = schedule_.standardize(frame, moments_.added());
  return code_from_cuts(codes_.code, cuts_.cuts(index), raw, out);
}

}  // namespace loopgate
