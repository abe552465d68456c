// Descriptor standardisation (dird_standardize.hpp): statistics against a hand computation, the causal rule,
// order independence of batch statistics, zero-variance dimensions, quantisation bounds, cosine against a
// brute-force double computation.
#include "stages/dird/dird_standardize.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "core/error.hpp"
#include "stages/dird/dird_similarity.hpp"

namespace loopgate {
namespace {

Descriptor filled(std::uint8_t value) {
  Descriptor d;
  d.fill(value);
  return d;
}

// Random descriptors around a per-dimension centre, with a per-dimension spread (some dimensions constant).
std::vector<Descriptor> random_descriptors(std::size_t count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> centre(40, 200);
  std::uniform_int_distribution<int> spread(0, 40);
  std::vector<int> c(kDirdBytes), s(kDirdBytes);
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    c[k] = centre(rng);
    s[k] = k % 97 == 0 ? 0 : spread(rng);
  }
  std::vector<Descriptor> out(count);
  for (auto& d : out) {
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      std::uniform_int_distribution<int> noise(-s[k], s[k]);
      d[k] = static_cast<std::uint8_t>(std::clamp(c[k] + noise(rng), 0, 255));
    }
  }
  return out;
}

int code(std::uint8_t byte) {
  return static_cast<int>(byte) - kStandardCodeZero;
}

TEST(DirdStandardize, StatisticsMatchAHandComputation) {
  // Dimension 0: 100, 110, 120 -> mean 110, population variance 200 / 3, sd 8.16497.
  // Dimension 1: 90, 90, 93 -> mean 91, variance 2, sd 1.41421. Every other dimension constant 100.
  std::vector<Descriptor> set(3, filled(100));
  set[0][0] = 100;
  set[1][0] = 110;
  set[2][0] = 120;
  set[0][1] = 90;
  set[1][1] = 90;
  set[2][1] = 93;
  StandardizeConfig config;  // clamp 4, min_stddev 1
  const Standardization s = standardization_of(set, config);
  EXPECT_EQ(s.count(), 3);
  EXPECT_FLOAT_EQ(s.mean(0), 110.0f);
  EXPECT_NEAR(s.stddev(0), std::sqrt(200.0 / 3.0), 1e-6);
  EXPECT_FLOAT_EQ(s.mean(1), 91.0f);
  EXPECT_NEAR(s.stddev(1), std::sqrt(2.0), 1e-6);
  EXPECT_FLOAT_EQ(s.mean(2), 100.0f);
  EXPECT_NEAR(s.stddev(2), 1.0, 1e-6);  // zero variance: the floor

  const Descriptor codes = s.apply(set[2]);
  // z = 10 / 8.16497 = 1.22474 -> 127 * z / 4 = 38.886 -> 39.
  EXPECT_EQ(code(codes[0]), 39);
  // z = 2 / 1.41421 = 1.41421 -> 44.903 -> 45.
  EXPECT_EQ(code(codes[1]), 45);
  EXPECT_EQ(code(codes[2]), 0);
  EXPECT_EQ(code(s.apply(set[0])[0]), -39);  // round half up is symmetric away from .5 here

  StandardizedFloat z;
  s.apply_float(set[2], z);
  EXPECT_NEAR(z[0], 10.0 / std::sqrt(200.0 / 3.0), 1e-6);
  EXPECT_NEAR(z[1], std::sqrt(2.0), 1e-6);
  EXPECT_EQ(z[2], 0.0f);
}

TEST(DirdStandardize, MomentsAreExactAndWindowed) {
  const std::vector<Descriptor> set = random_descriptors(7, 3);
  DescriptorMoments all;
  DescriptorMoments window(3);
  DescriptorMoments last3;
  for (std::size_t i = 0; i < set.size(); ++i) {
    all.add(set[i]);
    window.add(set[i]);
    if (i >= 4) last3.add(set[i]);
  }
  EXPECT_EQ(all.count(), 7);
  EXPECT_EQ(window.count(), 3);
  EXPECT_EQ(window.added(), 7);
  for (std::size_t k = 0; k < kDirdBytes; k += 13) {
    EXPECT_EQ(window.mean(k), last3.mean(k)) << k;
    EXPECT_EQ(window.variance(k), last3.variance(k)) << k;
    double mean = 0.0;
    for (const auto& d : set) mean += d[k];
    mean /= 7.0;
    double var = 0.0;
    for (const auto& d : set) var += (d[k] - mean) * (d[k] - mean);
    var /= 7.0;
    EXPECT_NEAR(all.mean(k), mean, 1e-12);
    EXPECT_NEAR(all.variance(k), var, 1e-9);
  }
}

