#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "pipeline/pipeline.hpp"
#include "pipeline_fake_dataset.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

using testing::FakeDataset;

using testing::read_csv;
using testing::read_file;

PipelineConfig base_config(int threads = 2) {
  PipelineConfig config;
  config.run.threads = threads;
  config.run.mode = RunMode::kOdometry;  // the graph itself; detection modes have their own tests
  config.run.decode = DecodePolicy::kAll;
  config.output.progress = Progress::kOff;
  return config;
}

TEST(PipelineGraph, EveryFrameExactlyOnceInOrder) {
  FakeDataset dataset(300);
  const auto out = testing::make_temp_dir("pipeline-order");
  PipelineConfig config = base_config();
  config.output.trace = true;
  const RunResult result = run_pipeline(config, dataset, out);
  EXPECT_FALSE(result.failed) << result.error;
  EXPECT_EQ(result.frames_in, 300u);
  EXPECT_EQ(result.frames_processed, 300u);
  EXPECT_EQ(result.frames_dropped, 0u);
  EXPECT_EQ(result.frames_ok + result.frames_warning + result.frames_error, result.frames_processed);
  EXPECT_EQ(result.frames_ok, 300u);

  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 300u);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    ASSERT_EQ(rows[i].size(), 17u);
    EXPECT_EQ(rows[i][0], std::to_string(i));  // seq
    EXPECT_EQ(rows[i][1], std::to_string(i));  // frame
    EXPECT_EQ(rows[i][14], "y");               // decoded
    EXPECT_EQ(rows[i][15], "ok");
  }
  // 100 ms between frames at 200 Hz: 21 samples (both ends interpolated) except the first frame.
  EXPECT_EQ(rows[0][13], "1");
  EXPECT_EQ(rows[1][13], "21");
  EXPECT_EQ(read_csv(out / "timing.csv").size(), 300u);
  EXPECT_EQ(read_csv(out / "trajectory.tum").size() + 1, 300u);  // read_csv drops the first line

  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["frames_in"].get<int>(), 300);
  EXPECT_EQ(summary["frames_processed"].get<int>(), 300);
  EXPECT_EQ(summary["stages"]["decode"]["calls"].get<int>(), 300);
  EXPECT_GT(summary["stages"]["decode"]["p50_ms"].get<double>(), 0.0);
  EXPECT_EQ(summary["config"]["run"]["threads"].get<int>(), 2);
  EXPECT_EQ(summary["counts"]["decoded"].get<int>(), 300);
  EXPECT_NEAR(summary["data_s"].get<double>(), 29.9, 1e-9);
  const auto trace = nlohmann::json::parse(read_file(out / "trace.json"));
  EXPECT_GE(trace["traceEvents"].size(), 4u * 300u);
  EXPECT_NE(result.profile_table.find("odometry"), std::string::npos);
}

TEST(PipelineGraph, OneAndTwoThreadsGiveIdenticalOutputs) {
  FakeDataset dataset(200);
  dataset.corrupt_frames = {17};
  dataset.cut_imu(1'000'000'000 + 5'020'000'000LL, 1'000'000'000 + 5'300'000'000LL);
  std::string frames[2], trajectory[2];
  for (int threads = 1; threads <= 2; ++threads) {
    const auto out = testing::make_temp_dir("pipeline-threads");
    const RunResult result = run_pipeline(base_config(threads), dataset, out);
    ASSERT_FALSE(result.failed) << result.error;
    frames[threads - 1] = read_file(out / "frames.csv");
    trajectory[threads - 1] = read_file(out / "trajectory.tum");
  }
  EXPECT_GT(frames[0].size(), 1000u);
  EXPECT_EQ(frames[0], frames[1]);
  EXPECT_EQ(trajectory[0], trajectory[1]);
}

