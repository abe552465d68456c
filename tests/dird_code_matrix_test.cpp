// CompactCodeMatrix keeps its rows in the order frames are coded: the distances do not depend on that order,
// only the frames coded take rows, and a frame not coded is refused instead of read.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "core/enum_names.hpp"
#include "stages/dird/dird_codes.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace loopgate {
namespace {

Descriptor random_codes(std::mt19937& rng) {
  std::uniform_int_distribution<int> code(-127, 127);
  Descriptor d;
  for (auto& b : d) b = static_cast<std::uint8_t>(code(rng) + kStandardCodeZero);
  return d;
}

TEST(DirdCodeMatrix, RowsFollowTheCodingOrderAndDistancesDoNot) {
  std::mt19937 rng(5);
  constexpr std::size_t kFrames = 60;
  for (const DirdCode code : {DirdCode::kSign, DirdCode::kTernary, DirdCode::kInt2}) {
    const DirdCodeConfig config{code, 0.5, 1.0};
    std::vector<Descriptor> d(kFrames);
    for (auto& x : d) x = random_codes(rng);
    // Every third frame left out; the others coded in sequence order in one matrix, and in a scrambled
    // order (late frames first, as a gated run describes past frames late) in the other.
    std::vector<std::uint8_t> coded(kFrames, 0);
    std::vector<std::size_t> order;
    for (std::size_t k = 0; k < kFrames; ++k) {
      if (k % 3 == 1) continue;
      coded[k] = 1;
      order.push_back(k);
    }
    CompactCodeMatrix in_order(config, 4.0, kFrames), scrambled(config, 4.0, kFrames);
    for (const std::size_t k : order) in_order.set(k, d[k]);
    std::vector<std::size_t> late = order;
    std::shuffle(late.begin(), late.end(), rng);
    for (const std::size_t k : late) scrambled.set(k, d[k]);
    EXPECT_EQ(in_order.rows(), order.size());
    EXPECT_EQ(scrambled.rows(), order.size());
    for (std::size_t k = 0; k < kFrames; ++k) EXPECT_EQ(scrambled.has(k), coded[k] == 1) << k;
    EXPECT_FALSE(scrambled.has(kFrames));

    for (const std::size_t a : order) {
      std::vector<double> row_a(kFrames, -1.0), row_b(kFrames, -1.0);
      in_order.distances(a, 0, kFrames, coded.data(), row_a.data());
      scrambled.distances(a, 0, kFrames, coded.data(), row_b.data());
      for (std::size_t j = 0; j < kFrames; ++j) {
        EXPECT_EQ(row_a[j], row_b[j]) << enum_name(code) << " a " << a << " j " << j;
        if (coded[j]) {
          EXPECT_EQ(row_b[j], scrambled.distance(a, j));
          EXPECT_EQ(row_b[j], in_order.distance(a, scrambled, j));  // across matrices
        } else {
          EXPECT_EQ(row_b[j], -1.0);  // skipped
        }
      }
    }
    // Coding a frame again rewrites its row instead of taking another.
    scrambled.set(order.front(), d[order.back()]);
    EXPECT_EQ(scrambled.rows(), order.size());
    EXPECT_EQ(scrambled.distance(order.front(), order.back()), 0.0);
  }
}

TEST(DirdCodeMatrix, AFrameNotCodedIsRefused) {
  std::mt19937 rng(11);
  const DirdCodeConfig config{DirdCode::kTernary, 0.5, 1.0};
  CompactCodeMatrix matrix(config, 4.0, 10);
  matrix.set(4, random_codes(rng));
  matrix.set(2, random_codes(rng));
  EXPECT_THROW(matrix.distance(4, 3), std::logic_error);
  EXPECT_THROW(matrix.distance(3, 4), std::logic_error);
  std::vector<std::uint8_t> coded(10, 0);
  coded[2] = coded[3] = 1;  // frame 3 flagged as coded but never set
  std::vector<double> row(10, -1.0);
  EXPECT_THROW(matrix.distances(4, 0, 10, coded.data(), row.data()), std::logic_error);
  EXPECT_THROW(matrix.distances(3, 0, 2, coded.data(), row.data()), std::logic_error);  // query not coded
  EXPECT_THROW(matrix.set(10, random_codes(rng)), std::out_of_range);
  EXPECT_THROW(matrix.distances(4, 0, 11, coded.data(), row.data()), std::out_of_range);
}

}  // namespace
}  // namespace loopgate