TEST(DirdStandardize, BatchStatisticsDoNotDependOnOrder) {
  std::vector<Descriptor> set = random_descriptors(200, 5);
  const StandardizeConfig config;
  const std::vector<Descriptor> codes = standardize_batch(set, config);
  const Standardization s = standardization_of(set, config);
  std::vector<std::size_t> order(set.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), std::mt19937(9));
  std::vector<Descriptor> shuffled;
  for (std::size_t i : order) shuffled.push_back(set[i]);
  const Standardization t = standardization_of(shuffled, config);
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    ASSERT_EQ(s.mean(k), t.mean(k));
    ASSERT_EQ(s.stddev(k), t.stddev(k));
  }
  for (std::size_t i = 0; i < set.size(); ++i) EXPECT_EQ(t.apply(set[i]), codes[i]);
}

TEST(DirdStandardize, SimdCodesEqualTheScalarDefinition) {
  std::vector<Descriptor> set = random_descriptors(50, 11);
  set.push_back(filled(0));
  set.push_back(filled(255));
  for (double clamp : {0.5, 3.0, 4.0, 127.0}) {
    StandardizeConfig config;
    config.clamp_sigma = clamp;
    const Standardization s = standardization_of(set, config);
    for (const Descriptor& d : set) {
      const Descriptor codes = s.apply(d);
      for (std::size_t k = 0; k < kDirdBytes; ++k) {
        ASSERT_EQ(codes[k], s.apply_one(k, d[k])) << "clamp " << clamp << " dim " << k;
        ASSERT_GE(codes[k], 1);
      }
    }
  }
}

TEST(DirdStandardize, QuantisationRoundTripIsWithinHalfAStep) {
  const std::vector<Descriptor> set = random_descriptors(100, 17);
  StandardizeConfig config;
  config.clamp_sigma = 1.5;  // uniform noise reaches sqrt(3) sigma: some values are clamped
  const Standardization s = standardization_of(set, config);
  const double step = config.clamp_sigma / kStandardCodeMax;
  std::size_t clamped = 0;
  for (const Descriptor& d : set) {
    const Descriptor codes = s.apply(d);
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      const double z = (d[k] - static_cast<double>(s.mean(k))) / s.stddev(k);
      const double decoded = code(codes[k]) * step;
      if (std::fabs(z) <= config.clamp_sigma) {
        ASSERT_LE(std::fabs(decoded - z), 0.5 * step + 1e-5) << k;
      } else {
        ++clamped;
        ASSERT_EQ(std::abs(code(codes[k])), kStandardCodeMax);
        ASSERT_EQ(decoded > 0.0, z > 0.0);
      }
    }
  }
  EXPECT_GT(clamped, 0u);
}

TEST(DirdStandardize, ZeroVarianceDimensionsUseTheFloor) {
  const std::vector<Descriptor> set(10, filled(77));
  StandardizeConfig config;  // min_stddev 1, clamp 4: one byte = 127 / 4 = 31.75 -> 32 code units
  const Standardization s = standardization_of(set, config);
  const Descriptor same = s.apply(set[0]);
  for (std::uint8_t b : same) ASSERT_EQ(b, kStandardCodeZero);
  Descriptor other = set[0];
  other[5] = 78;
  other[6] = 76;
  other[7] = 90;  // 13 bytes: far beyond the clamp
  const Descriptor codes = s.apply(other);
  EXPECT_EQ(code(codes[5]), 32);
  EXPECT_EQ(code(codes[6]), -32);
  EXPECT_EQ(code(codes[7]), kStandardCodeMax);
  config.min_stddev = 4.0;
  EXPECT_EQ(code(standardization_of(set, config).apply(other)[5]), 8);  // 127 / 16 = 7.94
  // Cosine of two all-zero code vectors: defined as 1 (orthogonal), no division by zero.
  EXPECT_EQ(standard_norm(same), 0.0);
  EXPECT_EQ(standard_cosine_distance(same, same), 1.0);
  EXPECT_EQ(standard_cosine_distance(same, codes), 1.0);
}

