// Full mode (run.mode = full) of the pipeline: DIRD on every frame, similarities against every earlier frame
// beyond the margin, streaming sequence match and NMS (the two-sequence mode: pipeline_two_sequence_test).
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>

#include "core/error.hpp"
#include "io/config.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline_fake_dataset.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

using testing::read_csv;
using testing::read_file;
using testing::RevisitDataset;

using testing::column_index;

constexpr std::size_t kPeriod = 120;

PipelineConfig full_config(int threads = 2, int margin = 30) {
  PipelineConfig config;
  config.run.mode = RunMode::kFull;
  config.run.threads = threads;
  config.output.progress = Progress::kOff;
  config.match.margin = margin;
  config.match.sequence_length = 10;
  config.match.tau3 = 0.05;
  config.match.nms_half_window = 20;
  return config;
}

// The loops the batch reference gives for the same images: DirdExtractor + sparse_columns + match_batch.
std::vector<LoopClosure> reference_loops(const Dataset& dataset, const PipelineConfig& config) {
  const DirdExtractor extractor(config.dird);
  const DirdSimilarity similarity(config.dird);
  std::vector<Descriptor> descriptors;
  for (std::size_t k = 0; k < dataset.frame_count(); ++k)
    descriptors.push_back(extractor.extract(dataset.load_image(k)));
  std::vector<std::vector<SimilarityEntry>> columns(descriptors.size());
  similarity.sparse_columns(descriptors, config.match.margin, 0, descriptors.size(), columns);
  return match_batch(columns, config.match);
}

