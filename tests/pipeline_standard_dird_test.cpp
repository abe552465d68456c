// DIRD with causal standardisation (standardize.mode causal) and the online scale as run methods
// (src/pipeline/standard_dird_methods.cpp). The checks, against a reference computed here from the stage
// classes (CausalStandardizer over the observed frames, cosine of the codes, the fixed standardised scale):
//   - the full run's loop closures are the batch DP + NMS of that S (every pair beyond the margin);
//   - the gated run's are the batch result of the same S restricted to the cells it reports, so gated codes
//     and similarities equal the full run's (both observe every observe_every-th frame);
//   - causal: a run over the first frames only gives the loops of the whole run's S restricted to them;
//   - 1 and 2 threads give identical outputs; the options a single sequence cannot take are refused.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <set>

#include "core/error.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline_dird_reference.hpp"
#include "pipeline_fake_dataset.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"
#include "stages/match/sequence_matcher.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::read_csv;
using testing::read_file;
using testing::RevisitDataset;

constexpr std::size_t kPeriod = 120;
constexpr std::size_t kLaps = 3;

PipelineConfig standard_config(RunMode mode, int threads = 2) {
  PipelineConfig config = testing::revisit_config(Detector::kDird, mode, threads);
  config.match.nms_half_window = 20;
  config.dird.normalization = DirdNormalization::kL2;
  config.standardize.mode = StandardizeMode::kCausal;
  testing::small_standardize(config.standardize);
  return config;
}

using Cell = std::pair<std::int64_t, std::int64_t>;  // (i, j)
using testing::read_cells;

std::vector<LoopClosure> read_loops(const fs::path& file) {
  std::vector<LoopClosure> loops;
  for (const auto& row : read_csv(file))
    loops.push_back({std::stoll(row[0]), std::stoll(row[1]), std::stod(row[4])});
  return loops;
}

// S(j, i) for every pair i - j >= margin of the first `frames` frames, from codes made by the causal rule
// over the observed frames (seq % observe_every == 0) of those frames. A row before the frame that completes
// the warm-up is empty (its codes would need that later frame's statistics).
std::vector<std::vector<SimilarityEntry>> reference_columns(const Dataset& dataset,
                                                            const PipelineConfig& config,
                                                            std::size_t frames) {
  const auto [codes, ready_frame] =
      testing::reference_codes(dataset, config.dird, config.standardize, frames);
  const LogisticScale scale = standard_default_scale(config.standardize, config.dird.tau1);
  std::vector<std::vector<SimilarityEntry>> columns(frames);
  for (std::size_t i = ready_frame; i < frames; ++i) {
    for (std::size_t j = 0; j + static_cast<std::size_t>(config.match.margin) <= i; ++j) {
      const double d = standard_cosine_distance(codes[i], codes[j]);
      if (d >= scale.cutoff_distance) continue;
      const double sim = logistic_similarity(d, scale.mu, scale.sigma);
      if (sim > config.dird.tau1) columns[i].push_back({static_cast<std::int64_t>(j), sim});
    }
  }
  return columns;
}

void expect_loops(const std::vector<LoopClosure>& loops, const std::vector<LoopClosure>& expected) {
  ASSERT_EQ(loops.size(), expected.size());
  for (std::size_t k = 0; k < loops.size(); ++k) {
    EXPECT_EQ(loops[k].i, expected[k].i) << k;
    EXPECT_EQ(loops[k].j, expected[k].j) << k;
    EXPECT_NEAR(loops[k].score, expected[k].score, 5e-7) << k;  // loops.csv keeps 6 decimals
  }
}

