// Causal estimate of the logistic's mu and sigma (sim(d) = 1 / (1 + exp((d - mu) / sigma))) from the
// distances seen so far, by the no-revisit rule of calibrate_logistic() (dird_calibration.hpp):
//   d_tau1 = quantile(distances, cutoff_quantile)   (default 0.01: sim(d_tau1) = tau1)
//   mu     = quantile(distances, mu_quantile)       (default 0.0005: sim(mu) = 0.5)
//   sigma  = (d_tau1 - mu) / ln(1 / tau1 - 1)
// where `distances` are all the distances added so far: in single-sequence mode the pairs beyond the safety
// margin (the ones the similarity is computed for), in two-sequence mode every (reference, query) pair. True
// revisits are among them; they are a small minority, the offline rule makes the same assumption.
//
// Streaming quantiles: a fixed histogram with logarithmic buckets, 1024 per octave (each bucket spans less
// than 0.1% of its values) over [2^-20, 2^24) plus an underflow bucket [0, 2^-20) and an overflow bucket
// (2^24 and above); bucket boundaries come from the exact binary exponent and mantissa (frexp), so the same
// distances give the same counts and the same estimate on every build, in any order of addition (counts
// only; merge() adds histograms of parallel workers). A quantile is read at the same rank as the offline
// rule (position q * (n - 1) among the sorted distances), interpolated linearly inside its bucket; it lies
// within 2^-10 (relative) of the exact linear-interpolation quantile. Memory: 45 058 counts (352 KB).
//
// Ready: at least min_distances distances (default 20 000: 10 of them below the mu quantile, 200 below the
// cut-off) and the estimate spread (d_tau1 - mu more than one bucket, 2^-10 d_tau1; the offline rule fails
// there too). Before that, scale() returns the prior (the configured mu / sigma, e.g.
// standard_default_scale() for standardised descriptors) with estimated = false.
//
// Use in a stream: the similarities of frame i use the scale frozen before frame i's distances are added
// (no frame's similarity depends on its own or later distances). The distances must be exact: kernels with
// an early exit (DirdSimilarity::sparse_columns' AVX2 path) return only lower bounds above their limit, which
// still count correctly as long as the limit lies above the cut-off quantile (use a limit well above it).
//
// Measured (docs/standardize.md): with the default quantiles this reproduces the offline rule, whose 1 %
// cut-off keeps too few entries for cross-season matching (Nordland DP AP 0.30 with standardised cosine);
// the fixed standard_default_scale() does better there (0.52) and as well elsewhere (KITTI 0.85), so it is
// the recommended scale for standardised descriptors and OnlineScale the option for raw ones.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "stages/dird/dird_standardize.hpp"

namespace loopgate {

// scale.mode: "off": dird.mu / dird.sigma as configured; "online": OnlineScale.
enum class ScaleMode { kOff, kOnline };
inline constexpr EnumName<ScaleMode> kScaleModeNames[] = {{ScaleMode::kOff, "off"},
                                                          {ScaleMode::kOnline, "online"}};
constexpr std::span<const EnumName<ScaleMode>> enum_names(ScaleMode) {
  return kScaleModeNames;
}

// Configuration section `scale`.
struct OnlineScaleConfig {
  ScaleMode mode = ScaleMode::kOff;    // off | online (ScaleMode)
  double cutoff_quantile = 0.01;       // quantile of the distances where sim = tau1
  double mu_quantile = 0.0005;         // quantile of the distances where sim = 0.5
  std::int64_t min_distances = 20000;  // distances before the estimate replaces the prior

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("mode", self.mode);
    v("cutoff_quantile", self.cutoff_quantile);
    v("mu_quantile", self.mu_quantile);
    v("min_distances", self.min_distances);
  }
  // Throws ConfigError naming "scale.<key>": 0 <= mu_quantile < cutoff_quantile < 1,
  // min_distances >= 1.
  void validate() const;

  bool online() const { return mode == ScaleMode::kOnline; }
};

// mu / sigma of the logistic in the units of the distance they apply to.
struct LogisticScale {
  double mu = 0.0;
  double sigma = 1.0;
  double cutoff_distance = 0.0;  // sim(cutoff_distance) = tau1
  bool estimated = false;        // false: the prior
  std::int64_t distances = 0;    // distances the estimate is based on
};

// A fixed logistic scale for standardised descriptors, in the units of config.distance: code SAD for "l1"
// (from a mean absolute z-score difference per dimension, see standard_l1_unit()), 1 - cos for "cosine".
// Its cut-off (tau1) lies at the low tail of the different-place distances of the data measured.
LogisticScale standard_default_scale(const StandardizeConfig& config, double tau1 = 0.05);

class OnlineScale {
 public:
  // `prior` is what scale() returns until ready(). Throws ConfigError for a bad config, std::invalid_argument
  // for tau1 outside (0, 0.5) or a prior with sigma <= 0.
  OnlineScale(const OnlineScaleConfig& config, double tau1, const LogisticScale& prior);

  // distance >= 0 and finite; throws std::invalid_argument otherwise.
  void add(double distance);
  void add(std::span<const double> distances);
  void add(std::span<const std::uint32_t> distances);
  // Adds the counts of another estimator (same bucket layout); the result equals adding its distances.
  void merge(const OnlineScale& other);

  std::int64_t count() const { return count_; }
  bool ready() const;
  // The estimate when ready(), else the prior (estimated = false).
  LogisticScale scale() const;
  // Histogram quantile (q in [0, 1]) of the distances added; throws std::logic_error when none.
  double quantile(double q) const;

  const OnlineScaleConfig& config() const { return config_; }
  double tau1() const { return tau1_; }

 private:
  LogisticScale estimate() const;

  OnlineScaleConfig config_;
  double tau1_ = 0.05;
  LogisticScale prior_;
  std::vector<std::uint64_t> counts_;
  std::int64_t count_ = 0;
};

}  // namespace loopgate
