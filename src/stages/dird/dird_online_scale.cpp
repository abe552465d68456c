#include "stages/dird/dird_online_scale.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "core/error.hpp"
#include "core/validate.hpp"

namespace loopgate {

namespace {

// Bucket layout (see the header): 0 = [0, 2^-20); then, for frexp exponents e = -19..24 (values in
// [2^(e-1), 2^e)), 1024 buckets of equal width per octave; last = [2^24, inf).
constexpr int kSubBits = 10;
constexpr int kSub = 1 << kSubBits;  // buckets per octave
constexpr int kMinExponent = -19;
constexpr int kMaxExponent = 24;
constexpr int kOctaves = kMaxExponent - kMinExponent + 1;  // 44
constexpr std::size_t kBuckets = 2 + static_cast<std::size_t>(kOctaves) * kSub;
constexpr std::size_t kOverflow = kBuckets - 1;
constexpr double kUnderflowEdge = 0x1p-20;  // 2^(kMinExponent - 1)
constexpr double kOverflowEdge = 0x1p24;    // 2^kMaxExponent

std::size_t bucket_of(double distance) {
  if (distance < kUnderflowEdge) return 0;
  if (distance >= kOverflowEdge) return kOverflow;
  int exponent = 0;
  const double mantissa = std::frexp(distance, &exponent);  // [0.5, 1), exact
  // (mantissa - 0.5) * 2 * kSub is exact (a power-of-two scaling of an exact difference).
  const int sub = static_cast<int>((mantissa - 0.5) * (2.0 * kSub));
  return 1 + static_cast<std::size_t>(exponent - kMinExponent) * kSub + static_cast<std::size_t>(sub);
}

// [lower, upper) of a bucket; the overflow bucket is reported as the single value 2^24.
void bucket_edges(std::size_t bucket, double& lower, double& upper) {
  if (bucket == 0) {
    lower = 0.0;
    upper = kUnderflowEdge;
    return;
  }
  if (bucket == kOverflow) {
    lower = upper = kOverflowEdge;
    return;
  }
  const std::size_t index = bucket - 1;
  const int exponent = kMinExponent + static_cast<int>(index / kSub);
  const double sub = static_cast<double>(index % kSub);
  lower = std::ldexp(0.5 + sub / (2.0 * kSub), exponent);
  upper = std::ldexp(0.5 + (sub + 1.0) / (2.0 * kSub), exponent);
}

}  // namespace

void OnlineScaleConfig::validate() const {
  if (!(cutoff_quantile > 0.0 && cutoff_quantile < 1.0)) {
    throw ConfigError("scale.cutoff_quantile: must be in (0, 1)");
  }
  if (!(mu_quantile >= 0.0 && mu_quantile < cutoff_quantile)) {
    throw ConfigError("scale.mu_quantile: must be in [0, scale.cutoff_quantile)");
  }
  require_in("scale.min_distances", min_distances, std::int64_t{1}, std::int64_t{1'000'000'000}, "distances");
}

LogisticScale standard_default_scale(const StandardizeConfig& config, double tau1) {
  if (!(tau1 > 0.0 && tau1 < 0.5)) throw std::invalid_argument("standard_default_scale: tau1 in (0, 0.5)");
  // Measured (docs/standardize.md, DP AP over a grid of fixed scales on Nordland, KITTI 00 thumbnails and
  // the rendered demo by day and at night). Unrelated standardised descriptors are nearly uncorrelated
  // (median 1 - cos = 1.00 on every data set) and differ by a mean |z| of ~1.09 per dimension.
  //   cosine: sim = 0.5 at cos 0.25, sim = tau1 at cos 0.08;
  //   l1:     sim = 0.5 at a mean |z difference| of 0.90 per dimension, sim = tau1 at 1.00.
  const double mu = config.cosine() ? 0.75 : 0.90;
  const double cutoff = config.cosine() ? 0.92 : 1.00;
  const double unit = config.cosine() ? 1.0 : 1.0 / standard_l1_unit(config.clamp_sigma);
  LogisticScale s;
  s.mu = mu * unit;
  s.cutoff_distance = cutoff * unit;
  s.sigma = (s.cutoff_distance - s.mu) / std::log(1.0 / tau1 - 1.0);
  return s;
}

OnlineScale::OnlineScale(const OnlineScaleConfig& config, double tau1, const LogisticScale& prior)
    : config_(config), tau1_(tau1), prior_(prior), counts_(kBuckets, 0) {
  config_.validate();
  if (!(tau1 > 0.0 && tau1 < 0.5)) throw std::invalid_argument("OnlineScale: tau1 must be in (0, 0.5)");
  if (!(std::isfinite(prior.mu) && std::isfinite(prior.sigma) && prior.sigma > 0.0)) {
    throw std::invalid_argument("OnlineScale: the prior needs a finite mu and sigma > 0");
  }
  prior_.estimated = false;
  prior_.distances = 0;
  prior_.cutoff_distance = prior.mu + prior.sigma * std::log(1.0 / tau1 - 1.0);
}

void OnlineScale::add(double distance) {
  if (!(distance >= 0.0 && std::isfinite(distance))) {
    throw std::invalid_argument("OnlineScale::add: distance must be finite and >= 0");
  }
  ++counts_[bucket_of(distance)];
  ++count_;
}

void OnlineScale::add(std::span<const double> distances) {
  for (double d : distances) add(d);
}

void OnlineScale::add(std::span<const std::uint32_t> distances) {
  for (std::uint32_t d : distances) {
    ++counts_[bucket_of(static_cast<double>(d))];
  }
  count_ += static_cast<std::int64_t>(distances.size());
}

void OnlineScale::merge(const OnlineScale& other) {
  for (std::size_t b = 0; b < kBuckets; ++b) counts_[b] += other.counts_[b];
  count_ += other.count_;
}

double OnlineScale::quantile(double q) const {
  if (count_ == 0) throw std::logic_error("OnlineScale::quantile: no distances");
  if (!(q >= 0.0 && q <= 1.0)) throw std::invalid_argument("OnlineScale::quantile: q must be in [0, 1]");
  // The offline rule's rank: position q (n - 1) among the sorted distances, linear interpolation between
  // the order statistics `first` and first + 1; each order statistic is placed inside its bucket as if
  // the bucket's values were spread evenly over it.
  const double position = q * static_cast<double>(count_ - 1);
  const std::uint64_t first = static_cast<std::uint64_t>(std::floor(position));
  const double fraction = position - static_cast<double>(first);
  const std::uint64_t last = std::min(first + 1, static_cast<std::uint64_t>(count_ - 1));
  double value[2] = {0.0, 0.0};
  const std::uint64_t wanted[2] = {first, last};
  int found = 0;
  std::uint64_t before = 0;
  for (std::size_t b = 0; b < kBuckets && found < 2; ++b) {
    const std::uint64_t c = counts_[b];
    while (found < 2 && wanted[found] < before + c) {
      double lower = 0.0, upper = 0.0;
      bucket_edges(b, lower, upper);
      const double within = (static_cast<double>(wanted[found] - before) + 0.5) / static_cast<double>(c);
      value[found] = lower + within * (upper - lower);
      ++found;
    }
    before += c;
  }
  return value[0] + fraction * (value[1] - value[0]);
}

LogisticScale OnlineScale::estimate() const {
  LogisticScale s;
  s.mu = quantile(config_.mu_quantile);
  s.cutoff_distance = quantile(config_.cutoff_quantile);
  s.sigma = (s.cutoff_distance - s.mu) / std::log(1.0 / tau1_ - 1.0);
  s.estimated = true;
  s.distances = count_;
  return s;
}

namespace {
// mu and the cut-off further apart than one bucket (2^-10 of the cut-off): a real spread, not one inside a
// bucket (which the interpolation would invent for equal distances).
bool spread(const LogisticScale& s) {
  return s.cutoff_distance - s.mu > s.cutoff_distance / static_cast<double>(kSub);
}
}  // namespace

bool OnlineScale::ready() const {
  if (count_ < config_.min_distances || count_ == 0) return false;
  return spread(estimate());
}

LogisticScale OnlineScale::scale() const {
  if (count_ < config_.min_distances || count_ == 0) return prior_;
  const LogisticScale s = estimate();
  return spread(s) ? s : prior_;
}

}  // namespace loopgate
