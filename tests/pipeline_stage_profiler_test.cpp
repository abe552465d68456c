// The stage profiler keeps each sample as a float: its percentiles are still the measured durations (whole
// nanoseconds, to the nanosecond below 8 ms), and its count, total and maximum are exact.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

#include "pipeline/outputs/stage_profiler.hpp"

namespace loopgate {
namespace {

TEST(StageProfiler, FloatSamplesGiveTheMeasuredPercentiles) {
  std::mt19937 rng(3);
  std::uniform_int_distribution<std::int64_t> ns(0, 8'000'000);  // up to 8 ms, whole nanoseconds
  SampleSeries series;
  std::vector<double> exact;
  for (int k = 0; k < 20'000; ++k) {
    const double ms = 1e-6 * static_cast<double>(ns(rng));  // as the sink computes a service time
    series.add(ms);
    exact.push_back(ms);
  }
  const LatencyStats expected = compute_stats(exact);
  const LatencyStats got = series.stats();
  EXPECT_EQ(got.calls, expected.calls);
  EXPECT_EQ(got.p50_ms, expected.p50_ms);  // bit-equal: the nearest nanosecond of the float
  EXPECT_EQ(got.p90_ms, expected.p90_ms);
  EXPECT_EQ(got.p99_ms, expected.p99_ms);
  EXPECT_EQ(got.max_ms, expected.max_ms);
  double total_ms = 0;
  for (const double ms : exact) total_ms += ms;
  EXPECT_EQ(got.total_ms, total_ms);  // summed in double in the same order
}

TEST(StageProfiler, LongSamplesKeepTheirMaximumAndTotalExactly) {
  SampleSeries series;
  series.add(0.25);
  series.add(12345.678901);  // 12 s: beyond the nanosecond range of a float
  series.add(-0.5);          // a wait can be negative (clocks of two threads)
  const LatencyStats s = series.stats();
  EXPECT_EQ(s.calls, 3u);
  EXPECT_EQ(s.max_ms, 12345.678901);
  EXPECT_EQ(s.total_ms, 0.25 + 12345.678901 - 0.5);
  EXPECT_NEAR(s.p99_ms, 12345.678901, 12345.678901 * 1e-7);
  EXPECT_EQ(s.p50_ms, 0.25);
  EXPECT_EQ(SampleSeries{}.stats().calls, 0u);
}

TEST(StageProfiler, StagesAndLatencyAreSeparateSeries) {
  StageProfiler profiler({"a", "b"}, 4);
  profiler.add(0, 1.0, 0.5);
  profiler.add(1, 2.0, 0.25);
  profiler.add(0, 3.0, 0.75);
  profiler.add_latency(7.0);
  EXPECT_EQ(profiler.service(0).calls, 2u);
  EXPECT_EQ(profiler.service(0).max_ms, 3.0);
  EXPECT_EQ(profiler.service(1).total_ms, 2.0);
  EXPECT_EQ(profiler.wait(0).max_ms, 0.75);
  EXPECT_EQ(profiler.latency().p50_ms, 7.0);
  const nlohmann::json json = profiler.to_json();
  EXPECT_EQ(json["a"]["calls"], 2);
  EXPECT_EQ(json["latency"]["max_ms"], 7.0);
}

}  // namespace
}  // namespace loopgate
