// Compact codes of standardised DIRD descriptors: the bits, the distances against a direct computation on
// the +-1 / ternary vectors, and the AVX2 kernels bit-equal with the portable ones.
#include "stages/dird/dird_codes.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <span>
#include <stdexcept>
#include <vector>

#include "core/error.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace loopgate {
namespace {

// Int8 codes (stored offset by 128) drawn around zero.
Descriptor random_codes(std::mt19937& rng) {
  std::uniform_int_distribution<int> code(-127, 127);
  Descriptor d;
  for (auto& b : d) b = static_cast<std::uint8_t>(code(rng) + kStandardCodeZero);
  return d;
}

int sign_of(std::uint8_t byte) {
  return byte > kStandardCodeZero ? 1 : -1;
}

int ternary_of(std::uint8_t byte, int threshold) {
  const int c = static_cast<int>(byte) - kStandardCodeZero;
  return c >= threshold ? 1 : (c <= -threshold ? -1 : 0);
}

TEST(DirdCodes, SignCodeIsTheSignOfEveryDimensionAndItsDistanceOneMinusCosine) {
  std::mt19937 rng(3);
  const DirdCodeConfig config{DirdCode::kSign, 0.5};
  const Descriptor a = random_codes(rng), b = random_codes(rng);
  std::vector<std::uint64_t> ca(code_words(DirdCode::kSign)), cb(ca.size());
  EXPECT_EQ(make_compact_code(config, 4.0, a, ca.data()), static_cast<std::int32_t>(kDirdBytes));
  make_compact_code(config, 4.0, b, cb.data());
  int dot = 0;
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    EXPECT_EQ((ca[k / 64] >> (k % 64)) & 1U, a[k] > kStandardCodeZero ? 1U : 0U) << "dimension " << k;
    dot += sign_of(a[k]) * sign_of(b[k]);
  }
  for (std::size_t k = kDirdBytes; k < kCodePlaneWords * 64; ++k)
    EXPECT_EQ((ca[k / 64] >> (k % 64)) & 1U, 0U);
  const double expected = 1.0 - static_cast<double>(dot) / static_cast<double>(kDirdBytes);
  EXPECT_NEAR(sign_code_distance(ca.data(), cb.data()), expected, 1e-12);
  EXPECT_EQ(sign_code_distance(ca.data(), ca.data()), 0.0);
}

TEST(DirdCodes, TernaryDotMatchesTheTernaryVectors) {
  std::mt19937 rng(5);
  const DirdCodeConfig config{DirdCode::kTernary, 1.0};
  const double clamp_sigma = 4.0;
  const int threshold = static_cast<int>(std::lround(127 * 1.0 / clamp_sigma));  // 32 code units
  for (int trial = 0; trial < 5; ++trial) {
    const Descriptor a = random_codes(rng), b = random_codes(rng);
    std::vector<std::uint64_t> ca(code_words(DirdCode::kTernary)), cb(ca.size());
    const std::int32_t na = make_compact_code(config, clamp_sigma, a, ca.data());
    const std::int32_t nb = make_compact_code(config, clamp_sigma, b, cb.data());
    int dot = 0, nza = 0, nzb = 0;
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      dot += ternary_of(a[k], threshold) * ternary_of(b[k], threshold);
      nza += ternary_of(a[k], threshold) != 0;
      nzb += ternary_of(b[k], threshold) != 0;
    }
    EXPECT_EQ(na, nza);
    EXPECT_EQ(nb, nzb);
    EXPECT_EQ(ternary_dot_portable(ca.data(), cb.data(), kCodePlaneWords), dot);
    EXPECT_EQ(ternary_dot(ca.data(), cb.data(), kCodePlaneWords), dot);
    EXPECT_NEAR(ternary_code_distance(ca.data(), na, cb.data(), nb), 1.0 - dot / std::sqrt(1.0 * nza * nzb),
                1e-12);
  }
}

