#include "stages/ekf/chi_square.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace loopgate {
namespace {

constexpr int kMaxIterations = 500;
constexpr double kRelativeEpsilon = 1e-15;
constexpr double kTiny = 1e-300;
constexpr int kBisectionSteps = 200;

// Series: P(a, x) = exp(-x) x^a / Gamma(a + 1) * sum_n x^n / ((a + 1) ... (a + n)).
double lower_gamma_series(double a, double x) {
  double term = 1.0 / a;
  double sum = term;
  double ap = a;
  for (int n = 0; n < kMaxIterations; ++n) {
    ap += 1.0;
    term *= x / ap;
    sum += term;
    if (std::abs(term) < std::abs(sum) * kRelativeEpsilon) break;
  }
  return sum * std::exp(-x + a * std::log(x) - std::lgamma(a));
}

// Continued fraction (modified Lentz) for Q(a, x) = 1 - P(a, x).
double upper_gamma_continued_fraction(double a, double x) {
  double b = x + 1.0 - a;
  double c = 1.0 / kTiny;
  double d = 1.0 / b;
  double h = d;
  for (int i = 1; i < kMaxIterations; ++i) {
    const double an = -static_cast<double>(i) * (static_cast<double>(i) - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < kRelativeEpsilon) break;
  }
  return std::exp(-x + a * std::log(x) - std::lgamma(a)) * h;
}

}  // namespace

double regularized_lower_gamma(double a, double x) {
  if (!(a > 0.0)) throw std::invalid_argument("regularized_lower_gamma: a must be > 0");
  if (x <= 0.0) return 0.0;
  if (x < a + 1.0) return lower_gamma_series(a, x);
  return 1.0 - upper_gamma_continued_fraction(a, x);
}

double chi_square_cdf(double x, int dof) {
  if (dof < 1) throw std::invalid_argument("chi_square_cdf: dof must be >= 1");
  return regularized_lower_gamma(0.5 * static_cast<double>(dof), 0.5 * x);
}

double chi_square_quantile(double probability, int dof) {
  if (!(probability > 0.0 && probability < 1.0)) {
    throw std::invalid_argument("chi_square_quantile: probability must be in (0, 1)");
  }
  if (dof < 1) throw std::invalid_argument("chi_square_quantile: dof must be >= 1");
  const double k = static_cast<double>(dof);
  double lo = 0.0;
  double hi = k + 10.0 * std::sqrt(2.0 * k) + 50.0;
  while (chi_square_cdf(hi, dof) < probability) hi *= 2.0;
  for (int i = 0; i < kBisectionSteps && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (chi_square_cdf(mid, dof) < probability) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

ChiSquareTable::ChiSquareTable(double probability, int max_dof) : probability_(probability) {
  table_.assign(static_cast<std::size_t>(std::max(max_dof, 0)) + 1, std::numeric_limits<double>::quiet_NaN());
  for (int dof = 1; dof <= max_dof; ++dof)
    table_[static_cast<std::size_t>(dof)] = chi_square_quantile(probability, dof);
}

double ChiSquareTable::quantile(int dof) const {
  if (dof >= 1 && static_cast<std::size_t>(dof) < table_.size()) return table_[static_cast<std::size_t>(dof)];
  return chi_square_quantile(probability_, dof);
}

}  // namespace loopgate
