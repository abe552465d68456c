#include "stages/dird/dird_standardize.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/error.hpp"
#include "core/validate.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LOOPGATE_STANDARDIZE_AVX2_DISPATCH 1
#endif

namespace loopgate {

void StandardizeConfig::validate() const {
  if (!(clamp_sigma >= 0.5 && clamp_sigma <= 127.0)) {
    throw ConfigError("standardize.clamp_sigma: must be in [0.5, 127]");
  }
  if (!(std::isfinite(min_stddev) && min_stddev > 0.0 && min_stddev <= 128.0)) {
    throw ConfigError("standardize.min_stddev: must be in (0, 128] descriptor byte units (got " +
                      std::to_string(min_stddev) + ")");
  }
  // Counts bounded by what makes sense: a million frames is longer than any dataset.
  require_in("standardize.warm_up", warm_up, std::int64_t{2}, std::int64_t{1'000'000}, "observations");
  if (window != 0) {
    require(window >= warm_up && window <= 1'000'000, "standardize.window",
            "0 (all observations) or in [standardize.warm_up, 1000000] observations", std::to_string(window));
  }
  require_in("standardize.refresh_every", refresh_every, std::int64_t{1}, std::int64_t{1'000'000},
             "observations");
  require_in("standardize.observe_every", observe_every, std::int64_t{1}, std::int64_t{1'000'000}, "frames");
}

StandardizeConfig observations_config(const StandardizeConfig& config) {
  config.validate();
  const std::int64_t k = config.observe_every;
  const auto up = [k](std::int64_t frames) { return (frames + k - 1) / k; };
  StandardizeConfig out = config;
  out.warm_up = std::max<std::int64_t>(2, up(config.warm_up));
  out.window = config.window == 0 ? 0 : std::max(out.warm_up, up(config.window));
  out.refresh_every = up(config.refresh_every);
  out.observe_every = 1;
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// DescriptorMoments

DescriptorMoments::DescriptorMoments(std::int64_t window)
    : window_(window), sum_(kDirdBytes, 0), sum_squares_(kDirdBytes, 0) {
  if (window < 0) throw std::invalid_argument("DescriptorMoments: window must be >= 0");
}

void DescriptorMoments::add(const Descriptor& raw) {
  if (window_ > 0) {
    const std::size_t slot = static_cast<std::size_t>(added_ % window_);
    if (ring_.size() < static_cast<std::size_t>(window_)) {
      ring_.push_back(raw);
    } else {
      const Descriptor& old = ring_[slot];
      for (std::size_t k = 0; k < kDirdBytes; ++k) {
        const std::uint64_t x = old[k];
        sum_[k] -= x;
        sum_squares_[k] -= x * x;
      }
      ring_[slot] = raw;
      --count_;
    }
  }
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    const std::uint64_t x = raw[k];
    sum_[k] += x;
    sum_squares_[k] += x * x;
  }
  ++count_;
  ++added_;
}

double DescriptorMoments::mean(std::size_t dim) const {
  if (count_ == 0) return 0.0;
  return static_cast<double>(sum_.at(dim)) / static_cast<double>(count_);
}

double DescriptorMoments::variance(std::size_t dim) const {
  if (count_ == 0) return 0.0;
  const std::uint64_t s = sum_.at(dim);
  const std::uint64_t q = sum_squares_.at(dim);
  const std::uint64_t n = static_cast<std::uint64_t>(count_);
  const double n2 = static_cast<double>(n) * static_cast<double>(n);
  if (n <= (std::uint64_t{1} << 24)) {
    // n * q <= n^2 * 255^2 < 2^64: the numerator n * q - s^2 (>= 0, Cauchy-Schwarz) is exact.
    return static_cast<double>(n * q - s * s) / n2;
  }
  const double m = static_cast<double>(s) / static_cast<double>(n);
  return std::max(0.0, static_cast<double>(q) / static_cast<double>(n) - m * m);
}

// ---------------------------------------------------------------------------------------------------------
// Standardization

Standardization::Standardization(const DescriptorMoments& moments, const StandardizeConfig& config) {
  if (moments.count() < 1) throw std::invalid_argument("Standardization: no descriptors");
  auto table = std::make_shared<Table>();
  table->mean.resize(kDirdBytes);
  table->code_scale.resize(kDirdBytes);
  table->count = moments.count();
  table->clamp_sigma = config.clamp_sigma;
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    const double sd = std::max(std::sqrt(moments.variance(k)), config.min_stddev);
    table->mean[k] = static_cast<float>(moments.mean(k));
    table->code_scale[k] = static_cast<float>(kStandardCodeMax / (config.clamp_sigma * sd));
  }
  table_ = std::move(table);
}

