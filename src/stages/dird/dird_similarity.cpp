#include "stages/dird/dird_similarity.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LOOPGATE_DIRD_AVX2_DISPATCH 1
#endif

namespace loopgate {

namespace {

#if defined(__SSE2__)
constexpr std::size_t kChunk = 16;
constexpr std::size_t kChunks = kDirdBytes / kChunk;  // 216
static_assert(kDirdBytes % kChunk == 0);

inline std::uint32_t horizontal_sum(__m128i acc) {
  return static_cast<std::uint32_t>(_mm_cvtsi128_si32(acc)) +
         static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_srli_si128(acc, 8)));
}

// L1 distances of kGroup descriptors `a[g]` to one descriptor `b` (each 16-byte chunk of b loaded once).
template <int kGroup>
inline void l1_group(const std::uint8_t* const* a, const std::uint8_t* b, std::uint32_t* out) {
  __m128i acc[kGroup];
  for (int g = 0; g < kGroup; ++g) acc[g] = _mm_setzero_si128();
  for (std::size_t k = 0; k < kChunks; ++k) {
    const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k * kChunk));
    for (int g = 0; g < kGroup; ++g) {
      const __m128i va = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a[g] + k * kChunk));
      acc[g] = _mm_add_epi64(acc[g], _mm_sad_epu8(va, vb));
    }
  }
  for (int g = 0; g < kGroup; ++g) out[g] = horizontal_sum(acc[g]);
}
#else
template <int kGroup>
inline void l1_group(const std::uint8_t* const* a, const std::uint8_t* b, std::uint32_t* out) {
  for (int g = 0; g < kGroup; ++g) {
    std::uint32_t sum = 0;
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      const int d = static_cast<int>(a[g][k]) - static_cast<int>(b[k]);
      sum += static_cast<std::uint32_t>(d < 0 ? -d : d);
    }
    out[g] = sum;
  }
}
#endif

#if defined(LOOPGATE_DIRD_AVX2_DISPATCH)
// The same distances with 32-byte vpsadbw, compiled for AVX2 and chosen at run time when the CPU has it
// (the library itself stays baseline x86-64). Integer results are identical.
constexpr std::size_t kChunk32 = 32;
constexpr std::size_t kChunks32 = kDirdBytes / kChunk32;  // 108
static_assert(kDirdBytes % kChunk32 == 0);

template <int kGroup>
__attribute__((target("avx2"))) void l1_group_avx2(const std::uint8_t* const* a, const std::uint8_t* b,
                                                   std::uint32_t* out) {
  __m256i acc[kGroup];
  for (int g = 0; g < kGroup; ++g) acc[g] = _mm256_setzero_si256();
  for (std::size_t k = 0; k < kChunks32; ++k) {
    const __m256i vb = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + k * kChunk32));
    for (int g = 0; g < kGroup; ++g) {
      const __m256i va = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a[g] + k * kChunk32));
      acc[g] = _mm256_add_epi64(acc[g], _mm256_sad_epu8(va, vb));
    }
  }
  for (int g = 0; g < kGroup; ++g) {
    const __m128i sum = _mm_add_epi64(_mm256_castsi256_si128(acc[g]), _mm256_extracti128_si256(acc[g], 1));
    out[g] = static_cast<std::uint32_t>(_mm_cvtsi128_si32(sum)) +
             static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_srli_si128(sum, 8)));
  }
}

__attribute__((target("avx2"))) inline std::uint32_t horizontal_sum_avx2(__m256i acc) {
  const __m128i sum = _mm_add_epi64(_mm256_castsi256_si128(acc), _mm256_extracti128_si256(acc, 1));
  return static_cast<std::uint32_t>(_mm_cvtsi128_si32(sum)) +
         static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_srli_si128(sum, 8)));
}

// kGroup descriptors a[g] against two descriptors b0, b1: out[g] (b0) and out[kGroup + g] (b1).
// Bounded: each out value is the exact distance when it is <= limit, otherwise some value > limit (the
// partial sums are lower bounds, so the loop stops early once all of them exceed the limit).
constexpr std::size_t kEarlyExitBlocks = 4;
static_assert(kChunks32 % kEarlyExitBlocks == 0);

