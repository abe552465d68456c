// Gated SeqSLAM (run.method seqslam, run.mode gated) through the pipeline, on a generated drive of three laps
// with a perceptual-aliasing detour (the same views 500 m away). The checks:
//   - every query's match is full SeqSLAM's step 4 on the run's frames, with the minimum the run subtracted,
//     restricted to the start rows whose match is a cell of candidate_cells.csv (the invariant of
//     stages/seqslam/seqslam_gated.hpp, recomputed here from the images), and loops.csv holds the accepted
//     ones;
//   - where the full SeqSLAM run's best match is a covered cell, the gated run reports the same frame;
//   - each frame is preprocessed at most once, every frame of a covered cell is, and far fewer than all;
//   - full SeqSLAM's best match of a detour frame is the place it shows, 500 m away; gated SeqSLAM searches
//     nothing there;
//   - 1 and 2 worker threads give identical outputs; run.mode full still gives full SeqSLAM.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "pipeline/pipeline.hpp"
#include "pipeline_fake_dataset.hpp"
#include "stages/seqslam/seqslam.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::read_csv;
using testing::read_file;
using testing::RevisitDataset;

constexpr std::size_t kPeriod = 120;
constexpr std::size_t kDetourBegin = 250, kDetourEnd = 300;  // third lap, 500 m away
constexpr double kInf = std::numeric_limits<double>::infinity();

PipelineConfig gated_config(int threads = 2) {
  PipelineConfig config = testing::revisit_config(Detector::kSeqSlam, RunMode::kGated, threads);
  config.seqslam.exclusion = SeqSlamExclusionKind::kPast;
  config.seqslam.exclusion_margin_frames = 30;  // = match.margin
  config.eval.truth_radius_m = 2.0;
  return config;
}

RevisitDataset detour_dataset() {
  return testing::detour_dataset(kPeriod, kDetourBegin, kDetourEnd);
}

using Cell = std::pair<std::size_t, std::size_t>;  // (query i, reference j)

std::set<Cell> read_cells(const fs::path& file) {
  std::set<Cell> cells;
  for (const auto& row : read_csv(file)) {
    const std::size_t i = std::stoul(row[0]);
    for (std::size_t j = std::stoul(row[1]); j <= std::stoul(row[2]); ++j) cells.insert({i, j});
  }
  return cells;
}

struct FrameRow {
  std::string detection, match, score, reason;
};

std::vector<FrameRow> read_frames(const fs::path& file) {
  std::vector<std::string> header;
  const auto rows = read_csv(file, &header);
  const auto col = [&](const std::string& name) { return testing::column_index(header, name); };
  std::vector<FrameRow> out;
  for (const auto& row : rows) {
    out.push_back({row[col("detection")], row[col("match_frame")], row[col("match_score")],
                   row[col("detection_reason")]});
  }
  return out;
}

// The run's frames preprocessed as the method does, the full run's E (step 3, before its minimum).
SeqSlamMatrix full_enhanced(const Dataset& dataset, const SeqSlamConfig& config) {
  const SeqSlam seqslam(config);
  SeqSlamImages images(static_cast<std::size_t>(config.image_width_px * config.image_height_px));
  for (std::size_t k = 0; k < dataset.frame_count(); ++k)
    images.add(seqslam.preprocess(dataset.load_image(k)));
  const std::size_t n = images.size();
  SeqSlamMatrix E(n, n);
  seqslam_difference_block(images, images, SeqSlamExclusion::from_config(config), 0, n, 0, n, E);
  seqslam_enhance_contrast(E, config.contrast_window_rows, 0, n);
  return E;
}

