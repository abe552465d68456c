// Gated mode (run.mode = gated) of the pipeline: the pose gate and the candidate areas decide which
// descriptors and similarities are computed (pose-gating.md §4-5). The checks:
//   - the run's loop closures are exactly what the batch DP + NMS give on S restricted to the cells the run
//     reports in candidate_cells.csv (so S is computed exactly there, and nothing else is used);
//   - inside the areas, every DP value whose whole path lies in the covered cells equals the full run's
//     (the invariant of pose-gating.md §5);
//   - descriptors are computed once each, exactly for the frames those cells touch, and images are read
//     only for them;
//   - a perceptual-aliasing detour (the same views 500 m away) gives full DIRD false loops and gated none;
//   - 1 and 2 worker threads give identical outputs.
#include <gtest/gtest.h>

#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>

#include "pipeline/pipeline.hpp"
#include "pipeline_fake_dataset.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::read_csv;
using testing::read_file;
using testing::RevisitDataset;

constexpr std::size_t kPeriod = 120;
constexpr std::size_t kDetourBegin = 250, kDetourEnd = 300;  // third lap, 500 m away

PipelineConfig gated_config(int threads = 2) {
  PipelineConfig config = testing::revisit_config(Detector::kDird, RunMode::kGated, threads);
  config.match.nms_half_window = 20;
  config.eval.truth_radius_m = 2.0;
  return config;
}

RevisitDataset detour_dataset() {
  return testing::detour_dataset(kPeriod, kDetourBegin, kDetourEnd);
}

using Cell = std::pair<std::int64_t, std::int64_t>;  // (i, j)
using testing::read_cells;

std::vector<LoopClosure> read_loops(const fs::path& file) {
  std::vector<LoopClosure> loops;
  for (const auto& row : read_csv(file))
    loops.push_back({std::stoll(row[0]), std::stoll(row[1]), std::stod(row[4])});
  return loops;
}

struct Reference {
  std::vector<std::vector<SimilarityEntry>> full;        // S(., i) for all j <= i - margin
  std::vector<std::vector<SimilarityEntry>> restricted;  // only the covered cells
};

Reference similarity_columns(const Dataset& dataset, const PipelineConfig& config,
                             const std::set<Cell>& cells) {
  const DirdExtractor extractor(config.dird);
  const DirdSimilarity similarity(config.dird);
  std::vector<Descriptor> descriptors;
  for (std::size_t k = 0; k < dataset.frame_count(); ++k)
    descriptors.push_back(extractor.extract(dataset.load_image(k)));
  Reference ref;
  ref.full.resize(descriptors.size());
  similarity.sparse_columns(descriptors, config.match.margin, 0, descriptors.size(), ref.full);
  ref.restricted.resize(descriptors.size());
  for (const auto& [i, j] : cells) {
    std::vector<SimilarityEntry> one;
    similarity.sparse_row(descriptors[static_cast<std::size_t>(i)], &descriptors[static_cast<std::size_t>(j)],
                          1, j, one);
    for (const auto& e : one) ref.restricted[static_cast<std::size_t>(i)].push_back(e);
  }
  return ref;
}

std::map<Cell, double> dp_values(const std::vector<std::vector<SimilarityEntry>>& columns,
                                 MatchConfig config) {
  config.tau3 = 0.0;  // every DP value > 0
  std::map<Cell, double> out;
  for (const LoopClosure& e : sequence_dp_batch(columns, config)) out[{e.i, e.j}] = e.score;
  return out;
}