TEST(PipelineStandardDird, FullIsTheBatchResultAndGatedTheSameRestrictedToItsCells) {
  const RevisitDataset dataset(kPeriod, kLaps);
  const std::size_t frames = kPeriod * kLaps;
  const auto out_full = testing::make_temp_dir("pipeline-std-full");
  const auto out_gated = testing::make_temp_dir("pipeline-std-gated");
  const PipelineConfig full = standard_config(RunMode::kFull);
  const PipelineConfig gated = standard_config(RunMode::kGated);
  const RunResult result_full = run_pipeline(full, dataset, out_full);
  ASSERT_FALSE(result_full.failed) << result_full.error;
  const RunResult result_gated = run_pipeline(gated, dataset, out_gated);
  ASSERT_FALSE(result_gated.failed) << result_gated.error;

  const auto columns = reference_columns(dataset, full, frames);
  const std::vector<LoopClosure> full_loops = read_loops(out_full / "loops.csv");
  expect_loops(full_loops, match_batch(columns, full.match));
  EXPECT_GT(full_loops.size(), 0u);

  const std::set<Cell> cells = read_cells(out_gated / "candidate_cells.csv");
  ASSERT_FALSE(cells.empty());
  std::vector<std::vector<SimilarityEntry>> restricted(frames);
  for (std::size_t i = 0; i < frames; ++i) {
    for (const SimilarityEntry& e : columns[i]) {
      if (cells.count({static_cast<std::int64_t>(i), e.j})) restricted[i].push_back(e);
    }
  }
  const std::vector<LoopClosure> gated_loops = read_loops(out_gated / "loops.csv");
  expect_loops(gated_loops, match_batch(restricted, gated.match));
  EXPECT_GT(gated_loops.size(), 0u);

  const auto s_full = nlohmann::json::parse(read_file(out_full / "summary.json"));
  const auto s_gated = nlohmann::json::parse(read_file(out_gated / "summary.json"));
  // Every observed frame is described (the gated run at its own time, outside areas too).
  EXPECT_EQ(s_full["standardize"]["observations"].get<std::size_t>(), frames / 2);
  EXPECT_EQ(s_gated["standardize"]["observations"].get<std::size_t>(), frames / 2);
  EXPECT_LE(s_gated["descriptors_computed"].get<std::size_t>(), frames);
  EXPECT_EQ(s_gated["similarities_computed"].get<std::size_t>(), cells.size());
  EXPECT_FALSE(s_gated["scale"]["estimated"].get<bool>());
}

TEST(PipelineStandardDird, CausalAPrefixRunGivesTheWholeRunsRowsRestrictedToIt) {
  const RevisitDataset dataset(kPeriod, kLaps);
  const std::size_t prefix = 2 * kPeriod + 40;
  PipelineConfig config = standard_config(RunMode::kFull);
  config.run.frames = ":" + std::to_string(prefix);
  const auto out = testing::make_temp_dir("pipeline-std-prefix");
  ASSERT_FALSE(run_pipeline(config, dataset, out).failed);
  // The reference of all frames, cut to the prefix afterwards: a frame's row must not have used later frames.
  auto columns = reference_columns(dataset, config, kPeriod * kLaps);
  columns.resize(prefix);
  expect_loops(read_loops(out / "loops.csv"), match_batch(columns, config.match));
}

TEST(PipelineStandardDird, OneAndTwoThreadsGiveIdenticalOutputs) {
  const RevisitDataset dataset(kPeriod, kLaps);
  for (const RunMode mode : {RunMode::kFull, RunMode::kGated}) {
    const auto out1 = testing::make_temp_dir("pipeline-std-t1");
    const auto out2 = testing::make_temp_dir("pipeline-std-t2");
    ASSERT_FALSE(run_pipeline(standard_config(mode, 1), dataset, out1).failed);
    ASSERT_FALSE(run_pipeline(standard_config(mode, 2), dataset, out2).failed);
    for (const char* file : {"loops.csv", "frames.csv"})
      EXPECT_EQ(read_file(out1 / file), read_file(out2 / file)) << file << " " << enum_name(mode);
  }
}

TEST(PipelineStandardDird, OnlineScaleIsEstimatedFromTheRunsDistances) {
  const RevisitDataset dataset(kPeriod, kLaps);
  PipelineConfig config = standard_config(RunMode::kFull);
  config.scale.mode = ScaleMode::kOnline;
  config.scale.min_distances = 5000;
  const auto out = testing::make_temp_dir("pipeline-std-online");
  ASSERT_FALSE(run_pipeline(config, dataset, out).failed);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["scale"]["estimated"].get<bool>());
  EXPECT_EQ(summary["scale"]["distances"].get<std::size_t>(),
            summary["similarities_computed"].get<std::size_t>());
  EXPECT_GT(summary["scale"]["sigma"].get<double>(), 0.0);
}

TEST(PipelineStandardDird, OptionsASingleSequenceCannotTakeAreRefused) {
  const RevisitDataset dataset(kPeriod, 1);
  PipelineConfig batch = standard_config(RunMode::kFull);
  batch.standardize.mode = StandardizeMode::kBatch;
  const auto out = testing::make_temp_dir("pipeline-std-refused");
  try {
    run_pipeline(batch, dataset, out);
    FAIL() << "standardize.mode batch was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("standardize.mode"), std::string::npos) << e.what();
  }
  PipelineConfig online_gated = standard_config(RunMode::kGated);
  online_gated.scale.mode = ScaleMode::kOnline;
  try {
    run_pipeline(online_gated, dataset, out);
    FAIL() << "scale.mode online with run.mode gated was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("scale.mode"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace loopgate
