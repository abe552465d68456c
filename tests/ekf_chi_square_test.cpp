#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "stages/ekf/chi_square.hpp"

namespace loopgate {
namespace {

TEST(ChiSquare, UpperQuantilesMatchTables) {
  // Reference values of the 0.95 quantile (standard statistical tables).
  EXPECT_NEAR(chi_square_quantile(0.95, 1), 3.841459, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.95, 2), 5.991465, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.95, 3), 7.814728, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.95, 10), 18.307038, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.95, 19), 30.143527, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.95, 100), 124.342113, 1e-4);
  EXPECT_NEAR(chi_square_quantile(0.05, 10), 3.940299, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.975, 15), 27.488393, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.025, 15), 6.262138, 1e-5);
}

TEST(ChiSquare, CdfKnownValues) {
  EXPECT_NEAR(chi_square_cdf(2.0, 2), 1.0 - std::exp(-1.0), 1e-12);  // chi2(2) is exponential(1/2)
  EXPECT_NEAR(chi_square_cdf(3.841459, 1), 0.95, 1e-6);
  EXPECT_DOUBLE_EQ(chi_square_cdf(0.0, 4), 0.0);
  EXPECT_NEAR(regularized_lower_gamma(1.0, 1.0), 1.0 - std::exp(-1.0), 1e-12);
}

TEST(ChiSquare, TableIsTheUpperQuantileAndGrowsWithDof) {
  const ChiSquareTable table(0.95, 30);
  EXPECT_NEAR(table.quantile(2), 5.991465, 1e-5);
  EXPECT_GT(table.quantile(2), 2.0);  // the upper quantile is above the mean (the 5% one is below)
  for (int dof = 2; dof <= 40; ++dof) EXPECT_GT(table.quantile(dof), table.quantile(dof - 1));
  EXPECT_NEAR(table.quantile(100), 124.342113, 1e-4);  // beyond the table: computed on demand
}

TEST(ChiSquare, RejectsBadArguments) {
  EXPECT_THROW(chi_square_quantile(1.0, 3), std::invalid_argument);
  EXPECT_THROW(chi_square_quantile(0.95, 0), std::invalid_argument);
  EXPECT_THROW(chi_square_cdf(1.0, 0), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