namespace {

constexpr float kCodeMax = static_cast<float>(kStandardCodeMax);

// One code: clamp((x - mean) * scale) to +-127, then v + 128.5 in [1.5, 255.5] truncated (round half up).
inline std::uint8_t code_of(std::uint8_t x, float mean, float scale) {
  float v = (static_cast<float>(x) - mean) * scale;
  v = v < -kCodeMax ? -kCodeMax : v;
  v = v > kCodeMax ? kCodeMax : v;
  return static_cast<std::uint8_t>(static_cast<int>(v + 128.5f));
}

#if defined(__SSE2__)
// The same operations on 4 lanes (sub, mul, max, min, add, truncate): bit-identical codes.
inline __m128i codes_of4(__m128i x32, const float* mean, const float* scale) {
  __m128 v = _mm_mul_ps(_mm_sub_ps(_mm_cvtepi32_ps(x32), _mm_loadu_ps(mean)), _mm_loadu_ps(scale));
  v = _mm_min_ps(_mm_max_ps(v, _mm_set1_ps(-kCodeMax)), _mm_set1_ps(kCodeMax));
  return _mm_cvttps_epi32(_mm_add_ps(v, _mm_set1_ps(128.5f)));
}
#endif

}  // namespace

void Standardization::apply(const Descriptor& raw, Descriptor& codes) const {
  if (!table_) throw std::logic_error("Standardization::apply: no statistics");
  const float* mean = table_->mean.data();
  const float* scale = table_->code_scale.data();
#if defined(__SSE2__)
  const __m128i zero = _mm_setzero_si128();
  for (std::size_t k = 0; k < kDirdBytes; k += 16) {
    const __m128i bytes = _mm_loadu_si128(reinterpret_cast<const __m128i*>(raw.data() + k));
    const __m128i lo16 = _mm_unpacklo_epi8(bytes, zero);
    const __m128i hi16 = _mm_unpackhi_epi8(bytes, zero);
    const __m128i c0 = codes_of4(_mm_unpacklo_epi16(lo16, zero), mean + k, scale + k);
    const __m128i c1 = codes_of4(_mm_unpackhi_epi16(lo16, zero), mean + k + 4, scale + k + 4);
    const __m128i c2 = codes_of4(_mm_unpacklo_epi16(hi16, zero), mean + k + 8, scale + k + 8);
    const __m128i c3 = codes_of4(_mm_unpackhi_epi16(hi16, zero), mean + k + 12, scale + k + 12);
    // Codes are 1..255: the saturating packs are exact.
    const __m128i packed = _mm_packus_epi16(_mm_packs_epi32(c0, c1), _mm_packs_epi32(c2, c3));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(codes.data() + k), packed);
  }
  static_assert(kDirdBytes % 16 == 0);
#else
  for (std::size_t k = 0; k < kDirdBytes; ++k) codes[k] = code_of(raw[k], mean[k], scale[k]);
#endif
}

std::uint8_t Standardization::apply_one(std::size_t dim, std::uint8_t raw) const {
  if (!table_) throw std::logic_error("Standardization::apply_one: no statistics");
  return code_of(raw, table_->mean.at(dim), table_->code_scale.at(dim));
}

Descriptor Standardization::apply(const Descriptor& raw) const {
  Descriptor codes;
  apply(raw, codes);
  return codes;
}

void Standardization::apply_float(const Descriptor& raw, StandardizedFloat& z) const {
  if (!table_) throw std::logic_error("Standardization::apply_float: no statistics");
  const float* mean = table_->mean.data();
  const float* scale = table_->code_scale.data();
  const float to_z = static_cast<float>(table_->clamp_sigma / kStandardCodeMax);
  for (std::size_t k = 0; k < kDirdBytes; ++k)
    z[k] = (static_cast<float>(raw[k]) - mean[k]) * scale[k] * to_z;
}

