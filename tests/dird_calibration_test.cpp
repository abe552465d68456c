// calibrate_logistic(): the rule stated in dird_calibration.hpp on synthetic distributions.
#include "stages/dird/dird_calibration.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "stages/dird/dird_similarity.hpp"

namespace loopgate {
namespace {

TEST(DirdCalibration, Quantile) {
  const std::vector<double> v = {5.0, 1.0, 3.0, 2.0, 4.0};
  EXPECT_DOUBLE_EQ(quantile(v, 0.0), 1.0);
  EXPECT_DOUBLE_EQ(quantile(v, 0.5), 3.0);
  EXPECT_DOUBLE_EQ(quantile(v, 1.0), 5.0);
  EXPECT_DOUBLE_EQ(quantile(v, 0.125), 1.5);
  EXPECT_THROW(quantile(std::vector<double>{}, 0.5), std::invalid_argument);
  EXPECT_THROW(quantile(v, 1.5), std::invalid_argument);
}

TEST(DirdCalibration, WithoutRevisitsUsesBeyondMarginQuantiles) {
  std::vector<double> beyond;
  for (int k = 0; k <= 1000; ++k) beyond.push_back(50000.0 + 10.0 * k);  // 50 000 .. 60 000
  const LogisticCalibration c = calibrate_logistic(beyond, {});
  EXPECT_DOUBLE_EQ(c.mu, 50005.0);               // 0.0005 quantile
  EXPECT_DOUBLE_EQ(c.cutoff_distance, 50100.0);  // 0.01 quantile
  EXPECT_NEAR(c.sigma, 95.0 / std::log(19.0), 1e-9);
  EXPECT_NEAR(logistic_similarity(c.cutoff_distance, c.mu, c.sigma), 0.05, 1e-12);
  EXPECT_NEAR(logistic_similarity(c.mu, c.mu, c.sigma), 0.5, 1e-15);
  EXPECT_EQ(c.beyond_count, 1001u);
  EXPECT_DOUBLE_EQ(c.beyond_median, 55000.0);
  EXPECT_FALSE(c.rule.empty());
}

TEST(DirdCalibration, WithRevisitsCentresOnTheirMedian) {
  std::mt19937 rng(5);
  std::normal_distribution<double> different(59000.0, 2000.0);
  std::normal_distribution<double> revisit(45000.0, 5000.0);
  std::vector<double> beyond, revisits;
  for (int k = 0; k < 20000; ++k) beyond.push_back(different(rng));
  for (int k = 0; k < 300; ++k) {
    revisits.push_back(revisit(rng));
    beyond.push_back(revisits.back());
  }
  LogisticCalibrationOptions options;
  options.cutoff_quantile = 0.02;
  const LogisticCalibration c = calibrate_logistic(beyond, revisits, options);
  EXPECT_DOUBLE_EQ(c.mu, quantile(revisits, 0.5));
  EXPECT_DOUBLE_EQ(c.cutoff_distance, quantile(beyond, 0.02));
  EXPECT_NEAR(logistic_similarity(c.cutoff_distance, c.mu, c.sigma), 0.05, 1e-12);
  // Most different places fall below tau1, most revisits above it.
  std::size_t kept_different = 0;
  for (int k = 0; k < 20000; ++k)
    kept_different += logistic_similarity(beyond[static_cast<std::size_t>(k)], c.mu, c.sigma) > 0.05;
  EXPECT_LT(kept_different, 20000u / 50u);
  std::size_t kept_revisits = 0;
  for (double d : revisits) kept_revisits += logistic_similarity(d, c.mu, c.sigma) > 0.05;
  EXPECT_GT(kept_revisits, 250u);
}

TEST(DirdCalibration, RevisitsNoCloserFallBackAndFailure) {
  std::vector<double> beyond;
  for (int k = 0; k <= 1000; ++k) beyond.push_back(1000.0 + k);
  const std::vector<double> far_revisits = {1900.0, 1950.0, 2000.0};
  const LogisticCalibration c = calibrate_logistic(beyond, far_revisits);
  EXPECT_DOUBLE_EQ(c.mu, 1000.5);  // no-revisit rule: 0.0005 quantile
  EXPECT_NE(c.rule.find("not below"), std::string::npos);
  const std::vector<double> constant(100, 5.0);
  EXPECT_THROW(calibrate_logistic(constant, {}), std::runtime_error);
  EXPECT_THROW(calibrate_logistic({}, {}), std::invalid_argument);
  LogisticCalibrationOptions bad;
  bad.mu_quantile = 0.2;
  EXPECT_THROW(calibrate_logistic(beyond, {}, bad), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
