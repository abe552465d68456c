// Gated SeqSLAM end to end: `loopgate simulate --preset aliasing`, then `loopgate run --method
// seqslam` with --mode gated and --mode full on it (configs/aliasing.yaml). The run says which SeqSLAM it
// runs; the gated one writes the gate's files and columns, preprocesses and compares far less, and where the
// full run's best match is a covered cell it reports the same frame (full SeqSLAM restricted to the covered
// cells, stages/seqslam/seqslam_gated.hpp); it loses the aliased places' false matches, so its AP is higher;
// 1 and 2 threads write identical outputs.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <utility>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

const fs::path kConfig = fs::path(LOOPGATE_SOURCE_DIR) / "configs" / "aliasing.yaml";

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " " + args, &output);
  return output;
}

// The rendered street, once for all tests of this file (empty path: the simulation failed, log in error).
const fs::path& dataset(std::string* error) {
  static std::string log;
  static const fs::path dir = [] {
    const fs::path out = testing::make_temp_dir("e2e-seqslam-gated-data");
    int status = -1;
    log = run("--log-level warn simulate --preset aliasing --out " + out.string(), &status);
    return status == 0 ? out : fs::path();
  }();
  *error = log;
  return dir;
}

// `loopgate run --method seqslam --mode MODE` into a fresh folder; its log (info level) in *log.
fs::path run_seqslam(const std::string& mode, int threads, std::string* log) {
  std::string error;
  const fs::path& data = dataset(&error);
  EXPECT_FALSE(data.empty()) << error;
  const fs::path out = testing::make_temp_dir("e2e-seqslam-" + mode);
  int status = -1;
  *log = run("run --config " + kConfig.string() + " --dataset " + data.string() +
                 " --method seqslam --mode " + mode + " --threads " + std::to_string(threads) + " --out " +
                 out.string() + " --set output.progress=off",
             &status);
  EXPECT_EQ(status, 0) << *log;
  return out;
}

struct Frames {
  std::vector<std::string> match, detection;
};

Frames read_frames(const fs::path& file) {
  std::vector<std::string> header;
  const auto rows = testing::read_csv(file, &header);
  Frames f;
  for (const auto& row : rows) {
    f.match.push_back(row[testing::column_index(header, "match_frame")]);
    f.detection.push_back(row[testing::column_index(header, "detection")]);
  }
  return f;
}

TEST(E2eSeqSlamGated, GatedAndFullOnTheAliasingPreset) {
  std::string gated_log, full_log;
  const fs::path gated = run_seqslam("gated", 2, &gated_log);
  const fs::path full = run_seqslam("full", 2, &full_log);
  EXPECT_NE(gated_log.find("run: SeqSLAM gated"), std::string::npos) << gated_log;
  EXPECT_NE(full_log.find("run: SeqSLAM full"), std::string::npos) << full_log;

  const auto g = nlohmann::json::parse(testing::read_file(gated / "summary.json"));
  const auto f = nlohmann::json::parse(testing::read_file(full / "summary.json"));
  EXPECT_EQ(g["method"], "seqslam");
  EXPECT_EQ(g["mode"], "gated");
  EXPECT_EQ(f["method"], "seqslam");
  EXPECT_EQ(f["mode"], "full");
  EXPECT_EQ(g["score_order"], "lower_is_better");
  EXPECT_EQ(g["evaluation"]["precision_recall"]["score_order"], "lower_is_better");
  EXPECT_TRUE(g["gate"]["enabled"].get<bool>());
  EXPECT_FALSE(f["gate"]["enabled"].get<bool>());
  for (const char* file : {"candidate_areas.csv", "candidate_cells.csv", "descriptors.csv"}) {
    EXPECT_TRUE(fs::exists(gated / file)) << file;
    EXPECT_FALSE(fs::exists(full / file)) << file;
  }
  EXPECT_EQ(f["descriptors_computed"].get<std::size_t>(), 490u);
  EXPECT_LT(g["descriptors_computed"].get<std::size_t>(), 490u / 2);
  EXPECT_LT(g["similarities_computed"].get<std::size_t>(), f["similarities_computed"].get<std::size_t>() / 4);
  EXPECT_TRUE(g["evaluation"].contains("gate_coverage"));

  // Where the full run's best match is a covered cell, the gated run reports the same frame.
  std::set<std::pair<std::size_t, std::size_t>> cells;
  for (const auto& row : testing::read_csv(gated / "candidate_cells.csv"))
    for (std::size_t j = std::stoul(row[1]); j <= std::stoul(row[2]); ++j)
      cells.insert({std::stoul(row[0]), j});
  const Frames fg = read_frames(gated / "frames.csv");
  const Frames ff = read_frames(full / "frames.csv");
  ASSERT_EQ(fg.match.size(), 490u);
  ASSERT_EQ(ff.match.size(), 490u);
  std::size_t compared = 0;
  for (std::size_t i = 0; i < ff.match.size(); ++i) {
    if (ff.match[i].empty() || !cells.count({i, std::stoul(ff.match[i])})) continue;
    ++compared;
    EXPECT_EQ(fg.match[i], ff.match[i]) << "query " << i;
  }
  EXPECT_GT(compared, 20u);

  // The aliased places' matches are gone: fewer false loops, a higher AP.
  EXPECT_LT(g["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>(),
            f["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>());
  EXPECT_GT(g["evaluation"]["loop_truth"]["loops_true"].get<std::size_t>(), 0u);
  EXPECT_GT(g["evaluation"]["precision_recall"]["average_precision"].get<double>(),
            f["evaluation"]["precision_recall"]["average_precision"].get<double>());
}

TEST(E2eSeqSlamGated, OneAndTwoThreadsWriteIdenticalOutputs) {
  std::string log1, log2;
  const fs::path one = run_seqslam("gated", 1, &log1);
  const fs::path two = run_seqslam("gated", 2, &log2);
  for (const char* file :
       {"loops.csv", "frames.csv", "candidate_areas.csv", "candidate_cells.csv", "descriptors.csv"})
    EXPECT_EQ(testing::read_file(one / file), testing::read_file(two / file)) << file;
  const auto s1 = nlohmann::json::parse(testing::read_file(one / "summary.json"));
  const auto s2 = nlohmann::json::parse(testing::read_file(two / "summary.json"));
  EXPECT_EQ(s1["evaluation"], s2["evaluation"]);
  EXPECT_EQ(s1["seqslam_gated"], s2["seqslam_gated"]);
}

}  // namespace
}  // namespace loopgate