std::int64_t Standardization::count() const {
  return table_ ? table_->count : 0;
}
float Standardization::mean(std::size_t dim) const {
  if (!table_) throw std::logic_error("Standardization::mean: no statistics");
  return table_->mean.at(dim);
}
double Standardization::stddev(std::size_t dim) const {
  if (!table_) throw std::logic_error("Standardization::stddev: no statistics");
  return kStandardCodeMax / (table_->clamp_sigma * static_cast<double>(table_->code_scale.at(dim)));
}
double Standardization::clamp_sigma() const {
  return table_ ? table_->clamp_sigma : 0.0;
}

Standardization standardization_of(std::span<const Descriptor> descriptors, const StandardizeConfig& config) {
  if (descriptors.empty()) throw std::invalid_argument("standardization_of: no descriptors");
  DescriptorMoments moments;
  for (const Descriptor& d : descriptors) moments.add(d);
  return Standardization(moments, config);
}

std::vector<Descriptor> standardize_batch(std::span<const Descriptor> descriptors,
                                          const StandardizeConfig& config) {
  const Standardization statistics = standardization_of(descriptors, config);
  std::vector<Descriptor> out(descriptors.size());
  for (std::size_t i = 0; i < descriptors.size(); ++i) statistics.apply(descriptors[i], out[i]);
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// CausalStandardizer

namespace {
constexpr std::int64_t kNoFrame = std::numeric_limits<std::int64_t>::min();
}

CausalSchedule::CausalSchedule(const StandardizeConfig& config)
    : warm_up_(config.warm_up),
      refresh_every_(config.refresh_every),
      last_observed_(kNoFrame),
      horizon_(kNoFrame) {
  config.validate();
}

bool CausalSchedule::observe(std::int64_t frame, std::int64_t observations) {
  if (frame <= last_observed_ || frame <= horizon_) {
    throw std::invalid_argument("CausalStandardizer::observe: frame " + std::to_string(frame) +
                                " is not after every frame observed or standardised before");
  }
  last_observed_ = frame;
  if (observations >= warm_up_ && (observations - warm_up_) % refresh_every_ == 0) {
    frames_.push_back(frame);
    return true;
  }
  return false;
}

std::size_t CausalSchedule::snapshot_for(std::int64_t frame, std::int64_t observations) const {
  if (frames_.empty()) {
    throw std::logic_error("CausalStandardizer: statistics not ready (" + std::to_string(observations) +
                           " of " + std::to_string(warm_up_) + " warm-up observations)");
  }
  // First snapshot with a frame > p; the one before it is the latest with frame <= p.
  const auto after = std::upper_bound(frames_.begin(), frames_.end(), frame);
  return after == frames_.begin() ? 0 : static_cast<std::size_t>(std::prev(after) - frames_.begin());
}

std::size_t CausalSchedule::standardize(std::int64_t frame, std::int64_t observations) {
  const std::size_t index = snapshot_for(frame, observations);
  horizon_ = std::max(horizon_, frame);
  return index;
}

CausalStandardizer::CausalStandardizer(const StandardizeConfig& config)
    : config_(config), schedule_(config), moments_(config.window) {}

void CausalStandardizer::observe(std::int64_t frame, const Descriptor& raw) {
  // The order check first: a rejected observation changes nothing.
  if (schedule_.observe(frame, moments_.added() + 1)) {
    moments_.add(raw);
    snapshots_.push_back(Standardization(moments_, config_));
  } else {
    moments_.add(raw);
  }
}

const Standardization& CausalStandardizer::statistics_for(std::int64_t frame) const {
  return snapshots_[schedule_.snapshot_for(frame, moments_.added())];
}

void CausalStandardizer::standardize(std::int64_t frame, const Descriptor& raw, Descriptor& codes) {
  snapshots_[schedule_.standardize(frame, moments_.added())].apply(raw, codes);
}

Descriptor CausalStandardizer::standardize(std::int64_t frame, const Descriptor& raw) {
  Descriptor codes;
  standardize(frame, raw, codes);
  return codes;
}

// ---------------------------------------------------------------------------------------------------------
// Distances

namespace {

// Integer dot product of the signed codes (integer sums: every path gives the same result).
[[maybe_unused]] std::int32_t dot_codes_scalar(const std::uint8_t* a, const std::uint8_t* b) {
  std::int32_t sum = 0;
  for (std::size_t k = 0; k < kDirdBytes; ++k) sum += (a[k] - 128) * (b[k] - 128);
  return sum;
}

#if defined(__SSE2__)
// Bytes -> int16 (zero-extended, minus 128) -> pmaddwd pairs into int32 lanes.
inline std::int32_t dot_codes_sse2(const std::uint8_t* a, const std::uint8_t* b) {
  const __m128i zero = _mm_setzero_si128();
  const __m128i offset = _mm_set1_epi16(128);
  __m128i acc0 = _mm_setzero_si128();
  __m128i acc1 = _mm_setzero_si128();
  for (std::size_t k = 0; k < kDirdBytes; k += 16) {
    const __m128i va = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k));
    const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k));
    const __m128i a_lo = _mm_sub_epi16(_mm_unpacklo_epi8(va, zero), offset);
    const __m128i a_hi = _mm_sub_epi16(_mm_unpackhi_epi8(va, zero), offset);
    const __m128i b_lo = _mm_sub_epi16(_mm_unpacklo_epi8(vb, zero), offset);
    const __m128i b_hi = _mm_sub_epi16(_mm_unpackhi_epi8(vb, zero), offset);
    acc0 = _mm_add_epi32(acc0, _mm_madd_epi16(a_lo, b_lo));
    acc1 = _mm_add_epi32(acc1, _mm_madd_epi16(a_hi, b_hi));
  }
  alignas(16) std::int32_t lanes[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(lanes), _mm_add_epi32(acc0, acc1));
  return lanes[0] + lanes[1] + lanes[2] + lanes[3];
}
#endif

