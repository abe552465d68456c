// Calibration of the logistic similarity sim(d) = 1 / (1 + exp((d - mu) / sigma)) from a dataset's own
// distance distributions (docs/detection.md § The paper's matcher).
//
// Rule (state it with the config it produced):
//   beyond  = distances of the pairs beyond the safety margin (mostly different places),
//   revisit = distances of ground-truth revisits beyond the margin (optional).
//   1. cut-off d_tau1 = quantile(beyond, cutoff_quantile) (default 0.01): sim(d_tau1) = tau1, so the
//      sparse matrix keeps about that fraction of the pairs beyond the margin.
//   2. centre mu (sim = 0.5):
//      - with revisits: mu = median(revisit), a typical revisit scores 0.5;
//      - without: mu = quantile(beyond, mu_quantile) (default 0.0005): the closest 0.05% of the pairs
//        beyond the margin score 0.5 or more (revisits are a small minority of those pairs: on KITTI 00
//        about 0.08% are within 3 m, and this rule gives nearly the constants of the revisit rule).
//      If that mu is not below d_tau1 (revisits no closer than different places), mu falls back to the
//      no-revisit rule; if still not below, calibration fails (std::runtime_error).
//   3. sigma = (d_tau1 - mu) / ln(1 / tau1 - 1).
// Quantiles interpolate linearly between order statistics.
#pragma once

#include <cstddef>
#include <span>
#include <string>

namespace loopgate {

struct LogisticCalibrationOptions {
  double tau1 = 0.05;             // the similarity at the cut-off (dird.tau1)
  double cutoff_quantile = 0.01;  // quantile of the beyond-margin distances where sim = tau1
  double mu_quantile = 0.0005;    // without revisits: quantile of the beyond-margin distances where sim = 0.5
};

struct LogisticCalibration {
  double mu = 0.0;
  double sigma = 0.0;
  double cutoff_distance = 0.0;  // d with sim(d) = tau1
  std::size_t beyond_count = 0;
  std::size_t revisit_count = 0;
  double beyond_median = 0.0;
  double revisit_median = 0.0;  // 0 without revisits
  std::string rule;             // which branch of the rule was used, human-readable
};

// Linear-interpolation quantile (q in [0, 1]) of a non-empty sample.
double quantile(std::span<const double> values, double q);

// Throws std::invalid_argument for an empty `beyond_margin` or options out of range, std::runtime_error
// when the distributions give no usable constants (see the rule above).
LogisticCalibration calibrate_logistic(std::span<const double> beyond_margin,
                                       std::span<const double> revisits,
                                       const LogisticCalibrationOptions& options = {});

}  // namespace loopgate