template <int kGroup>
__attribute__((target("avx2"))) void l1_group2_avx2(const std::uint8_t* const* a, const std::uint8_t* b0,
                                                    const std::uint8_t* b1, std::uint32_t limit,
                                                    std::uint32_t* out) {
  __m256i acc0[kGroup];
  __m256i acc1[kGroup];
  for (int g = 0; g < kGroup; ++g) acc0[g] = acc1[g] = _mm256_setzero_si256();
  constexpr std::size_t kBlock = kChunks32 / kEarlyExitBlocks;
  for (std::size_t block = 0; block < kEarlyExitBlocks; ++block) {
    for (std::size_t k = block * kBlock; k < (block + 1) * kBlock; ++k) {
      const __m256i vb0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b0 + k * kChunk32));
      const __m256i vb1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b1 + k * kChunk32));
      for (int g = 0; g < kGroup; ++g) {
        const __m256i va = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a[g] + k * kChunk32));
        acc0[g] = _mm256_add_epi64(acc0[g], _mm256_sad_epu8(va, vb0));
        acc1[g] = _mm256_add_epi64(acc1[g], _mm256_sad_epu8(va, vb1));
      }
    }
    bool all_above = true;
    for (int g = 0; g < kGroup; ++g) {
      out[g] = horizontal_sum_avx2(acc0[g]);
      out[kGroup + g] = horizontal_sum_avx2(acc1[g]);
      all_above = all_above && out[g] > limit && out[kGroup + g] > limit;
    }
    if (all_above) return;
  }
}

const bool kHasAvx2 = __builtin_cpu_supports("avx2");
#endif

template <int kGroup>
inline void l1_distances2(const std::uint8_t* const* a, const std::uint8_t* b0, const std::uint8_t* b1,
                          std::uint32_t limit, std::uint32_t* out) {
#if defined(LOOPGATE_DIRD_AVX2_DISPATCH)
  if (kHasAvx2) {
    l1_group2_avx2<kGroup>(a, b0, b1, limit, out);
    return;
  }
#endif
  static_cast<void>(limit);  // the SSE2 path computes exact distances
  l1_group<kGroup>(a, b0, out);
  l1_group<kGroup>(a, b1, out + kGroup);
}

template <int kGroup>
inline void l1_distances(const std::uint8_t* const* a, const std::uint8_t* b, std::uint32_t* out) {
#if defined(LOOPGATE_DIRD_AVX2_DISPATCH)
  if (kHasAvx2) {
    l1_group_avx2<kGroup>(a, b, out);
    return;
  }
#endif
  l1_group<kGroup>(a, b, out);
}

constexpr int kGroupSize = 4;

}  // namespace

std::uint32_t l1_distance(const Descriptor& a, const Descriptor& b) {
  const std::uint8_t* pa = a.data();
  std::uint32_t out = 0;
  l1_distances<1>(&pa, b.data(), &out);
  return out;
}

std::uint32_t l2_squared_distance(const Descriptor& a, const Descriptor& b) {
  std::uint32_t sum = 0;  // at most 3456 * 255^2 < 2^28
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    const int d = static_cast<int>(a[k]) - static_cast<int>(b[k]);
    sum += static_cast<std::uint32_t>(d * d);
  }
  return sum;
}

double l2_distance(const Descriptor& a, const Descriptor& b) {
  return std::sqrt(static_cast<double>(l2_squared_distance(a, b)));
}

double logistic_similarity(double distance, double mu, double sigma) {
  return 1.0 / (1.0 + std::exp((distance - mu) / sigma));
}

double logistic_distance_at(double similarity, double mu, double sigma) {
  if (!(similarity > 0.0 && similarity < 1.0)) {
    throw std::invalid_argument("logistic_distance_at: similarity must be in (0, 1)");
  }
  return mu + sigma * std::log(1.0 / similarity - 1.0);
}

DirdSimilarity::DirdSimilarity(const DirdConfig& config) : config_(config) {
  config_.validate();
  l2_metric_ = config_.l2_metric();
  const double cut = logistic_distance_at(config_.tau1, config_.mu, config_.sigma);
  // Generous by one distance unit plus rounding: the exact test sim > tau1 decides.
  cutoff_distance_ = cut + 1.0 + 1e-9 * std::fabs(cut);
}