TEST(PipelineGraph, BadInputReportedPerFrameAndRunCompletes) {
  FakeDataset dataset(100);
  dataset.corrupt_frames = {40};
  // No IMU between 3.02 s and 3.3 s (frames at 1.0 + 0.1 k s): frames 21, 22, 23 overlap the gap.
  dataset.cut_imu(3'020'000'000LL, 3'300'000'000LL);
  dataset.add_issue("truncated last line");
  const auto out = testing::make_temp_dir("pipeline-bad");
  const RunResult result = run_pipeline(base_config(), dataset, out);
  EXPECT_FALSE(result.failed) << result.error;
  EXPECT_EQ(result.frames_processed, 100u);
  EXPECT_EQ(result.frames_error, 1u);
  EXPECT_EQ(result.frames_warning, 3u);
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 100u);
  EXPECT_EQ(rows[40][15], "error");
  EXPECT_NE(rows[40][16].find("corrupt PNG"), std::string::npos) << rows[40][16];
  EXPECT_EQ(rows[40][14], "n");
  EXPECT_EQ(rows[40][12], "tracking");  // the pose does not need the pixels
  for (const int k : {21, 22, 23}) {
    EXPECT_EQ(rows[static_cast<std::size_t>(k)][15], "warning") << k;
    EXPECT_NE(rows[static_cast<std::size_t>(k)][16].find("IMU gap"), std::string::npos);
  }
  EXPECT_EQ(rows[24][15], "ok");
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["data_issues"]["image_errors"].get<int>(), 1);
  EXPECT_EQ(summary["data_issues"]["imu_gaps"].get<int>(), 3);
  EXPECT_EQ(summary["data_issues"]["frames_with_issues"].get<int>(), 4);
  EXPECT_EQ(summary["data_issues"]["dataset_issue_count"].get<int>(), 1);
  EXPECT_NE(summary["data_issues"]["dataset_issues"][0].get<std::string>().find("data.csv:42: truncated"),
            std::string::npos);
}

TEST(PipelineGraph, FrameRangeAndLazyDecode) {
  FakeDataset dataset(50);
  dataset.corrupt_frames = {12};  // never decoded: nothing needs pixels with the drift source
  PipelineConfig config = base_config();
  config.run.decode = DecodePolicy::kLazy;
  config.run.frames = "10:20";
  const auto out = testing::make_temp_dir("pipeline-range");
  const RunResult result = run_pipeline(config, dataset, out);
  EXPECT_EQ(result.frames_processed, 10u);
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 10u);
  EXPECT_EQ(rows.front()[0], "0");
  EXPECT_EQ(rows.front()[1], "10");
  EXPECT_EQ(rows.back()[1], "19");
  for (const auto& row : rows) EXPECT_EQ(row[14], "n");
  EXPECT_EQ(result.frames_ok, 10u);
}

TEST(PipelineGraph, RealTimeReplayDropsWhenSaturated) {
  FakeDataset dataset(60);
  dataset.decode_delay_ms = 15;  // slower than the 2 ms frame period at rate 50
  PipelineConfig config = base_config(1);
  config.run.rate = "50";
  config.run.max_in_flight = 2;
  config.output.trace = true;
  const auto out = testing::make_temp_dir("pipeline-rate");
  const RunResult result = run_pipeline(config, dataset, out);
  EXPECT_FALSE(result.failed) << result.error;
  EXPECT_GT(result.frames_dropped, 0u);
  EXPECT_EQ(result.frames_in, 60u);
  EXPECT_EQ(result.frames_processed + result.frames_dropped, result.frames_in);
  EXPECT_GT(result.deadline_misses, 0u);
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), result.frames_processed);
  for (std::size_t i = 0; i < rows.size(); ++i) EXPECT_EQ(rows[i][0], std::to_string(i));  // contiguous seq
  // Trace.json shows each dropped frame and each deadline miss as an instant event, with its frame.
  const auto trace = nlohmann::json::parse(testing::read_file(out / "trace.json"));
  std::set<std::int64_t> dropped, missed;
  std::set<std::int64_t> processed;
  for (const auto& row : rows) processed.insert(std::stoll(row[1]));
  for (const auto& event : trace["traceEvents"]) {
    if (event["name"] == "dropped frame") {
      EXPECT_EQ(event["ph"], "i");
      dropped.insert(event["args"]["frame"].get<std::int64_t>());
    }
    if (event["name"] == "deadline miss") missed.insert(event["args"]["frame"].get<std::int64_t>());
  }
  EXPECT_EQ(dropped.size(), result.frames_dropped);
  EXPECT_EQ(missed.size(), result.deadline_misses);
  for (const std::int64_t frame : dropped) EXPECT_EQ(processed.count(frame), 0u) << frame;
  for (const std::int64_t frame : missed) EXPECT_EQ(processed.count(frame), 1u) << frame;
}