TEST(DirdCodes, MatrixDistancesAreThoseOfTheCodes) {
  std::mt19937 rng(9);
  for (const DirdCode code : {DirdCode::kSign, DirdCode::kTernary}) {
    const DirdCodeConfig config{code, 0.5};
    CompactCodeMatrix matrix(config, 4.0, 3);
    std::vector<Descriptor> d = {random_codes(rng), random_codes(rng), random_codes(rng)};
    for (std::size_t k = 0; k < 3; ++k) matrix.set(k, d[k]);
    std::vector<std::uint64_t> c0(code_words(code)), c2(code_words(code));
    const std::int32_t n0 = make_compact_code(config, 4.0, d[0], c0.data());
    const std::int32_t n2 = make_compact_code(config, 4.0, d[2], c2.data());
    const double expected = code == DirdCode::kSign ? sign_code_distance(c0.data(), c2.data())
                                                    : ternary_code_distance(c0.data(), n0, c2.data(), n2);
    EXPECT_EQ(matrix.distance(0, 2), expected);
    EXPECT_EQ(matrix.distance(1, 1), 0.0);
    EXPECT_THROW(matrix.set(3, d[0]), std::out_of_range);
  }
}

// The int2 value of one int8 code: sign (code > 0) times 1 or 3 (|code| >= threshold).
int int2_of(std::uint8_t byte, int threshold) {
  const int c = static_cast<int>(byte) - kStandardCodeZero;
  const int magnitude = (c >= threshold || c <= -threshold) ? 3 : 1;
  return c > 0 ? magnitude : -magnitude;
}

TEST(DirdCodes, Int2DotAndNormMatchTheFourLevelVectors) {
  std::mt19937 rng(17);
  const DirdCodeConfig config{DirdCode::kInt2, 0.5, 1.0};
  const int threshold = code_threshold(1.0, 4.0);
  for (int trial = 0; trial < 5; ++trial) {
    const Descriptor a = random_codes(rng), b = random_codes(rng);
    std::vector<std::uint64_t> ca(code_words(DirdCode::kInt2)), cb(ca.size());
    const std::int32_t ma = make_compact_code(config, 4.0, a, ca.data());
    const std::int32_t mb = make_compact_code(config, 4.0, b, cb.data());
    long dot = 0, na = 0, nb = 0;
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      dot += int2_of(a[k], threshold) * int2_of(b[k], threshold);
      na += int2_of(a[k], threshold) * int2_of(a[k], threshold);
      nb += int2_of(b[k], threshold) * int2_of(b[k], threshold);
    }
    EXPECT_EQ(na, static_cast<long>(kDirdBytes) + 8 * ma);
    EXPECT_NEAR(int2_code_distance(ca.data(), ma, cb.data(), mb),
                1.0 - static_cast<double>(dot) / std::sqrt(static_cast<double>(na) * static_cast<double>(nb)),
                1e-12);
    EXPECT_NEAR(int2_code_distance(ca.data(), ma, ca.data(), ma), 0.0, 1e-12);
  }
}

TEST(DirdCodes, EveryKernelIsBitEqualWithThePortableOne) {
  std::mt19937_64 rng(23);
  int kernels_run = 0;
  for (const PopcountKernel kernel : {PopcountKernel::kAvx2, PopcountKernel::kAvx512}) {
    if (!popcount_kernel_available(kernel)) continue;
    ++kernels_run;
    // Random words, and the extremes (all ones against zeros: the largest counts); lengths with and without
    // the AVX-512 kernel's four-word tail.
    for (int trial = 0; trial < 200; ++trial) {
      const std::size_t words = 4 * (1 + trial % 40);
      std::vector<std::uint64_t> a(2 * words), b(2 * words);
      for (std::size_t k = 0; k < a.size(); ++k) {
        a[k] = trial == 0 ? ~std::uint64_t{0} : rng();
        b[k] = trial == 0 ? 0 : (trial == 1 ? ~std::uint64_t{0} : rng());
      }
      ASSERT_EQ(hamming_words(a.data(), b.data(), words, kernel),
                hamming_words_portable(a.data(), b.data(), words))
          << enum_name(kernel) << " words " << words;
      ASSERT_EQ(ternary_dot(a.data(), b.data(), words, kernel),
                ternary_dot_portable(a.data(), b.data(), words))
          << enum_name(kernel) << " words " << words;
      ASSERT_EQ(int2_pair_term(a.data(), b.data(), words, kernel),
                int2_pair_term(a.data(), b.data(), words, PopcountKernel::kPortable))
          << enum_name(kernel) << " words " << words;
    }
  }
  if (kernels_run == 0) GTEST_SKIP() << "this CPU runs only the portable kernels";
  std::vector<std::uint64_t> ones(kCodePlaneWords, ~std::uint64_t{0}), zeros(kCodePlaneWords, 0);
  EXPECT_EQ(hamming_words(ones.data(), zeros.data(), kCodePlaneWords),
            static_cast<int>(kCodePlaneWords * 64));
}