TEST(PipelineSeqSlamGated, MatchesAreFullSeqSlamRestrictedToTheCoveredCells) {
  const RevisitDataset dataset = detour_dataset();
  const PipelineConfig config = gated_config();
  const auto out = testing::make_temp_dir("pipeline-seqslam-gated");
  const RunResult result = run_pipeline(config, dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  ASSERT_EQ(result.frames_processed, 3 * kPeriod);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["method"], "seqslam");
  EXPECT_EQ(summary["mode"], "gated");
  EXPECT_EQ(summary["score_order"], "lower_is_better");
  EXPECT_TRUE(summary["gate"]["enabled"].get<bool>());

  const std::set<Cell> cells = read_cells(out / "candidate_cells.csv");
  ASSERT_FALSE(cells.empty());
  const double minimum = summary["seqslam_gated"]["minimum_subtracted"].get<double>();
  SeqSlamMatrix E = full_enhanced(dataset, config.seqslam);
  seqslam_subtract(E, minimum, 0, E.query_count());
  const auto h = static_cast<std::size_t>(config.seqslam.sequence_length_frames / 2);

  const std::vector<FrameRow> frames = read_frames(out / "frames.csv");
  ASSERT_EQ(frames.size(), 3 * kPeriod);
  std::set<Cell> accepted;
  std::size_t matched = 0;
  for (std::size_t query = 0; query < frames.size(); ++query) {
    std::vector<double> scores = seqslam_sequence_scores(E, query, config.seqslam);
    bool row_covered = false;
    for (std::size_t s = 0; s < scores.size(); ++s) {
      if (!cells.count({query, s + h})) scores[s] = kInf;
    }
    for (const auto& [i, j] : cells) row_covered = row_covered || i == query;
    const SeqSlamMatch m = seqslam_match_from_scores(query, scores.data(), scores.size(), 0, config.seqslam);
    const FrameRow& row = frames[query];
    const std::string where = "query " + std::to_string(query);
    if (!row_covered) {
      EXPECT_EQ(row.reason, "outside every candidate area") << where;
    }
    if (!m.has_match) {
      EXPECT_EQ(row.detection, "no match") << where;
      EXPECT_EQ(row.match, "") << where;
      continue;
    }
    ++matched;
    EXPECT_EQ(row.match, std::to_string(m.reference)) << where;
    if (std::isfinite(m.ratio)) {
      EXPECT_NEAR(std::stod(row.score), m.ratio, 5e-7) << where;  // frames.csv keeps 6 decimals
    } else {
      EXPECT_EQ(row.score, "inf") << where;
    }
    EXPECT_EQ(row.detection, m.accepted ? "loop" : "rejected") << where;
    if (m.accepted) accepted.insert({query, m.reference});
  }
  EXPECT_GT(matched, 50u);
  std::set<Cell> loops;
  for (const auto& row : read_csv(out / "loops.csv")) loops.insert({std::stoul(row[0]), std::stoul(row[1])});
  EXPECT_EQ(loops, accepted);
  EXPECT_GT(loops.size(), 10u);

  // Each frame preprocessed once; every frame of a covered cell among them; far fewer than all.
  std::set<std::size_t> of_cells, listed;
  for (const auto& [i, j] : cells) {
    of_cells.insert(i);
    of_cells.insert(j);
  }
  for (const auto& row : read_csv(out / "descriptors.csv")) {
    EXPECT_TRUE(listed.insert(std::stoul(row[0])).second) << "frame " << row[0] << " preprocessed twice";
    EXPECT_LE(std::stoul(row[0]), std::stoul(row[1]));
    EXPECT_EQ(row[2], "y");
  }
  for (const std::size_t k : of_cells) EXPECT_TRUE(listed.count(k)) << "frame " << k;
  const auto& counts = summary["seqslam_gated"];
  EXPECT_EQ(summary["descriptors_computed"].get<std::size_t>(), listed.size());
  EXPECT_EQ(counts["frames_requested"].get<std::size_t>(), listed.size());
  EXPECT_EQ(counts["frames_of_cells"].get<std::size_t>(), of_cells.size());
  EXPECT_LE(counts["frames_read"].get<std::size_t>(), listed.size());
  EXPECT_LT(listed.size(), 3 * kPeriod);
  EXPECT_EQ(summary["similarities_computed"], counts["difference_entries"]);
  EXPECT_EQ(summary["gate"]["cells"].get<std::size_t>(), cells.size());
}

