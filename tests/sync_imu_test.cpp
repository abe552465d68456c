#include <gtest/gtest.h>

#include "core/error.hpp"
#include "stages/sync/imu_sync.hpp"

namespace loopgate {
namespace {

constexpr Timestamp kMs = 1'000'000;

// gyro.x = t in ms, accel.z = 2 * t in ms: linear in time, so interpolation is exact.
ImuSample sample_at(Timestamp t_ns) {
  ImuSample s;
  s.t_ns = t_ns;
  const double t_ms = static_cast<double>(t_ns) / static_cast<double>(kMs);
  s.gyro_radps = Eigen::Vector3d(t_ms, -t_ms, 1.0);
  s.accel_mps2 = Eigen::Vector3d(0.0, 0.5, 2.0 * t_ms);
  return s;
}

std::vector<ImuSample> stream(Timestamp start_ms, Timestamp end_ms, Timestamp step_ms) {
  std::vector<ImuSample> out;
  for (Timestamp t = start_ms; t <= end_ms; t += step_ms) out.push_back(sample_at(t * kMs));
  return out;
}

TEST(SyncImu, BothEndsInterpolatedToImageTimes) {
  ImuSynchronizer sync(stream(0, 1000, 5), SyncConfig{});
  const SyncedImu first = sync.next(12 * kMs + 500'000);  // 12.5 ms
  ASSERT_EQ(first.samples.size(), 1u);
  EXPECT_EQ(first.samples[0].t_ns, 12 * kMs + 500'000);
  EXPECT_NEAR(first.samples[0].gyro_radps.x(), 12.5, 1e-12);
  EXPECT_TRUE(first.report.ok());

  const SyncedImu second = sync.next(63 * kMs);
  EXPECT_EQ(second.t_prev_ns, 12 * kMs + 500'000);
  // 12.5 (interpolated), 15, 20, ..., 60 (10 real samples), 63 (interpolated)
  ASSERT_EQ(second.samples.size(), 12u);
  EXPECT_EQ(second.samples.front().t_ns, 12 * kMs + 500'000);
  EXPECT_EQ(second.samples[1].t_ns, 15 * kMs);
  EXPECT_EQ(second.samples[10].t_ns, 60 * kMs);
  EXPECT_EQ(second.samples.back().t_ns, 63 * kMs);
  EXPECT_NEAR(second.samples.back().gyro_radps.x(), 63.0, 1e-12);
  EXPECT_NEAR(second.samples.back().gyro_radps.y(), -63.0, 1e-12);
  EXPECT_NEAR(second.samples.back().accel_mps2.z(), 126.0, 1e-12);
  EXPECT_NEAR(second.samples.front().accel_mps2.z(), 25.0, 1e-12);
  for (std::size_t i = 1; i < second.samples.size(); ++i) {
    EXPECT_LT(second.samples[i - 1].t_ns, second.samples[i].t_ns);
  }
  EXPECT_TRUE(second.report.ok());

  // An image exactly on a sample: the sample itself, no duplicate end point.
  const SyncedImu third = sync.next(70 * kMs);
  ASSERT_EQ(third.samples.size(), 3u);  // 63 (interp), 65, 70
  EXPECT_EQ(third.samples.back().t_ns, 70 * kMs);
  EXPECT_DOUBLE_EQ(third.samples.back().gyro_radps.x(), 70.0);
}

TEST(SyncImu, GapReportedByEveryOverlappingFrame) {
  auto samples = stream(0, 100, 5);
  const auto tail = stream(200, 400, 5);  // 100 ms without samples
  samples.insert(samples.end(), tail.begin(), tail.end());
  ImuSynchronizer sync(samples, SyncConfig{});
  EXPECT_TRUE(sync.next(50 * kMs).report.ok());
  const SyncedImu a = sync.next(150 * kMs);  // [50, 150] overlaps the gap (100, 200)
  EXPECT_EQ(a.report.gaps, 1);
  EXPECT_NEAR(a.report.max_gap_s, 0.1, 1e-12);
  ASSERT_EQ(a.report.messages.size(), 1u);
  EXPECT_NE(a.report.messages[0].find("IMU gap of 0.100 s"), std::string::npos) << a.report.messages[0];
  // End point interpolated across the gap: still linear in time.
  EXPECT_NEAR(a.samples.back().gyro_radps.x(), 150.0, 1e-9);
  const SyncedImu b = sync.next(250 * kMs);  // [150, 250] overlaps it too
  EXPECT_EQ(b.report.gaps, 1);
  const SyncedImu c = sync.next(300 * kMs);
  EXPECT_TRUE(c.report.ok());
  EXPECT_EQ(sync.anomalies().size(), 1u);
}

TEST(SyncImu, OutOfOrderAndDuplicatesReportedInTheirFrame) {
  auto samples = stream(0, 200, 10);
  // After 50 ms: a duplicate of 50; after 120 ms: a sample from the past (30 ms).
  samples.insert(samples.begin() + 6, sample_at(50 * kMs));
  samples.insert(samples.begin() + 14, sample_at(30 * kMs));
  ImuSynchronizer sync(samples, SyncConfig{});
  ASSERT_EQ(sync.anomalies().size(), 2u);
  EXPECT_EQ(sync.anomalies()[0].kind, ImuAnomaly::Kind::kDuplicate);
  EXPECT_EQ(sync.anomalies()[0].index, 6u);
  EXPECT_EQ(sync.anomalies()[1].kind, ImuAnomaly::Kind::kOutOfOrder);
  EXPECT_EQ(sync.clean_samples().size(), 21u);

  const SyncedImu f0 = sync.next(20 * kMs);
  EXPECT_TRUE(f0.report.ok());
  const SyncedImu f1 = sync.next(80 * kMs);  // holds the duplicate (found after 50)
  EXPECT_EQ(f1.report.duplicates, 1);
  EXPECT_EQ(f1.report.out_of_order, 0);
  ASSERT_EQ(f1.samples.size(), 7u);  // 20 30 40 50 60 70 80: the duplicate is gone
  const SyncedImu f2 = sync.next(110 * kMs);
  EXPECT_TRUE(f2.report.ok());
  const SyncedImu f3 = sync.next(150 * kMs);  // holds the out-of-order sample (found after 120)
  EXPECT_EQ(f3.report.out_of_order, 1);
  EXPECT_EQ(f3.report.duplicates, 0);
  ASSERT_EQ(f3.report.messages.size(), 1u);
  EXPECT_NE(f3.report.messages[0].find("out of order"), std::string::npos);
  for (std::size_t i = 1; i < f3.samples.size(); ++i) EXPECT_LT(f3.samples[i - 1].t_ns, f3.samples[i].t_ns);
}

TEST(SyncImu, MissingCoverageAndNoImu) {
  ImuSynchronizer sync(stream(100, 200, 5), SyncConfig{});
  const SyncedImu before = sync.next(50 * kMs);
  EXPECT_TRUE(before.report.imu_missing);
  EXPECT_TRUE(before.samples.empty());
  const SyncedImu straddle = sync.next(150 * kMs);  // starts before the first sample
  EXPECT_TRUE(straddle.report.imu_missing);
  const SyncedImu inside = sync.next(180 * kMs);
  EXPECT_FALSE(inside.report.imu_missing);
  EXPECT_EQ(inside.samples.size(), 7u);
  const SyncedImu after = sync.next(250 * kMs);
  EXPECT_TRUE(after.report.imu_missing);

  ImuSynchronizer none({}, SyncConfig{});
  EXPECT_FALSE(none.has_imu());
  const SyncedImu n = none.next(10);
  EXPECT_TRUE(n.samples.empty());
  EXPECT_TRUE(n.report.ok());
}

TEST(SyncImu, SkippedFramesStillCoverTheirInterval) {
  ImuSynchronizer sync(stream(0, 1000, 5), SyncConfig{});
  sync.next(100 * kMs);
  const SyncedImu later = sync.next(300 * kMs);  // frames in between were dropped upstream
  EXPECT_EQ(later.samples.front().t_ns, 100 * kMs);
  EXPECT_EQ(later.samples.back().t_ns, 300 * kMs);
  EXPECT_EQ(later.samples.size(), 41u);
  EXPECT_THROW(sync.next(300 * kMs), std::invalid_argument);
}

TEST(SyncImu, ConfigValidation) {
  SyncConfig config;
  config.max_gap_ms = 0;
  EXPECT_THROW(config.validate(), ConfigError);
  config.max_gap_ms = 2;
  ImuSynchronizer sync(stream(0, 100, 5), config);  // every step is a 5 ms "gap"
  EXPECT_EQ(sync.anomalies().size(), 20u);
}

}  // namespace
}  // namespace loopgate