// Raw descriptors with DIRD-like per-dimension statistics, some dimensions constant (the min_stddev floor)
// and some at the ends of the byte range.
std::vector<Descriptor> raw_descriptors(std::mt19937& rng, std::size_t n) {
  std::uniform_int_distribution<int> centre(0, 255), spread(0, 60);
  std::vector<int> c(kDirdBytes), s(kDirdBytes);
  for (std::size_t k = 0; k < kDirdBytes; ++k) {
    c[k] = centre(rng);
    s[k] = k % 7 == 0 ? 0 : spread(rng);
  }
  std::vector<Descriptor> out(n);
  for (auto& d : out) {
    for (std::size_t k = 0; k < kDirdBytes; ++k) {
      std::normal_distribution<double> noise(c[k], s[k] + 0.01);
      d[k] = static_cast<std::uint8_t>(std::clamp(static_cast<int>(std::lround(noise(rng))), 0, 255));
    }
  }
  return out;
}

TEST(DirdCodes, CodesFromCutsAreThoseOfTheInt8Codes) {
  std::mt19937 rng(29);
  const std::vector<Descriptor> set = raw_descriptors(rng, 60);
  for (const double clamp_sigma : {4.0, 0.5}) {
    StandardizeConfig standardize;
    standardize.clamp_sigma = clamp_sigma;
    const Standardization statistics = standardization_of(std::span(set).first(40), standardize);
    for (const DirdCodeConfig config :
         {DirdCodeConfig{DirdCode::kSign, 0.5, 1.0}, DirdCodeConfig{DirdCode::kTernary, 0.5, 1.0},
          DirdCodeConfig{DirdCode::kTernary, 4.0, 1.0}, DirdCodeConfig{DirdCode::kInt2, 0.5, 1.0},
          DirdCodeConfig{DirdCode::kInt2, 0.5, 0.1}}) {
      std::vector<std::uint8_t> cuts(code_cuts(config.code) * kDirdBytes);
      make_code_cuts(statistics, config, cuts.data());
      std::vector<std::uint64_t> expected(code_words(config.code)), got(expected.size()),
          portable(expected.size());
      // Every byte value of every dimension: the constant descriptors 0..255, then the set itself.
      std::vector<Descriptor> probes(256);
      for (int v = 0; v < 256; ++v) probes[static_cast<std::size_t>(v)].fill(static_cast<std::uint8_t>(v));
      probes.insert(probes.end(), set.begin(), set.end());
      for (const Descriptor& raw : probes) {
        const std::int32_t n = make_compact_code(config, clamp_sigma, statistics.apply(raw), expected.data());
        ASSERT_EQ(code_from_cuts(config.code, cuts.data(), raw, got.data()), n) << enum_name(config.code);
        ASSERT_EQ(got, expected) << enum_name(config.code) << " clamp " << clamp_sigma;
        ASSERT_EQ(code_from_cuts(config.code, cuts.data(), raw, portable.data(), PopcountKernel::kPortable),
                  n);
        ASSERT_EQ(portable, expected) << enum_name(config.code) << " clamp " << clamp_sigma << " (portable)";
      }
    }
  }
}

