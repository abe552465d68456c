// Chi-square distribution helpers for the MSCKF gating test (upper quantiles).
#pragma once

#include <vector>

namespace loopgate {

// Regularised lower incomplete gamma function P(a, x) (series for x < a + 1, continued fraction above).
double regularized_lower_gamma(double a, double x);
// Cumulative distribution function of the chi-square distribution with `dof` degrees of freedom.
double chi_square_cdf(double x, int dof);
// The `probability` quantile (e.g. 0.95 -> the value exceeded with 5% probability), by bisection on the CDF.
double chi_square_quantile(double probability, int dof);

// Quantiles for dof = 1..max_dof, precomputed once; larger dof are computed on demand.
class ChiSquareTable {
 public:
  ChiSquareTable(double probability, int max_dof);
  double probability() const { return probability_; }
  double quantile(int dof) const;

 private:
  double probability_;
  std::vector<double> table_;  // index dof
};

}  // namespace loopgate