// The stop request comes on an event, not a timer (a fixed 150 ms timer failed under TSan, where
// no frame was through by then): when frame 50 is read. At most run.max_in_flight frames are in the graph,
// so every frame up to 50 - max_in_flight has left it, and the producer stops within max_in_flight frames.
TEST(PipelineGraph, StopRequestDrainsAndWritesOutputs) {
  FakeDataset dataset(400);
  std::atomic<bool> stop{false};
  dataset.on_load = [&](std::size_t frame) {
    if (frame >= 50) stop.store(true);
  };
  const auto out = testing::make_temp_dir("pipeline-stop");
  const PipelineConfig config = base_config();
  const RunResult result = run_pipeline(config, dataset, out, &stop);
  EXPECT_TRUE(result.interrupted);
  EXPECT_FALSE(result.failed);
  EXPECT_GE(result.frames_processed, 50u - static_cast<std::size_t>(config.run.max_in_flight));
  EXPECT_LT(result.frames_processed, 400u);
  EXPECT_EQ(result.frames_processed, result.frames_in);
  EXPECT_EQ(read_csv(out / "frames.csv").size(), result.frames_processed);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["interrupted"].get<bool>());
}

TEST(PipelineGraph, EscapingExceptionCancelsAndNamesTheFrame) {
  FakeDataset dataset(100);
  dataset.crashing_frames = {30};
  const auto out = testing::make_temp_dir("pipeline-crash");
  const RunResult result = run_pipeline(base_config(), dataset, out);
  EXPECT_TRUE(result.failed);
  EXPECT_NE(result.error.find("stage 'decode'"), std::string::npos) << result.error;
  EXPECT_NE(result.error.find("frame 30"), std::string::npos) << result.error;
  EXPECT_NE(result.error.find("decoder crashed"), std::string::npos) << result.error;
  EXPECT_LE(result.frames_processed, 30u);
  EXPECT_EQ(read_csv(out / "frames.csv").size(), result.frames_processed);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["failed"].get<bool>());
}

// Odometry.file pointing at this run's own output (a previous run's trajectory.tum) was read,
// then overwritten. Refused before anything is written; the file is left as it was.
TEST(PipelineGraph, AnInputThatIsAnOutputIsRefused) {
  const FakeDataset dataset(20);
  const auto out = testing::make_temp_dir("pipeline-overlap");
  {
    std::ofstream previous(out / "trajectory.tum");
    for (std::size_t i = 0; i < 20; ++i) previous << ns_to_s(dataset.frame_t_ns(i)) << " 0 0 0 0 0 0 1\n";
  }
  const std::string before = read_file(out / "trajectory.tum");
  PipelineConfig config = base_config();
  config.odometry.source = OdometrySourceKind::kFile;
  config.odometry.file = (out / "trajectory.tum").string();
  try {
    run_pipeline(config, dataset, out);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("trajectory.tum is also odometry.file"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(read_file(out / "trajectory.tum"), before);
  EXPECT_FALSE(std::filesystem::exists(out / "frames.csv"));
}

}  // namespace
}  // namespace loopgate
