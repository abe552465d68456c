#include "stages/dird/dird_calibration.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

namespace loopgate {

namespace {

double quantile_of_sorted(const std::vector<double>& sorted, double q) {
  const double position = q * static_cast<double>(sorted.size() - 1);
  const std::size_t below = static_cast<std::size_t>(std::floor(position));
  const std::size_t above = std::min(below + 1, sorted.size() - 1);
  const double fraction = position - static_cast<double>(below);
  return sorted[below] + fraction * (sorted[above] - sorted[below]);
}

std::vector<double> sorted_copy(std::span<const double> values) {
  std::vector<double> sorted(values.begin(), values.end());
  std::sort(sorted.begin(), sorted.end());
  return sorted;
}

}  // namespace

double quantile(std::span<const double> values, double q) {
  if (values.empty()) throw std::invalid_argument("quantile of an empty sample");
  if (!(q >= 0.0 && q <= 1.0)) throw std::invalid_argument("quantile: q must be in [0, 1]");
  return quantile_of_sorted(sorted_copy(values), q);
}

LogisticCalibration calibrate_logistic(std::span<const double> beyond_margin,
                                       std::span<const double> revisits,
                                       const LogisticCalibrationOptions& options) {
  if (beyond_margin.empty())
    throw std::invalid_argument("calibrate_logistic: no distances beyond the margin");
  if (!(options.tau1 > 0.0 && options.tau1 < 0.5))
    throw std::invalid_argument("calibrate_logistic: tau1 must be in (0, 0.5)");
  if (!(options.cutoff_quantile > 0.0 && options.cutoff_quantile < 1.0) ||
      !(options.mu_quantile >= 0.0 && options.mu_quantile < options.cutoff_quantile)) {
    throw std::invalid_argument("calibrate_logistic: need 0 <= mu_quantile < cutoff_quantile < 1");
  }
  LogisticCalibration c;
  c.beyond_count = beyond_margin.size();
  c.revisit_count = revisits.size();
  const std::vector<double> beyond = sorted_copy(beyond_margin);
  c.beyond_median = quantile_of_sorted(beyond, 0.5);
  c.cutoff_distance = quantile_of_sorted(beyond, options.cutoff_quantile);
  const double mu_without = quantile_of_sorted(beyond, options.mu_quantile);
  char text[256];
  if (!revisits.empty()) {
    c.revisit_median = quantile(revisits, 0.5);
    if (c.revisit_median < c.cutoff_distance) {
      c.mu = c.revisit_median;
      std::snprintf(text, sizeof text,
                    "mu = median of %zu revisit distances; sim = %.3g at the %.3g quantile of %zu "
                    "beyond-margin distances",
                    c.revisit_count, options.tau1, options.cutoff_quantile, c.beyond_count);
    } else {
      c.mu = mu_without;
      std::snprintf(text, sizeof text,
                    "revisit median %.6g not below the cut-off %.6g: mu = %.3g quantile of %zu beyond-margin "
                    "distances; sim = %.3g at their %.3g quantile",
                    c.revisit_median, c.cutoff_distance, options.mu_quantile, c.beyond_count, options.tau1,
                    options.cutoff_quantile);
    }
  } else {
    c.mu = mu_without;
    std::snprintf(text, sizeof text,
                  "mu = %.3g quantile, sim = %.3g at the %.3g quantile of %zu beyond-margin distances (no "
                  "revisits given)",
                  options.mu_quantile, options.tau1, options.cutoff_quantile, c.beyond_count);
  }
  c.rule = text;
  if (!(c.mu < c.cutoff_distance)) {
    throw std::runtime_error(
        "calibrate_logistic: the distances beyond the margin are not spread enough (mu " +
        std::to_string(c.mu) + " >= cut-off " + std::to_string(c.cutoff_distance) + ")");
  }
  c.sigma = (c.cutoff_distance - c.mu) / std::log(1.0 / options.tau1 - 1.0);
  return c;
}

}  // namespace loopgate