TEST(PipelineGatedMode, LoopsAreTheBatchResultOnTheCoveredCellsAndDpEqualsFullInside) {
  const RevisitDataset dataset = detour_dataset();
  const PipelineConfig config = gated_config();
  const auto out = testing::make_temp_dir("pipeline-gated");
  const RunResult result = run_pipeline(config, dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  ASSERT_EQ(result.frames_processed, 3 * kPeriod);

  const std::set<Cell> cells = read_cells(out / "candidate_cells.csv");
  ASSERT_FALSE(cells.empty());
  std::set<std::int64_t> touched;
  for (const auto& [i, j] : cells) {
    ASSERT_GE(i - j, config.match.margin);
    touched.insert(i);
    touched.insert(j);
  }
  const Reference ref = similarity_columns(dataset, config, cells);

  // The run's loops are exactly the batch DP + NMS on S restricted to its cells.
  const std::vector<LoopClosure> loops = read_loops(out / "loops.csv");
  const std::vector<LoopClosure> expected = match_batch(ref.restricted, config.match);
  ASSERT_EQ(loops.size(), expected.size());
  for (std::size_t k = 0; k < loops.size(); ++k) {
    EXPECT_EQ(loops[k].i, expected[k].i);
    EXPECT_EQ(loops[k].j, expected[k].j);
    EXPECT_NEAR(loops[k].score, expected[k].score, 5e-7);  // loops.csv keeps 6 decimals
  }
  EXPECT_GT(loops.size(), 0u);

  // Inside the areas, a DP value whose whole path (L columns back, up to max_step rows per column) lies in
  // covered cells (or before the margin, missing in both runs) equals the full run's.
  const auto dp_full = dp_values(ref.full, config.match);
  const auto dp_gated = dp_values(ref.restricted, config.match);
  const auto L = static_cast<std::int64_t>(config.match.sequence_length);
  const auto step = static_cast<std::int64_t>(config.match.max_step);
  std::size_t checked = 0;
  for (const auto& [i, j] : cells) {
    bool inside = i - (L - 1) >= 0;
    for (std::int64_t k = 0; inside && k < L; ++k) {
      for (std::int64_t r = std::max<std::int64_t>(0, j - k * step); inside && r <= j; ++r) {
        const bool beyond_margin = (i - k) - r >= config.match.margin;
        inside = !beyond_margin || cells.count({i - k, r}) == 1;
      }
    }
    if (!inside) continue;
    ++checked;
    const auto a = dp_full.find({i, j});
    const auto b = dp_gated.find({i, j});
    ASSERT_EQ(a == dp_full.end(), b == dp_gated.end()) << "cell " << i << "," << j;
    if (a != dp_full.end()) {
      EXPECT_DOUBLE_EQ(a->second, b->second) << "cell " << i << "," << j;
    }
  }
  EXPECT_GT(checked, cells.size() / 2);

  // Descriptors once each, exactly for the touched frames; images read only for them (drift odometry
  // needs no pixels); similarities exactly for the cells.
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["descriptors_computed"].get<std::size_t>(), touched.size());
  EXPECT_EQ(summary["images_decoded"].get<std::size_t>(), touched.size());
  EXPECT_EQ(summary["similarities_computed"].get<std::size_t>(), cells.size());
  EXPECT_EQ(summary["gate"]["cells"].get<std::size_t>(), cells.size());
  EXPECT_LT(touched.size(), 3 * kPeriod);
  EXPECT_GE(summary["candidate_areas"].get<std::size_t>(), 2u);

  // descriptors.csv lists exactly the touched frames, each once, requested no later than needed.
  std::set<std::int64_t> listed;
  for (const auto& row : read_csv(out / "descriptors.csv")) {
    EXPECT_TRUE(listed.insert(std::stoll(row[0])).second) << "frame " << row[0] << " described twice";
    EXPECT_LE(std::stoll(row[0]), std::stoll(row[1]));
    EXPECT_EQ(row[2], "y");
  }
  EXPECT_EQ(listed, touched);

  // frames.csv: one row per frame with the gate columns; "descriptor" says whether the frame was described
  // when its row was written (a frame can be described later, as the reference of a later area).
  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  const auto col = [&](const std::string& name) { return testing::column_index(header, name); };
  ASSERT_NO_THROW(col("area_id"));
  ASSERT_NO_THROW(col("gate_d_m"));
  ASSERT_EQ(rows.size(), 3 * kPeriod);
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const auto frame = static_cast<std::int64_t>(k);
    if (rows[k][col("descriptor")] == "y") {
      EXPECT_TRUE(touched.count(frame)) << "frame " << frame;
    }
    if (rows[k][col("gated")] == "y") {
      EXPECT_LT(std::stod(rows[k][col("gate_d_m")]), std::stod(rows[k][col("gate_threshold_m")]));
    }
  }
}

