// The compact coder's snapshots kept as differences: every snapshot reads back as pushed, whatever the
// order of the reads and the size of the changes, and small changes take a fraction of the whole snapshots.
#include "stages/dird/dird_cut_snapshots.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

namespace loopgate {
namespace {

// `count` snapshots of `bytes` bytes, each from the one before by the changes of `step`.
template <class Step>
std::vector<std::vector<std::uint8_t>> walk(std::size_t count, std::size_t bytes, std::mt19937& rng,
                                            Step step) {
  std::vector<std::vector<std::uint8_t>> s(count, std::vector<std::uint8_t>(bytes));
  std::uniform_int_distribution<int> any(0, 255);
  for (auto& b : s[0]) b = static_cast<std::uint8_t>(any(rng));
  for (std::size_t i = 1; i < count; ++i) {
    s[i] = s[i - 1];
    for (auto& b : s[i]) b = static_cast<std::uint8_t>(step(b, rng));
  }
  return s;
}

void expect_reads_back(CutSnapshots& store, const std::vector<std::vector<std::uint8_t>>& s,
                       const std::vector<std::size_t>& order) {
  for (const std::size_t i : order) {
    const std::uint8_t* got = store.cuts(i);
    for (std::size_t k = 0; k < s[i].size(); ++k)
      ASSERT_EQ(got[k], s[i][k]) << "snapshot " << i << " byte " << k;
  }
}

TEST(DirdCutSnapshots, EverySnapshotReadsBackAsPushedInAnyOrder) {
  std::mt19937 rng(11);
  // Mostly small changes, some large ones (exceptions), some wrapping around 0 / 255, some unchanged.
  const auto s = walk(70, 6912, rng, [](std::uint8_t b, std::mt19937& r) {
    const int u = std::uniform_int_distribution<int>(0, 99)(r);
    if (u < 50) return static_cast<int>(b);
    if (u < 80) return b + (u % 2 ? 1 : -1);
    if (u < 95) return b + (u % 7) - 3;
    return std::uniform_int_distribution<int>(0, 255)(r);
  });
  CutSnapshots store(6912);
  for (const auto& snapshot : s) store.push(snapshot.data());
  ASSERT_EQ(store.size(), s.size());
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < s.size(); ++i) order.push_back(i);  // forward
  for (std::size_t i = s.size(); i-- > 0;) order.push_back(i);    // backward
  for (int k = 0; k < 200; ++k)                                   // random
    order.push_back(std::uniform_int_distribution<std::size_t>(0, s.size() - 1)(rng));
  expect_reads_back(store, s, order);
  EXPECT_THROW(store.cuts(s.size()), std::out_of_range);
}

TEST(DirdCutSnapshotsSize, EachWidthReadsBackAndSmallChangesTakeLittle) {
  std::mt19937 rng(12);
  const std::size_t bytes = 3456, count = 8 * CutSnapshots::kKeyEvery;
  // Unchanged (exceptions only), +-1 (2 bits), -7..7 (4 bits), anything (whole bytes), geometric (Rice).
  // 100: a two-sided geometric change (half of the bytes unchanged, a quarter +-1, ...): a Rice code.
  const std::array<int, 5> spans = {0, 1, 7, 255, 100};
  std::array<std::size_t, 5> sizes{};
  for (std::size_t w = 0; w < spans.size(); ++w) {
    const int span = spans[w];
    const auto s = walk(count, bytes, rng, [span](std::uint8_t b, std::mt19937& r) {
      if (span == 100) {
        const int magnitude = std::geometric_distribution<int>(0.5)(r);
        return b + (std::bernoulli_distribution(0.5)(r) ? magnitude : -magnitude);
      }
      return span == 255 ? std::uniform_int_distribution<int>(0, 255)(r)
                         : b + std::uniform_int_distribution<int>(-span, span)(r);
    });
    CutSnapshots store(bytes);
    for (const auto& snapshot : s) store.push(snapshot.data());
    std::vector<std::size_t> order;
    for (std::size_t i = 0; i < count; ++i) order.push_back((i * 7) % count);
    expect_reads_back(store, s, order);
    sizes[w] = store.bytes();
  }
  const std::size_t whole = count * bytes;
  EXPECT_LT(sizes[0], whole / 8) << "unchanged snapshots";
  EXPECT_LT(sizes[1], whole * 35 / 100) << "+-1 changes";
  EXPECT_LT(sizes[2], whole * 60 / 100) << "-7..7 changes";
  EXPECT_GE(sizes[3], whole) << "random bytes cannot be smaller than whole";
  EXPECT_LT(sizes[4], whole * 48 / 100) << "two-sided geometric changes (4 bits per byte: 54%)";
}

TEST(DirdCutSnapshots, RejectsAnUnusableSize) {
  EXPECT_THROW(CutSnapshots(0), std::invalid_argument);
  EXPECT_THROW(CutSnapshots(70000), std::invalid_argument);
}

}  // namespace
}  // namespace loopgate
