// Compact codes of standardised DIRD descriptors: the bits, the distances against a direct computation on
// the +-1 / ternary vectors, and the AVX2 kernels bit-equal with the portable ones.
#include "stages/dird/dird_codes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
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

TEST(DirdCodes, Avx2KernelsAreBitEqualWithThePortableOnes) {
  if (!compact_codes_use_avx2()) GTEST_SKIP() << "this CPU has no AVX2: only the portable kernels run";
  std::mt19937_64 rng(11);
  // Random words, and the extremes (all ones: 64 per word, the largest byte counts).
  for (int trial = 0; trial < 200; ++trial) {
    const std::size_t words = 4 * (1 + trial % 40);
    std::vector<std::uint64_t> a(2 * words), b(2 * words);
    for (std::size_t k = 0; k < a.size(); ++k) {
      a[k] = trial == 0 ? ~std::uint64_t{0} : rng();
      b[k] = trial == 0 ? 0 : rng();
    }
    ASSERT_EQ(hamming_words(a.data(), b.data(), words), hamming_words_portable(a.data(), b.data(), words));
    ASSERT_EQ(ternary_dot(a.data(), b.data(), words), ternary_dot_portable(a.data(), b.data(), words));
  }
  std::vector<std::uint64_t> ones(kCodePlaneWords, ~std::uint64_t{0}), zeros(kCodePlaneWords, 0);
  EXPECT_EQ(hamming_words(ones.data(), zeros.data(), kCodePlaneWords),
            static_cast<int>(kCodePlaneWords * 64));
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

TEST(DirdCodes, ConfigRejectsAThresholdOutsideItsRange) {
  DirdCodeConfig config;
  config.ternary_threshold_sigma = 0.0;
  EXPECT_THROW(config.validate(), ConfigError);
  config.ternary_threshold_sigma = 0.5;
  EXPECT_NO_THROW(config.validate());
  EXPECT_THROW(CompactCodeMatrix(DirdCodeConfig{}, 4.0, 4), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