TEST(PipelineGatedMode, AliasingDetourGivesFullFalseLoopsAndGatedNone) {
  const RevisitDataset dataset = detour_dataset();
  PipelineConfig full = gated_config();
  full.run.mode = RunMode::kFull;
  const auto out_full = testing::make_temp_dir("pipeline-gated-alias-full");
  const auto out_gated = testing::make_temp_dir("pipeline-gated-alias-gated");
  ASSERT_FALSE(run_pipeline(full, dataset, out_full).failed);
  ASSERT_FALSE(run_pipeline(gated_config(), dataset, out_gated).failed);
  const auto in_detour = [](const LoopClosure& loop) {
    return loop.i >= static_cast<std::int64_t>(kDetourBegin) &&
           loop.i < static_cast<std::int64_t>(kDetourEnd);
  };
  // Full DIRD matches the detour's views with the places they show, 500 m away: false loops.
  std::size_t full_false = 0;
  for (const LoopClosure& loop : read_loops(out_full / "loops.csv")) full_false += in_detour(loop) ? 1 : 0;
  EXPECT_GT(full_false, 10u);
  // The gate knows the detour is far from everything: no area, no loop there (an area opening after the
  // detour reaches back area_margin_query_frames rows into it for the DP history).
  const auto reach_back = static_cast<std::int64_t>(gated_config().gate.area_margin_query_frames);
  for (const LoopClosure& loop : read_loops(out_gated / "loops.csv")) {
    EXPECT_FALSE(loop.i >= static_cast<std::int64_t>(kDetourBegin) &&
                 loop.i < static_cast<std::int64_t>(kDetourEnd) - reach_back)
        << loop.i << "," << loop.j;
  }
  const auto summary_full = nlohmann::json::parse(read_file(out_full / "summary.json"));
  const auto summary_gated = nlohmann::json::parse(read_file(out_gated / "summary.json"));
  EXPECT_GT(summary_full["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>(),
            summary_gated["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>());
  EXPECT_GT(summary_gated["evaluation"]["loop_truth"]["loops_true"].get<std::size_t>(), 0u);
  EXPECT_EQ(summary_gated["evaluation"]["gate_coverage"]["covered_fraction"].get<double>(), 1.0);
}

TEST(PipelineGatedMode, OneAndTwoThreadsGiveIdenticalOutputs) {
  const RevisitDataset dataset = detour_dataset();
  const auto out1 = testing::make_temp_dir("pipeline-gated-t1");
  const auto out2 = testing::make_temp_dir("pipeline-gated-t2");
  ASSERT_FALSE(run_pipeline(gated_config(1), dataset, out1).failed);
  ASSERT_FALSE(run_pipeline(gated_config(2), dataset, out2).failed);
  for (const char* file : {"loops.csv", "frames.csv", "candidate_areas.csv", "candidate_cells.csv"})
    EXPECT_EQ(read_file(out1 / file), read_file(out2 / file)) << file;
}

// With every frame decoded (as a visual odometry source needs), the recent images are kept: describe takes
// the rows just behind a new area from the cache instead of reading them again; results are unchanged.
TEST(PipelineGatedMode, ImageCacheServesRecentFramesWithIdenticalResults) {
  const RevisitDataset dataset = detour_dataset();
  PipelineConfig cached = gated_config();
  cached.run.decode = DecodePolicy::kAll;
  PipelineConfig uncached = cached;
  uncached.run.image_cache_frames = 0;
  const auto out_cached = testing::make_temp_dir("pipeline-gated-cache");
  const auto out_uncached = testing::make_temp_dir("pipeline-gated-nocache");
  const RunResult a = run_pipeline(cached, dataset, out_cached);
  const RunResult b = run_pipeline(uncached, dataset, out_uncached);
  ASSERT_FALSE(a.failed || b.failed);
  for (const char* file : {"loops.csv", "candidate_cells.csv", "descriptors.csv"})
    EXPECT_EQ(read_file(out_cached / file), read_file(out_uncached / file)) << file;
  EXPECT_GT(a.summary["image_cache_hits"].get<std::size_t>(), 0u);
  EXPECT_EQ(b.summary["image_cache_hits"].get<std::size_t>(), 0u);
  EXPECT_EQ(a.summary["images_read_for_description"].get<std::size_t>() +
                a.summary["image_cache_hits"].get<std::size_t>(),
            b.summary["images_read_for_description"].get<std::size_t>());
}

// When decode reads every frame (the ekf source tracks images; here run.decode all), a frame's own
// descriptor is computed from the image decode already holds: no frame is decoded a second time for its
// own describe. Only the past frames a later area asks for are read again (no image cache here), so the
// dataset's reads are one per frame plus one per descriptor requested by another frame.
TEST(PipelineGatedMode, OwnFrameIsDescribedFromTheTrackersImage) {
  RevisitDataset dataset = detour_dataset();
  std::mutex mutex;  // decode and describe run on several threads
  std::map<std::size_t, int> loads;
  dataset.on_load = [&](std::size_t frame) {
    const std::lock_guard lock(mutex);
    ++loads[frame];
  };
  PipelineConfig config = gated_config();
  config.run.decode = DecodePolicy::kAll;
  config.run.image_cache_frames = 0;
  const auto out = testing::make_temp_dir("pipeline-gated-own-image");
  const RunResult result = run_pipeline(config, dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  std::size_t own = 0, other = 0;
  for (const auto& row : read_csv(out / "descriptors.csv")) (row[0] == row[1] ? own : other) += 1;
  ASSERT_GT(own, 0u);
  ASSERT_GT(other, 0u);
  EXPECT_EQ(result.summary["images_read_for_description"].get<std::size_t>(), other);
  std::size_t total = 0;
  for (const auto& [frame, count] : loads) total += static_cast<std::size_t>(count);
  EXPECT_EQ(total, 3 * kPeriod + other);
  EXPECT_EQ(result.summary["time_accounting"]["decode_in_describe_ms"].get<double>() > 0, other > 0);
}

TEST(PipelineGatedMode, UnreadablePastFrameIsReportedAndTheRunCompletes) {
  RevisitDataset dataset = detour_dataset();
  dataset.corrupt_frames = {130};  // a reference the second lap's area needs
  const auto out = testing::make_temp_dir("pipeline-gated-corrupt");
  const RunResult result = run_pipeline(gated_config(), dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  EXPECT_EQ(result.frames_processed, 3 * kPeriod);
  const std::string frames = read_file(out / "frames.csv");
  EXPECT_NE(frames.find("frame 130 could not be read"), std::string::npos);
  EXPECT_GT(read_loops(out / "loops.csv").size(), 0u);
}

TEST(PipelineGatedMode, NeedsImages) {
  testing::FakeDataset dataset(50);
  dataset.images = false;
  const auto out = testing::make_temp_dir("pipeline-gated-noimages");
  try {
    run_pipeline(gated_config(), dataset, out);
    FAIL() << "gated mode without images accepted";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("--mode odometry"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace loopgate