TEST(DirdStandardize, CausalCodesDoNotDependOnLaterFrames) {
  const std::vector<Descriptor> first = random_descriptors(120, 21);
  std::vector<Descriptor> second = first;
  const std::vector<Descriptor> other = random_descriptors(120, 22);
  std::copy(other.begin() + 60, other.end(), second.begin() + 60);  // frames 60.. differ
  for (std::int64_t refresh : {1, 7}) {
    for (std::int64_t window : {0, 25}) {
      StandardizeConfig config;
      config.mode = StandardizeMode::kCausal;
      config.warm_up = 20;
      config.refresh_every = refresh;
      config.window = window;
      CausalStandardizer a(config), b(config), late(config);
      std::vector<Descriptor> codes_a, codes_b;
      for (std::int64_t f = 0; f < 120; ++f) {
        const std::size_t i = static_cast<std::size_t>(f);
        a.observe(f, first[i]);
        b.observe(f, second[i]);
        late.observe(f, first[i]);
        if (a.ready()) {
          // Stream: each frame as soon as it can be (the warm-up frames when ready).
          while (static_cast<std::int64_t>(codes_a.size()) <= f) {
            const std::int64_t g = static_cast<std::int64_t>(codes_a.size());
            codes_a.push_back(a.standardize(g, first[static_cast<std::size_t>(g)]));
            codes_b.push_back(b.standardize(g, second[static_cast<std::size_t>(g)]));
          }
        } else {
          EXPECT_THROW(a.standardize(f, first[i]), std::logic_error);
        }
      }
      for (std::size_t i = 0; i < 60; ++i) {
        ASSERT_EQ(codes_a[i], codes_b[i]) << "frame " << i << " refresh " << refresh << " window " << window;
      }
      EXPECT_NE(codes_a[100], codes_b[100]);
      // Late description (a gated run's past frame): the same codes as at the frame's own time, in any order.
      for (std::int64_t f = 119; f >= 0; f -= 3) {
        const std::size_t i = static_cast<std::size_t>(f);
        ASSERT_EQ(late.standardize(f, first[i]), codes_a[i]) << "frame " << f;
      }
    }
  }
}

TEST(DirdStandardize, CausalWarmUpAndSnapshotRule) {
  const std::vector<Descriptor> set = random_descriptors(40, 31);
  StandardizeConfig config;
  config.mode = StandardizeMode::kCausal;
  config.warm_up = 10;
  config.refresh_every = 5;
  CausalStandardizer causal(config);
  // Only every second frame is observed (frames 0, 2, 4, ...), as a gated run that describes some frames.
  for (std::int64_t f = 0; f < 40; f += 2) {
    EXPECT_EQ(causal.ready(), causal.observations() >= 10);
    causal.observe(f, set[static_cast<std::size_t>(f)]);
  }
  // Snapshots after observations 10, 15, 20 = frames 18, 28, 38.
  EXPECT_EQ(causal.snapshots(), 3u);
  const std::vector<Descriptor> first10 = {set[0],  set[2],  set[4],  set[6],  set[8],
                                           set[10], set[12], set[14], set[16], set[18]};
  const Standardization warm = standardization_of(first10, config);
  EXPECT_EQ(causal.statistics_for(0).count(), 10);
  EXPECT_EQ(causal.statistics_for(17).count(), 10);  // before the warm-up frame: the warm-up statistics
  EXPECT_EQ(causal.statistics_for(18).count(), 10);
  EXPECT_EQ(causal.statistics_for(27).count(), 10);
  EXPECT_EQ(causal.statistics_for(28).count(), 15);
  EXPECT_EQ(causal.statistics_for(1000).count(), 20);
  EXPECT_EQ(causal.standardize(3, set[3]), warm.apply(set[3]));
  EXPECT_EQ(causal.standardize(25, set[25]), warm.apply(set[25]));
}

TEST(DirdStandardize, CausalOrderIsEnforced) {
  const std::vector<Descriptor> set = random_descriptors(10, 41);
  StandardizeConfig config;
  config.mode = StandardizeMode::kCausal;
  config.warm_up = 2;
  CausalStandardizer causal(config);
  EXPECT_THROW(causal.statistics_for(0), std::logic_error);
  causal.observe(0, set[0]);
  EXPECT_THROW(causal.observe(0, set[1]), std::invalid_argument);  // not increasing
  causal.observe(2, set[2]);
  ASSERT_TRUE(causal.ready());
  causal.standardize(5, set[5]);                                   // horizon 5
  EXPECT_THROW(causal.observe(4, set[4]), std::invalid_argument);  // would change frame 5's statistics
  EXPECT_THROW(causal.observe(5, set[5]), std::invalid_argument);
  causal.observe(6, set[6]);
  causal.standardize(1, set[1]);  // a past frame: allowed, the horizon stays at 6
  causal.observe(7, set[7]);
}