// Float sums: element k goes to partial sum k mod 32, the 32 partials are added in one fixed order, so
// the SSE2 and AVX2 paths give bit-identical results.
constexpr std::size_t kPartials = 32;
static_assert(kDirdBytes % kPartials == 0);

inline float reduce_partials(const float* partial) {
  float total = 0.0f;
  for (std::size_t j = 0; j < kPartials; ++j) total += partial[j];
  return total;
}

#if defined(__SSE2__)
template <bool kAbsDiff>
inline float float_kernel_sse2(const float* a, const float* b) {
  __m128 acc[8];
  for (auto& x : acc) x = _mm_setzero_ps();
  const __m128 sign = _mm_set1_ps(-0.0f);
  for (std::size_t k = 0; k < kDirdBytes; k += kPartials) {
    for (std::size_t g = 0; g < 8; ++g) {
      const __m128 va = _mm_loadu_ps(a + k + 4 * g);
      const __m128 vb = _mm_loadu_ps(b + k + 4 * g);
      const __m128 term = kAbsDiff ? _mm_andnot_ps(sign, _mm_sub_ps(va, vb)) : _mm_mul_ps(va, vb);
      acc[g] = _mm_add_ps(acc[g], term);
    }
  }
  alignas(16) float partial[kPartials];
  for (std::size_t g = 0; g < 8; ++g) _mm_store_ps(partial + 4 * g, acc[g]);
  return reduce_partials(partial);
}
#else
template <bool kAbsDiff>
inline float float_kernel_sse2(const float* a, const float* b) {
  float partial[kPartials] = {};
  for (std::size_t k = 0; k < kDirdBytes; k += kPartials) {
    for (std::size_t j = 0; j < kPartials; ++j) {
      partial[j] += kAbsDiff ? std::fabs(a[k + j] - b[k + j]) : a[k + j] * b[k + j];
    }
  }
  return reduce_partials(partial);
}
#endif

