// OnlineScale (dird_online_scale.hpp): histogram quantiles against exact ones, the online scale against the
// offline rule (calibrate_logistic), readiness and the prior, order independence and merge, determinism.
#include "stages/dird/dird_online_scale.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "core/error.hpp"
#include "stages/dird/dird_calibration.hpp"
#include "stages/dird/dird_similarity.hpp"

namespace loopgate {
namespace {

// Relative accuracy of every histogram quantile (the bucket width: 2^-10 of the bucket's lower edge).
constexpr double kRelative = 1.0 / 1024.0;

OnlineScaleConfig online_config(std::int64_t min_distances = 20000) {
  OnlineScaleConfig c;
  c.mode = ScaleMode::kOnline;
  c.min_distances = min_distances;
  return c;
}

LogisticScale prior() {
  LogisticScale p;
  p.mu = 100.0;
  p.sigma = 10.0;
  return p;
}

// Different places around 52 000 (L1-like), plus 0.1% revisits much closer.
std::vector<double> synthetic_distances(std::size_t count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> different(52000.0, 4000.0);
  std::normal_distribution<double> revisit(30000.0, 5000.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> out(count);
  for (double& d : out) d = std::max(0.0, u(rng) < 0.001 ? revisit(rng) : different(rng));
  return out;
}

TEST(DirdOnlineScale, QuantilesAreWithinTheBucketWidth) {
  std::mt19937 rng(1);
  std::lognormal_distribution<double> lognormal(0.0, 2.0);
  std::lognormal_distribution<double> narrow(0.0, 0.5);
  std::uniform_int_distribution<int> integers(30000, 70000);
  std::vector<double> samples[3];
  for (int k = 0; k < 50000; ++k) {
    samples[0].push_back(lognormal(rng));     // spans many octaves
    samples[1].push_back(integers(rng));      // integer SADs
    samples[2].push_back(narrow(rng) * 0.5);  // cosine distances
  }
  for (const auto& values : samples) {
    OnlineScale scale(online_config(), 0.05, prior());
    scale.add(values);
    for (double q : {0.0, 0.0005, 0.01, 0.1, 0.5, 0.9, 1.0}) {
      const double exact = quantile(values, q);
      EXPECT_NEAR(scale.quantile(q), exact, kRelative * exact) << "q " << q;
    }
  }
}

TEST(DirdOnlineScale, EqualsTheOfflineRuleWithinTolerance) {
  const std::vector<double> distances = synthetic_distances(200000, 2);
  const LogisticCalibration offline = calibrate_logistic(distances, {});
  OnlineScale online(online_config(), 0.05, prior());
  online.add(distances);
  ASSERT_TRUE(online.ready());
  const LogisticScale s = online.scale();
  EXPECT_TRUE(s.estimated);
  EXPECT_EQ(s.distances, 200000);
  // Tolerance: each quantile within 2^-10 (relative), so sigma = (cut - mu) / ln 19 within
  // 2^-10 (cut + mu) / ln 19.
  EXPECT_NEAR(s.mu, offline.mu, kRelative * offline.mu);
  EXPECT_NEAR(s.cutoff_distance, offline.cutoff_distance, kRelative * offline.cutoff_distance);
  EXPECT_NEAR(s.sigma, offline.sigma, kRelative * (offline.cutoff_distance + offline.mu) / std::log(19.0));
  EXPECT_NEAR(logistic_similarity(s.cutoff_distance, s.mu, s.sigma), 0.05, 1e-12);
  // Integer distances (SAD) through the integer overload: the same counts.
  std::vector<std::uint32_t> sads;
  for (double d : distances) sads.push_back(static_cast<std::uint32_t>(d));
  OnlineScale from_ints(online_config(), 0.05, prior());
  from_ints.add(sads);
  std::vector<double> truncated(sads.begin(), sads.end());
  OnlineScale from_doubles(online_config(), 0.05, prior());
  from_doubles.add(truncated);
  EXPECT_EQ(from_ints.scale().mu, from_doubles.scale().mu);
  EXPECT_EQ(from_ints.scale().sigma, from_doubles.scale().sigma);
}

TEST(DirdOnlineScale, PriorUntilReady) {
  const std::vector<double> distances = synthetic_distances(30000, 3);
  OnlineScale online(online_config(20000), 0.05, prior());
  EXPECT_FALSE(online.ready());
  EXPECT_THROW(online.quantile(0.5), std::logic_error);
  LogisticScale s = online.scale();
  EXPECT_FALSE(s.estimated);
  EXPECT_EQ(s.mu, 100.0);
  EXPECT_EQ(s.sigma, 10.0);
  EXPECT_NEAR(s.cutoff_distance, 100.0 + 10.0 * std::log(19.0), 1e-12);
  online.add(std::span<const double>(distances.data(), 19999));
  EXPECT_FALSE(online.ready());
  EXPECT_FALSE(online.scale().estimated);
  online.add(distances[19999]);
  EXPECT_TRUE(online.ready());
  EXPECT_TRUE(online.scale().estimated);
  // Degenerate: every distance equal, mu == cut-off: never ready, the prior stays.
  OnlineScale flat(online_config(10), 0.05, prior());
  for (int k = 0; k < 100; ++k) flat.add(5000.0);
  EXPECT_FALSE(flat.ready());
  EXPECT_FALSE(flat.scale().estimated);
}

TEST(DirdOnlineScale, OrderIndependentDeterministicAndMergeable) {
  std::vector<double> distances = synthetic_distances(50000, 4);
  OnlineScale a(online_config(), 0.05, prior());
  a.add(distances);
  std::shuffle(distances.begin(), distances.end(), std::mt19937(5));
  OnlineScale b(online_config(), 0.05, prior());
  b.add(distances);
  OnlineScale first(online_config(), 0.05, prior());
  OnlineScale second(online_config(), 0.05, prior());
  first.add(std::span<const double>(distances.data(), 20000));
  second.add(std::span<const double>(distances.data() + 20000, distances.size() - 20000));
  first.merge(second);
  for (const OnlineScale* other : {&b, &first}) {
    EXPECT_EQ(other->count(), a.count());
    EXPECT_EQ(other->scale().mu, a.scale().mu);  // exactly: counts only
    EXPECT_EQ(other->scale().sigma, a.scale().sigma);
    EXPECT_EQ(other->quantile(0.37), a.quantile(0.37));
  }
}

TEST(DirdOnlineScale, ExtremesAndInvalidInput) {
  OnlineScale s(online_config(1), 0.05, prior());
  s.add(0.0);  // underflow bucket
  s.add(1e-30);
  s.add(1e9);  // overflow bucket: reported as 2^24
  EXPECT_GE(s.quantile(0.0), 0.0);
  EXPECT_LT(s.quantile(0.0), std::ldexp(1.0, -20));
  EXPECT_EQ(s.quantile(1.0), std::ldexp(1.0, 24));
  EXPECT_THROW(s.add(-1.0), std::invalid_argument);
  EXPECT_THROW(s.add(std::nan("")), std::invalid_argument);
  EXPECT_THROW(s.add(INFINITY), std::invalid_argument);
  EXPECT_THROW(s.quantile(1.5), std::invalid_argument);
  EXPECT_THROW(OnlineScale(online_config(), 0.6, prior()), std::invalid_argument);
  LogisticScale bad = prior();
  bad.sigma = 0.0;
  EXPECT_THROW(OnlineScale(online_config(), 0.05, bad), std::invalid_argument);
}

TEST(DirdOnlineScale, ConfigValidationNamesTheKey) {
  auto message = [](const OnlineScaleConfig& c) {
    try {
      c.validate();
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  OnlineScaleConfig c;
  EXPECT_EQ(message(c), "");
  c.cutoff_quantile = 1.0;
  EXPECT_NE(message(c).find("scale.cutoff_quantile"), std::string::npos);
  c = {};
  c.mu_quantile = 0.02;
  EXPECT_NE(message(c).find("scale.mu_quantile"), std::string::npos);
  c = {};
  c.min_distances = 0;
  EXPECT_NE(message(c).find("scale.min_distances"), std::string::npos);
  EXPECT_THROW(OnlineScale(c, 0.05, prior()), ConfigError);
  std::vector<std::string> keys;
  OnlineScaleConfig::fields(c, [&](const char* key, auto&) { keys.emplace_back(key); });
  EXPECT_EQ(keys.size(), 4u);
}

TEST(DirdOnlineScale, StandardDefaultScale) {
  StandardizeConfig config;
  for (const StandardizeDistance distance : {StandardizeDistance::kL1, StandardizeDistance::kCosine}) {
    config.distance = distance;
    const LogisticScale s = standard_default_scale(config);
    EXPECT_GT(s.sigma, 0.0);
    EXPECT_LT(s.mu, s.cutoff_distance);
    EXPECT_NEAR(logistic_similarity(s.cutoff_distance, s.mu, s.sigma), 0.05, 1e-12);
  }
  // L1 in code SAD units: twice the clamp, half the SAD for the same z-score difference.
  config.distance = StandardizeDistance::kL1;
  config.clamp_sigma = 4.0;
  const double mu4 = standard_default_scale(config).mu;
  config.clamp_sigma = 8.0;
  EXPECT_NEAR(standard_default_scale(config).mu, mu4 / 2.0, 1e-9 * mu4);
}

}  // namespace
}  // namespace loopgate