double DirdSimilarity::distance(const Descriptor& a, const Descriptor& b) const {
  return l2_metric_ ? l2_distance(a, b) : static_cast<double>(l1_distance(a, b));
}

double DirdSimilarity::similarity_from_distance(double distance) const {
  return logistic_similarity(distance, config_.mu, config_.sigma);
}

double DirdSimilarity::similarity(const Descriptor& a, const Descriptor& b) const {
  return similarity_from_distance(distance(a, b));
}

void DirdSimilarity::sparse_row(const Descriptor& current, const Descriptor* earlier, std::size_t count,
                                std::int64_t j_offset, std::vector<SimilarityEntry>& out) const {
  for (std::size_t j = 0; j < count; ++j) {
    const double d = distance(current, earlier[j]);
    if (d > cutoff_distance_) continue;
    const double sim = similarity_from_distance(d);
    if (keeps(sim)) out.push_back({static_cast<std::int64_t>(j) + j_offset, sim});
  }
}

void DirdSimilarity::sparse_columns(std::span<const Descriptor> descriptors, std::int64_t margin,
                                    std::size_t i_begin, std::size_t i_end,
                                    std::span<std::vector<SimilarityEntry>> columns) const {
  if (i_end < i_begin || i_end > descriptors.size() || columns.size() != i_end - i_begin || margin < 0) {
    throw std::invalid_argument("DirdSimilarity::sparse_columns: bad range");
  }
  for (auto& column : columns) column.clear();
  // Number of earlier frames j in [0, i - margin] compared with current frame i.
  auto span_of = [margin](std::size_t i) -> std::size_t {
    const std::int64_t n = static_cast<std::int64_t>(i) - margin + 1;
    return n > 0 ? static_cast<std::size_t>(n) : 0;
  };
  std::size_t i = i_begin;
  if (!l2_metric_) {
    for (; i + kGroupSize <= i_end; i += kGroupSize) {
      const std::size_t common = span_of(i);
      const std::uint8_t* group[kGroupSize];
      for (int g = 0; g < kGroupSize; ++g) group[g] = descriptors[i + static_cast<std::size_t>(g)].data();
      std::uint32_t d[2 * kGroupSize];
      // Distances above the (generous) cut-off only need to be known to be above it.
      const std::uint32_t limit = cutoff_distance_ >= static_cast<double>(kDirdBytes * 255u)
                                      ? static_cast<std::uint32_t>(kDirdBytes * 255u)
                                      : static_cast<std::uint32_t>(std::max(0.0, cutoff_distance_));
      auto store = [&](std::size_t j, const std::uint32_t* dist_j) {
        for (int g = 0; g < kGroupSize; ++g) {
          const double dist = static_cast<double>(dist_j[g]);
          if (dist > cutoff_distance_) continue;
          const double sim = similarity_from_distance(dist);
          if (keeps(sim)) {
            columns[i - i_begin + static_cast<std::size_t>(g)].push_back({static_cast<std::int64_t>(j), sim});
          }
        }
      };
      std::size_t j = 0;
      for (; j + 2 <= common; j += 2) {
        l1_distances2<kGroupSize>(group, descriptors[j].data(), descriptors[j + 1].data(), limit, d);
        store(j, d);
        store(j + 1, d + kGroupSize);
      }
      for (; j < common; ++j) {
        l1_distances<kGroupSize>(group, descriptors[j].data(), d);
        store(j, d);
      }
      for (int g = 1; g < kGroupSize; ++g) {
        const std::size_t ig = i + static_cast<std::size_t>(g);
        const std::size_t total = span_of(ig);
        sparse_row(descriptors[ig], descriptors.data() + common, total - common,
                   static_cast<std::int64_t>(common), columns[ig - i_begin]);
      }
    }
  }
  for (; i < i_end; ++i) sparse_row(descriptors[i], descriptors.data(), span_of(i), 0, columns[i - i_begin]);
}

}  // namespace loopgate