TEST(PipelineFullMode, FindsTheRevisitsAndEqualsTheBatchReference) {
  const RevisitDataset dataset(kPeriod, 3);
  const auto out = testing::make_temp_dir("pipeline-full");
  const PipelineConfig config = full_config();
  const RunResult result = run_pipeline(config, dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  ASSERT_EQ(result.frames_processed, 3 * kPeriod);

  const auto loops = read_csv(out / "loops.csv");
  const auto expected = reference_loops(dataset, config);
  ASSERT_FALSE(expected.empty());
  ASSERT_EQ(loops.size(), expected.size());
  std::size_t on_revisit = 0;
  for (std::size_t k = 0; k < loops.size(); ++k) {
    ASSERT_EQ(loops[k].size(), 5u);
    EXPECT_EQ(std::stoll(loops[k][0]), expected[k].i);
    EXPECT_EQ(std::stoll(loops[k][1]), expected[k].j);
    EXPECT_NEAR(std::stod(loops[k][4]), expected[k].score, 1e-6);
    EXPECT_NEAR(std::stod(loops[k][2]), 1.0 + 0.1 * static_cast<double>(expected[k].i), 1e-6);  // t_i
    const std::int64_t lag = expected[k].i - expected[k].j;
    if (lag % static_cast<std::int64_t>(kPeriod) <= 2 ||
        lag % static_cast<std::int64_t>(kPeriod) >= static_cast<std::int64_t>(kPeriod) - 2)
      ++on_revisit;
  }
  // Loops only where the drive revisits (second and third lap), and a good part of those frames.
  EXPECT_EQ(on_revisit, loops.size());
  EXPECT_GE(loops.size(), 2 * kPeriod / 4);
  for (const auto& row : loops) EXPECT_GE(std::stoul(row[0]), kPeriod);

  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["descriptors_computed"].get<std::size_t>(), 3 * kPeriod);
  EXPECT_EQ(summary["images_decoded"].get<std::size_t>(), 3 * kPeriod);
  std::size_t pairs = 0;
  for (std::size_t i = 30; i < 3 * kPeriod; ++i) pairs += i - 30 + 1;
  EXPECT_EQ(summary["similarities_computed"].get<std::size_t>(), pairs);
  EXPECT_EQ(summary["loops"].get<std::size_t>(), loops.size());
  EXPECT_EQ(summary["evaluation"]["loop_truth"]["loops_true"].get<std::size_t>(), loops.size());
  EXPECT_EQ(summary["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>(), 0u);
  EXPECT_EQ(summary["detection"]["loop"].get<std::size_t>() +
                summary["detection"]["suppressed"].get<std::size_t>() +
                summary["detection"]["below_threshold"].get<std::size_t>() +
                summary["detection"]["no_candidate"].get<std::size_t>(),
            3 * kPeriod);
  EXPECT_EQ(summary["config"]["match"]["margin"].get<int>(), 30);
  EXPECT_EQ(summary["config"]["dird"]["normalization"].get<std::string>(), "libdird");
  EXPECT_TRUE(summary["stages"].contains("describe"));
  EXPECT_TRUE(summary["stages"].contains("match"));
  EXPECT_EQ(summary["stages"]["describe"]["calls"].get<std::size_t>(), 3 * kPeriod);
}

TEST(PipelineFullMode, EveryFrameOnceWithExactlyOneStatus) {
  RevisitDataset dataset(kPeriod, 2);
  dataset.corrupt_frames = {7, 200};
  const auto out = testing::make_temp_dir("pipeline-full-status");
  const RunResult result = run_pipeline(full_config(), dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  ASSERT_EQ(rows.size(), 2 * kPeriod);
  const std::size_t detection = column_index(header, "detection");
  const std::size_t descriptor = column_index(header, "descriptor");
  const std::size_t reason = column_index(header, "detection_reason");
  const std::set<std::string> outcomes = {"no candidate", "below threshold", "suppressed", "loop"};
  std::set<std::string> seen;
  std::set<std::size_t> loop_frames;
  for (const auto& row : read_csv(out / "loops.csv")) loop_frames.insert(std::stoul(row[0]));
  for (std::size_t k = 0; k < rows.size(); ++k) {
    ASSERT_EQ(rows[k].size(), header.size());
    EXPECT_EQ(rows[k][0], std::to_string(k));
    EXPECT_EQ(outcomes.count(rows[k][detection]), 1u) << rows[k][detection];
    seen.insert(rows[k][detection]);
    EXPECT_EQ(rows[k][detection] == "loop", loop_frames.count(k) == 1) << k;
    const bool corrupt = k == 7 || k == 200;
    EXPECT_EQ(rows[k][descriptor], corrupt ? "n" : "y");
    if (corrupt) {
      EXPECT_EQ(rows[k][detection], "no candidate");
      EXPECT_NE(rows[k][reason].find("no descriptor"), std::string::npos);
      EXPECT_EQ(rows[k][15], "error");
    }
    if (k < 30) {
      EXPECT_EQ(rows[k][detection], "no candidate");
    }
  }
  EXPECT_EQ(seen.count("loop"), 1u);
  EXPECT_EQ(seen.count("no candidate"), 1u);
  for (const auto& row : read_csv(out / "loops.csv")) {
    EXPECT_NE(std::stoul(row[1]), 7u);  // no pair with a frame without descriptor
    EXPECT_NE(std::stoul(row[0]), 200u);
  }
}

TEST(PipelineFullMode, OneAndTwoThreadsIdenticalAlsoWithMarginBelowInFlight) {
  const RevisitDataset dataset(kPeriod, 3);
  for (const int margin : {30, 5}) {
    PipelineConfig config1 = full_config(1, margin);
    PipelineConfig config2 = full_config(2, margin);
    config2.run.max_in_flight = 16;  // different split between describe and match
    const auto out1 = testing::make_temp_dir("pipeline-full-t1");
    const auto out2 = testing::make_temp_dir("pipeline-full-t2");
    ASSERT_FALSE(run_pipeline(config1, dataset, out1).failed);
    ASSERT_FALSE(run_pipeline(config2, dataset, out2).failed);
    EXPECT_EQ(read_file(out1 / "loops.csv"), read_file(out2 / "loops.csv")) << "margin " << margin;
    EXPECT_EQ(read_file(out1 / "frames.csv"), read_file(out2 / "frames.csv")) << "margin " << margin;
    const auto s1 = nlohmann::json::parse(read_file(out1 / "summary.json"));
    const auto s2 = nlohmann::json::parse(read_file(out2 / "summary.json"));
    EXPECT_EQ(s1["similarities_computed"], s2["similarities_computed"]);
    EXPECT_GT(s1["loops"].get<std::size_t>(), 0u);
  }
}

TEST(PipelineFullMode, ModeIsValidatedAndNamesTheModes) {
  RawConfig raw;
  raw.apply_override("run.mode=bogus");
  PipelineConfig config;
  try {
    apply_config(raw, config);
    FAIL() << "run.mode=bogus accepted";
  } catch (const ConfigError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("run.mode"), std::string::npos) << what;
    EXPECT_NE(what.find("gated|full|odometry"), std::string::npos) << what;
  }
  PipelineConfig odometry_only;
  odometry_only.run.mode = RunMode::kOdometry;
  odometry_only.output.progress = Progress::kOff;
  const RevisitDataset dataset(kPeriod, 1);
  const auto out = testing::make_temp_dir("pipeline-odometry-mode");
  const RunResult result = run_pipeline(odometry_only, dataset, out);
  ASSERT_FALSE(result.failed);
  EXPECT_FALSE(fs::exists(out / "loops.csv"));
  EXPECT_EQ(result.summary["descriptors_computed"].get<std::size_t>(), 0u);
  EXPECT_EQ(result.summary["images_decoded"].get<std::size_t>(), 0u);  // lazy decode: nobody needs pixels
}

// An interrupted run's evaluation counted the ground-truth positives of frames it never processed.
// Now it covers the frames it got to: the same evaluation as a run over exactly that range, and fewer
// positives than the whole dataset's.
TEST(PipelineFullMode, InterruptedRunIsEvaluatedOnlyOverTheFramesItGotTo) {
  RevisitDataset dataset(kPeriod, 3);
  std::atomic<bool> stop{false};
  dataset.on_load = [&](std::size_t frame) {
    if (frame >= 200) stop.store(true);
  };
  const RunResult stopped = run_pipeline(full_config(), dataset, testing::make_temp_dir("full-stop"), &stop);
  ASSERT_TRUE(stopped.interrupted);
  ASSERT_FALSE(stopped.failed) << stopped.error;
  const nlohmann::json& evaluation = stopped.summary.at("evaluation");
  ASSERT_TRUE(evaluation.contains("frames_evaluated")) << evaluation.dump();
  const auto end = evaluation["frames_evaluated"]["end_frame"].get<std::size_t>();
  EXPECT_GT(end, 200u);
  EXPECT_LT(end, 3 * kPeriod);
  EXPECT_EQ(evaluation["frames_evaluated"]["requested_end_frame"].get<std::size_t>(), 3 * kPeriod);

  dataset.on_load = nullptr;
  PipelineConfig range = full_config();
  range.run.frames = "0:" + std::to_string(end);
  const RunResult limited = run_pipeline(range, dataset, testing::make_temp_dir("full-range"));
  const nlohmann::json& expected = limited.summary.at("evaluation");
  EXPECT_EQ(evaluation["precision_recall"]["positives"], expected["precision_recall"]["positives"]);
  EXPECT_EQ(evaluation["precision_recall"]["average_precision"],
            expected["precision_recall"]["average_precision"]);
  EXPECT_EQ(evaluation["loop_truth"], expected["loop_truth"]);
  const RunResult whole = run_pipeline(full_config(), dataset, testing::make_temp_dir("full-whole"));
  EXPECT_LT(evaluation["precision_recall"]["positives"].get<int>(),
            whole.summary["evaluation"]["precision_recall"]["positives"].get<int>());
  EXPECT_FALSE(whole.summary["evaluation"].contains("frames_evaluated"));
}

}  // namespace
}  // namespace loopgate