TEST(PipelineSeqSlamGated, SameMatchAsFullWhereFullMatchesACoveredCellAndNothingInTheDetour) {
  const RevisitDataset dataset = detour_dataset();
  PipelineConfig full = gated_config();
  full.run.mode = RunMode::kFull;
  const auto out_full = testing::make_temp_dir("pipeline-seqslam-full");
  const auto out_gated = testing::make_temp_dir("pipeline-seqslam-gated-vs-full");
  ASSERT_FALSE(run_pipeline(full, dataset, out_full).failed);
  ASSERT_FALSE(run_pipeline(gated_config(), dataset, out_gated).failed);
  const auto summary_full = nlohmann::json::parse(read_file(out_full / "summary.json"));
  EXPECT_EQ(summary_full["mode"], "full");
  EXPECT_EQ(summary_full["descriptors_computed"].get<std::size_t>(), 3 * kPeriod);
  EXPECT_FALSE(fs::exists(out_full / "candidate_cells.csv"));

  const std::set<Cell> cells = read_cells(out_gated / "candidate_cells.csv");
  const std::vector<FrameRow> f = read_frames(out_full / "frames.csv");
  const std::vector<FrameRow> g = read_frames(out_gated / "frames.csv");
  ASSERT_EQ(f.size(), g.size());
  std::size_t compared = 0;
  for (std::size_t query = 0; query < f.size(); ++query) {
    if (f[query].match.empty() || !cells.count({query, std::stoul(f[query].match)})) continue;
    ++compared;
    EXPECT_EQ(g[query].match, f[query].match) << "query " << query;
  }
  EXPECT_GT(compared, 50u);

  // Full SeqSLAM's best match of a detour frame is the place it shows, 500 m away (the ratio test then
  // rejects most of them: laps 1 and 2 both look alike); the gate knows the detour is far from everything: no
  // cell, no match there (an area opening after it reaches back area_margin_query_frames rows).
  const std::size_t reach_back = static_cast<std::size_t>(gated_config().gate.area_margin_query_frames);
  std::size_t full_aliased = 0;
  for (std::size_t query = kDetourBegin; query < kDetourEnd - reach_back; ++query) {
    if (!f[query].match.empty()) {
      const std::size_t shift = (query - std::stoul(f[query].match)) % kPeriod;
      full_aliased += shift <= 1 || shift + 1 == kPeriod ? 1 : 0;
    }
    EXPECT_EQ(g[query].detection, "no match") << "query " << query;
    EXPECT_EQ(g[query].reason, "outside every candidate area") << "query " << query;
  }
  EXPECT_GT(full_aliased, 30u);
  const auto summary_gated = nlohmann::json::parse(read_file(out_gated / "summary.json"));
  EXPECT_EQ(summary_gated["evaluation"]["gate_coverage"]["covered_fraction"].get<double>(), 1.0);
  EXPECT_LT(summary_gated["similarities_computed"].get<std::size_t>(),
            summary_full["similarities_computed"].get<std::size_t>() / 2);
}

TEST(PipelineSeqSlamGated, OneAndTwoThreadsGiveIdenticalOutputs) {
  const RevisitDataset dataset = detour_dataset();
  const auto out1 = testing::make_temp_dir("pipeline-seqslam-gated-t1");
  const auto out2 = testing::make_temp_dir("pipeline-seqslam-gated-t2");
  ASSERT_FALSE(run_pipeline(gated_config(1), dataset, out1).failed);
  ASSERT_FALSE(run_pipeline(gated_config(2), dataset, out2).failed);
  for (const char* file :
       {"loops.csv", "frames.csv", "candidate_areas.csv", "candidate_cells.csv", "descriptors.csv"})
    EXPECT_EQ(read_file(out1 / file), read_file(out2 / file)) << file;
  const auto s1 = nlohmann::json::parse(read_file(out1 / "summary.json"));
  const auto s2 = nlohmann::json::parse(read_file(out2 / "summary.json"));
  EXPECT_EQ(s1["evaluation"], s2["evaluation"]);
  EXPECT_EQ(s1["seqslam_gated"], s2["seqslam_gated"]);
}

TEST(PipelineSeqSlamGated, UnreadablePastFrameTakesPartAsAZeroImage) {
  RevisitDataset dataset = detour_dataset();
  dataset.corrupt_frames = {130};  // a reference the second lap's area needs
  const auto out = testing::make_temp_dir("pipeline-seqslam-gated-corrupt");
  const RunResult result = run_pipeline(gated_config(), dataset, out);
  ASSERT_FALSE(result.failed) << result.error;
  EXPECT_EQ(result.frames_processed, 3 * kPeriod);
  EXPECT_NE(read_file(out / "frames.csv").find("frame 130 could not be read"), std::string::npos);
  bool listed_not_computed = false;
  for (const auto& row : read_csv(out / "descriptors.csv"))
    listed_not_computed = listed_not_computed || (row[0] == "130" && row[2] == "n");
  EXPECT_TRUE(listed_not_computed);
  EXPECT_GT(read_csv(out / "loops.csv").size(), 0u);
}

}  // namespace
}  // namespace loopgate