#if defined(LOOPGATE_STANDARDIZE_AVX2_DISPATCH)
__attribute__((target("avx2"))) std::int32_t dot_codes_avx2(const std::uint8_t* a, const std::uint8_t* b) {
  const __m256i offset = _mm256_set1_epi16(128);
  __m256i acc0 = _mm256_setzero_si256();
  __m256i acc1 = _mm256_setzero_si256();
  for (std::size_t k = 0; k < kDirdBytes; k += 32) {
    const __m256i a0 = _mm256_sub_epi16(
        _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k))), offset);
    const __m256i a1 = _mm256_sub_epi16(
        _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k + 16))), offset);
    const __m256i b0 = _mm256_sub_epi16(
        _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k))), offset);
    const __m256i b1 = _mm256_sub_epi16(
        _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k + 16))), offset);
    acc0 = _mm256_add_epi32(acc0, _mm256_madd_epi16(a0, b0));
    acc1 = _mm256_add_epi32(acc1, _mm256_madd_epi16(a1, b1));
  }
  alignas(32) std::int32_t lanes[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), _mm256_add_epi32(acc0, acc1));
  std::int32_t sum = 0;
  for (std::int32_t lane : lanes) sum += lane;
  return sum;
}
static_assert(kDirdBytes % 32 == 0);

template <bool kAbsDiff>
__attribute__((target("avx2"))) float float_kernel_avx2(const float* a, const float* b) {
  __m256 acc[4];
  for (auto& x : acc) x = _mm256_setzero_ps();
  const __m256 sign = _mm256_set1_ps(-0.0f);
  for (std::size_t k = 0; k < kDirdBytes; k += kPartials) {
    for (std::size_t g = 0; g < 4; ++g) {
      const __m256 va = _mm256_loadu_ps(a + k + 8 * g);
      const __m256 vb = _mm256_loadu_ps(b + k + 8 * g);
      const __m256 term = kAbsDiff ? _mm256_andnot_ps(sign, _mm256_sub_ps(va, vb)) : _mm256_mul_ps(va, vb);
      acc[g] = _mm256_add_ps(acc[g], term);
    }
  }
  alignas(32) float partial[kPartials];
  for (std::size_t g = 0; g < 4; ++g) _mm256_store_ps(partial + 8 * g, acc[g]);
  return reduce_partials(partial);
}

const bool kHasAvx2 = __builtin_cpu_supports("avx2");
#endif

template <bool kAbsDiff>
float float_kernel(const float* a, const float* b) {
#if defined(LOOPGATE_STANDARDIZE_AVX2_DISPATCH)
  if (kHasAvx2) return float_kernel_avx2<kAbsDiff>(a, b);
#endif
  return float_kernel_sse2<kAbsDiff>(a, b);
}

double cosine_distance_from(double dot, double norm_a, double norm_b) {
  if (norm_a == 0.0 || norm_b == 0.0) return 1.0;
  const double c = dot / (norm_a * norm_b);
  return 1.0 - std::clamp(c, -1.0, 1.0);
}

}  // namespace

std::int32_t standard_dot(const Descriptor& a, const Descriptor& b) {
#if defined(LOOPGATE_STANDARDIZE_AVX2_DISPATCH)
  if (kHasAvx2) return dot_codes_avx2(a.data(), b.data());
#endif
#if defined(__SSE2__)
  return dot_codes_sse2(a.data(), b.data());
#else
  return dot_codes_scalar(a.data(), b.data());
#endif
}

double standard_norm(const Descriptor& a) {
  return std::sqrt(static_cast<double>(standard_dot(a, a)));
}

double standard_cosine_distance(const Descriptor& a, const Descriptor& b) {
  return standard_cosine_distance(a, standard_norm(a), b, standard_norm(b));
}

double standard_cosine_distance(const Descriptor& a, double norm_a, const Descriptor& b, double norm_b) {
  return cosine_distance_from(static_cast<double>(standard_dot(a, b)), norm_a, norm_b);
}

double standard_l1_unit(double clamp_sigma) {
  return clamp_sigma / (static_cast<double>(kStandardCodeMax) * static_cast<double>(kDirdBytes));
}

float float_l1_distance(const StandardizedFloat& a, const StandardizedFloat& b) {
  return float_kernel<true>(a.data(), b.data());
}

float float_dot(const StandardizedFloat& a, const StandardizedFloat& b) {
  return float_kernel<false>(a.data(), b.data());
}

double float_cosine_distance(const StandardizedFloat& a, const StandardizedFloat& b) {
  const double norm_a = std::sqrt(static_cast<double>(float_dot(a, a)));
  const double norm_b = std::sqrt(static_cast<double>(float_dot(b, b)));
  return cosine_distance_from(static_cast<double>(float_dot(a, b)), norm_a, norm_b);
}

}  // namespace loopgate
