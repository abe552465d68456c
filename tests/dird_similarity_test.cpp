// Distances, logistic similarity and the sparse similarity matrix (dird.md §2), and config validation.
#include "stages/dird/dird_similarity.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "core/error.hpp"

namespace loopgate {
namespace {

Descriptor random_descriptor(std::mt19937& rng) {
  Descriptor d;
  std::uniform_int_distribution<int> byte(0, 255);
  for (auto& b : d) b = static_cast<std::uint8_t>(byte(rng));
  return d;
}

// A copy of `d` with every byte moved by up to +-spread (clamped).
Descriptor perturbed(const Descriptor& d, int spread, std::mt19937& rng) {
  Descriptor out = d;
  std::uniform_int_distribution<int> delta(-spread, spread);
  for (auto& b : out) b = static_cast<std::uint8_t>(std::clamp(static_cast<int>(b) + delta(rng), 0, 255));
  return out;
}

std::uint64_t naive_l1(const Descriptor& a, const Descriptor& b) {
  std::uint64_t sum = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    sum += static_cast<std::uint64_t>(std::abs(int(a[k]) - int(b[k])));
  return sum;
}

TEST(DirdSimilarity, L1AndL2Distances) {
  Descriptor zero{};
  Descriptor full;
  full.fill(255);
  EXPECT_EQ(l1_distance(zero, full), 3456u * 255u);
  EXPECT_EQ(l1_distance(full, zero), 3456u * 255u);
  EXPECT_EQ(l2_squared_distance(zero, full), 3456u * 255u * 255u);
  EXPECT_DOUBLE_EQ(l2_distance(zero, full), std::sqrt(3456.0) * 255.0);
  Descriptor one = zero;
  one[0] = 3;
  one[3455] = 200;
  EXPECT_EQ(l1_distance(zero, one), 203u);
  EXPECT_EQ(l2_squared_distance(one, zero), 9u + 40000u);
  std::mt19937 rng(7);
  for (int t = 0; t < 50; ++t) {
    const Descriptor a = random_descriptor(rng);
    const Descriptor b = random_descriptor(rng);
    EXPECT_EQ(l1_distance(a, b), naive_l1(a, b));
    EXPECT_EQ(l1_distance(a, a), 0u);
  }
}

TEST(DirdSimilarity, LogisticReferenceValues) {
  const double mu = kDirdReferenceMuL1;
  EXPECT_NEAR(mu, 37837.84, 0.01);
  EXPECT_DOUBLE_EQ(logistic_similarity(mu, mu, 4000.0), 0.5);
  // sim > 0.05 exactly when d < about 49 616 (dird.md §2).
  const double cut = logistic_distance_at(0.05, mu, 4000.0);
  EXPECT_NEAR(cut, 49615.59, 0.01);  // mu + 4000 ln 19
  EXPECT_GT(logistic_similarity(49615.0, mu, 4000.0), 0.05);
  EXPECT_LT(logistic_similarity(49616.0, mu, 4000.0), 0.05);
  EXPECT_NEAR(logistic_similarity(mu - 4000.0, mu, 4000.0), 1.0 / (1.0 + std::exp(-1.0)), 1e-15);
  EXPECT_NEAR(logistic_similarity(0.0, mu, 4000.0), 1.0, 1e-4);
  EXPECT_LT(logistic_similarity(3456.0 * 255.0, mu, 4000.0), 1e-30);
  EXPECT_THROW(logistic_distance_at(0.0, mu, 4000.0), std::invalid_argument);
}

TEST(DirdSimilarity, SimilarityUsesConfiguredMetric) {
  Descriptor zero{};
  Descriptor some{};
  for (std::size_t k = 0; k < 100; ++k) some[k] = 30;  // L1 3000, L2 300
  const DirdSimilarity l1{DirdConfig{}};
  EXPECT_DOUBLE_EQ(l1.distance(zero, some), 3000.0);
  EXPECT_DOUBLE_EQ(l1.similarity(zero, some), logistic_similarity(3000.0, kDirdReferenceMuL1, 4000.0));
  DirdConfig l2_config;
  l2_config.metric = DirdMetric::kL2;
  l2_config.mu = 250.0;
  l2_config.sigma = 20.0;
  const DirdSimilarity l2{l2_config};
  EXPECT_DOUBLE_EQ(l2.distance(zero, some), 300.0);
  EXPECT_DOUBLE_EQ(l2.similarity(zero, some), 1.0 / (1.0 + std::exp(2.5)));
  EXPECT_GT(l2.cutoff_distance(), logistic_distance_at(0.05, 250.0, 20.0));
}

TEST(DirdSimilarity, SparseRowKeepsAboveTau1Only) {
  std::mt19937 rng(3);
  const Descriptor current = random_descriptor(rng);
  std::vector<Descriptor> earlier;
  for (int k = 0; k < 40; ++k) {
    // Spread 0..39: L1 grows ~ 3456 * spread / 2, crossing the cut-off ~49 616 around spread 28.
    earlier.push_back(perturbed(current, k, rng));
  }
  const DirdSimilarity similarity{DirdConfig{}};
  std::vector<SimilarityEntry> row;
  similarity.sparse_row(current, earlier.data(), earlier.size(), 100, row);
  std::size_t expected = 0;
  for (std::size_t k = 0; k < earlier.size(); ++k) {
    const double sim = similarity.similarity(current, earlier[k]);
    if (sim > 0.05) {
      ASSERT_LT(expected, row.size());
      EXPECT_EQ(row[expected].j, static_cast<std::int64_t>(k) + 100);
      EXPECT_EQ(row[expected].similarity, sim);
      ++expected;
    }
  }
  EXPECT_EQ(row.size(), expected);
  EXPECT_GT(expected, 10u);
  EXPECT_LT(expected, 40u);
}

TEST(DirdSimilarity, SparseColumnsEqualRowByRow) {
  std::mt19937 rng(11);
  // A random walk of descriptors: neighbours are similar, far frames are not; some revisits.
  std::vector<Descriptor> descriptors;
  descriptors.push_back(random_descriptor(rng));
  for (int k = 1; k < 157; ++k) {
    if (k % 7 == 0 && k < 60) {
      descriptors.push_back(random_descriptor(rng));  // far from everything: early exits of the kernel
    } else if (k % 50 == 0) {
      descriptors.push_back(perturbed(descriptors[static_cast<std::size_t>(k - 45)], 6, rng));
    } else {
      descriptors.push_back(perturbed(descriptors.back(), 5, rng));
    }
  }
  DirdConfig config;
  config.mu = 30000.0;
  config.sigma = 5000.0;
  const DirdSimilarity similarity{config};
  for (std::int64_t margin : {0, 3, 10}) {
    for (std::size_t begin : {std::size_t{0}, std::size_t{5}, std::size_t{17}}) {
      const std::size_t end = descriptors.size() - (begin % 3);
      std::vector<std::vector<SimilarityEntry>> columns(end - begin);
      similarity.sparse_columns(descriptors, margin, begin, end, columns);
      std::size_t stored = 0;
      for (std::size_t i = begin; i < end; ++i) {
        std::vector<SimilarityEntry> row;
        const std::int64_t count = static_cast<std::int64_t>(i) - margin + 1;
        if (count > 0)
          similarity.sparse_row(descriptors[i], descriptors.data(), static_cast<std::size_t>(count), 0, row);
        const auto& column = columns[i - begin];
        ASSERT_EQ(column.size(), row.size()) << "i=" << i << " margin=" << margin;
        for (std::size_t k = 0; k < row.size(); ++k) {
          EXPECT_EQ(column[k].j, row[k].j);
          EXPECT_EQ(column[k].similarity, row[k].similarity);
          EXPECT_LE(column[k].j, static_cast<std::int64_t>(i) - margin);
        }
        stored += row.size();
      }
      EXPECT_GT(stored, 100u);
    }
  }
  std::vector<std::vector<SimilarityEntry>> wrong(2);
  EXPECT_THROW(similarity.sparse_columns(descriptors, 0, 0, 5, wrong), std::invalid_argument);
}

TEST(DirdConfig, ValidateNamesKeys) {
  DirdConfig config;
  EXPECT_NO_THROW(config.validate());
  config.sigma = 0.0;
  EXPECT_THROW(config.validate(), ConfigError);
  config = DirdConfig{};
  config.tau1 = 1.0;
  EXPECT_THROW(config.validate(), ConfigError);
  // l2 metric with the L1 reference constants is refused: they must be calibrated.
  config = DirdConfig{};
  config.metric = DirdMetric::kL2;
  EXPECT_THROW(config.validate(), ConfigError);
  config.mu = kDirdScaleMuL2;
  config.sigma = kDirdScaleSigmaL2;
  EXPECT_NO_THROW(config.validate());
  // The visitor sees every key once.
  std::vector<std::string> keys;
  const DirdConfig& const_config = config;
  DirdConfig::fields(const_config, [&](const char* key, const auto&) { keys.emplace_back(key); });
  EXPECT_EQ(keys, (std::vector<std::string>{"normalization", "flip_vertical", "resize", "metric", "mu",
                                            "sigma", "tau1"}));
}

}  // namespace
}  // namespace loopgate