TEST(DirdStandardize, DotAndCosineMatchABruteForceDoubleComputation) {
  std::mt19937 rng(51);
  std::uniform_int_distribution<int> byte(0, 255);
  for (int trial = 0; trial < 20; ++trial) {
    Descriptor a, b;
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      a[k] = static_cast<std::uint8_t>(byte(rng));
      b[k] = static_cast<std::uint8_t>(trial == 0 ? a[k] : byte(rng));
    }
    if (trial == 1) a.fill(0);  // extreme codes: -128
    double dot = 0.0, na = 0.0, nb = 0.0, l1 = 0.0;
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      const double x = a[k] - 128.0, y = b[k] - 128.0;
      dot += x * y;
      na += x * x;
      nb += y * y;
      l1 += std::fabs(x - y);
    }
    EXPECT_EQ(standard_dot(a, b), static_cast<std::int32_t>(dot));
    EXPECT_NEAR(standard_norm(a), std::sqrt(na), 1e-9);
    const double cosine = 1.0 - dot / std::sqrt(na * nb);
    EXPECT_NEAR(standard_cosine_distance(a, b), cosine, 1e-12);
    EXPECT_NEAR(standard_cosine_distance(a, standard_norm(a), b, standard_norm(b)), cosine, 1e-12);
    EXPECT_EQ(static_cast<double>(l1_distance(a, b)), l1);  // L1 on codes = SAD on the stored bytes
  }
}

TEST(DirdStandardize, FloatDistancesMatchADoubleComputation) {
  const std::vector<Descriptor> set = random_descriptors(20, 61);
  const Standardization s = standardization_of(set, StandardizeConfig{});
  StandardizedFloat a, b;
  s.apply_float(set[0], a);
  s.apply_float(set[1], b);
  double dot = 0.0, na = 0.0, nb = 0.0, l1 = 0.0;
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    dot += static_cast<double>(a[k]) * b[k];
    na += static_cast<double>(a[k]) * a[k];
    nb += static_cast<double>(b[k]) * b[k];
    l1 += std::fabs(static_cast<double>(a[k]) - b[k]);
  }
  EXPECT_NEAR(float_l1_distance(a, b), l1, 1e-5 * l1);
  EXPECT_NEAR(float_dot(a, b), dot, 1e-5 * std::sqrt(na * nb));
  EXPECT_NEAR(float_cosine_distance(a, b), 1.0 - dot / std::sqrt(na * nb), 1e-5);
  EXPECT_EQ(float_l1_distance(a, b), float_l1_distance(a, b));  // deterministic
  // The int8 codes approximate the float cosine (quantisation step clamp / 127 sigma).
  EXPECT_NEAR(standard_cosine_distance(s.apply(set[0]), s.apply(set[1])), 1.0 - dot / std::sqrt(na * nb),
              0.01);
}

TEST(DirdStandardize, ConfigValidationNamesTheKey) {
  auto message = [](const StandardizeConfig& c) {
    try {
      c.validate();
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  StandardizeConfig c;
  EXPECT_EQ(message(c), "");
  c.clamp_sigma = 0.1;
  EXPECT_NE(message(c).find("standardize.clamp_sigma"), std::string::npos);
  c = {};
  c.min_stddev = 0.0;
  EXPECT_NE(message(c).find("standardize.min_stddev"), std::string::npos);
  c = {};
  c.warm_up = 1;
  EXPECT_NE(message(c).find("standardize.warm_up"), std::string::npos);
  c = {};
  c.window = 10;  // < warm_up 50
  EXPECT_NE(message(c).find("standardize.window"), std::string::npos);
  c = {};
  c.refresh_every = 0;
  EXPECT_NE(message(c).find("standardize.refresh_every"), std::string::npos);
  c = {};
  c.observe_every = 0;
  EXPECT_NE(message(c).find("standardize.observe_every"), std::string::npos);
  // fields() lists every key once.
  std::vector<std::string> keys;
  StandardizeConfig::fields(c, [&](const char* key, auto&) { keys.emplace_back(key); });
  EXPECT_EQ(keys.size(), 8u);
}

// Spans of frames become counts of observations of every observe_every-th frame.
TEST(StandardizeConfig, ObservationsConfigDividesTheFrameSpansByTheStride) {
  StandardizeConfig c;
  c.observe_every = 3;
  c.warm_up = 50;
  c.window = 100;
  c.refresh_every = 10;
  const StandardizeConfig o = observations_config(c);
  EXPECT_EQ(o.warm_up, 17);  // ceil(50 / 3)
  EXPECT_EQ(o.window, 34);
  EXPECT_EQ(o.refresh_every, 4);
  EXPECT_EQ(o.observe_every, 1);
  c.window = 0;
  c.warm_up = 4;
  c.observe_every = 4;
  EXPECT_EQ(observations_config(c).window, 0);
  EXPECT_EQ(observations_config(c).warm_up, 2);  // at least 2 observations
}

}  // namespace
}  // namespace loopgate