TEST(DirdCodes, CausalCoderKeepsTheCutsOfEachSnapshotAndCodesAsTheStandardizer) {
  std::mt19937 rng(31);
  // 400 frames: 39 snapshots, more than one key of the snapshots' differences (dird_cut_snapshots.hpp).
  const std::vector<Descriptor> set = raw_descriptors(rng, 400);
  StandardizeConfig standardize;
  standardize.mode = StandardizeMode::kCausal;
  standardize.warm_up = 10;
  standardize.window = 20;
  standardize.refresh_every = 5;
  for (const DirdCode code : {DirdCode::kSign, DirdCode::kTernary, DirdCode::kInt2}) {
    const DirdCodeConfig config{code, 0.5, 1.0};
    CausalStandardizer reference(standardize);
    CausalCompactCoder coder(standardize, config);
    EXPECT_FALSE(coder.ready());
    std::vector<std::uint64_t> expected(code_words(code)), got(expected.size());
    EXPECT_THROW(coder.code(0, set[0], got.data()), std::logic_error);
    // Odd frames observed; every frame coded at its own time, and again late (a gated run's reference).
    for (std::size_t f = 0; f < set.size(); ++f) {
      if (f % 2 == 1) {
        reference.observe(static_cast<std::int64_t>(f), set[f]);
        coder.observe(static_cast<std::int64_t>(f), set[f]);
      }
      if (!coder.ready()) continue;
      for (const std::size_t p : {f, f / 3, (f * 7) % (f + 1)}) {
        const auto frame = static_cast<std::int64_t>(p);
        const std::int32_t n = make_compact_code(config, standardize.clamp_sigma,
                                                 reference.standardize(frame, set[p]), expected.data());
        ASSERT_EQ(coder.code(frame, set[p], got.data()), n);
        ASSERT_EQ(got, expected) << enum_name(code) << " frame " << p << " at " << f;
      }
    }
    EXPECT_EQ(coder.snapshots(), reference.snapshots());
    EXPECT_GT(coder.snapshots(), CutSnapshots::kKeyEvery);
    EXPECT_THROW(coder.observe(3, set[3]), std::invalid_argument);  // before the horizon
  }
}

TEST(DirdCodes, MatrixRowIsThePairDistances) {
  std::mt19937 rng(37);
  for (const DirdCode code : {DirdCode::kSign, DirdCode::kTernary, DirdCode::kInt2}) {
    const DirdCodeConfig config{code, 0.5, 1.0};
    CompactCodeMatrix matrix(config, 4.0, 40);
    std::vector<std::uint8_t> coded(40, 0);
    for (std::size_t k = 0; k < 40; ++k) {
      if (k % 5 == 3) continue;  // frames without a code: left out of the row
      matrix.set(k, random_codes(rng));
      coded[k] = 1;
    }
    std::vector<double> row(30, -1.0);
    matrix.distances(7, 5, 35, coded.data(), row.data());
    for (std::size_t j = 5; j < 35; ++j) {
      if (coded[j]) {
        EXPECT_EQ(row[j - 5], matrix.distance(7, j)) << enum_name(code) << " j " << j;
      } else {
        EXPECT_EQ(row[j - 5], -1.0);
      }
    }
    EXPECT_THROW(matrix.distances(7, 5, 41, coded.data(), row.data()), std::out_of_range);
  }
}

TEST(DirdCodes, ConfigRejectsAThresholdOutsideItsRange) {
  DirdCodeConfig config;
  config.ternary_threshold_sigma = 0.0;
  EXPECT_THROW(config.validate(), ConfigError);
  config.ternary_threshold_sigma = 0.5;
  EXPECT_NO_THROW(config.validate());
  config.int2_threshold_sigma = 4.5;
  EXPECT_THROW(config.validate(), ConfigError);
  EXPECT_THROW(CompactCodeMatrix(DirdCodeConfig{}, 4.0, 4), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
