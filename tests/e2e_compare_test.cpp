// `loopgate compare` end to end on the rendered aliasing street (configs/aliasing.yaml): full DIRD, gated
// DIRD and SeqSLAM in one command; compare.json holds one summary per method plus the ratios, the table names
// every method, the runs' folders exist, and the gated run computes fewer descriptors and no false loop
// while full DIRD reports the aliased ones. Bad --methods is a clear error.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

const fs::path kConfig = fs::path(LOOPGATE_SOURCE_DIR) / "configs" / "aliasing.yaml";

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " --log-level warn " + args, &output);
  return output;
}

TEST(E2eCompare, EveryMethodSideBySide) {
  const fs::path data = testing::make_temp_dir("e2e-compare-data");
  int status = -1;
  std::string output = run("simulate --preset aliasing --out " + data.string(), &status);
  ASSERT_EQ(status, 0) << output;
  const fs::path out = testing::make_temp_dir("e2e-compare-out");
  output = run("compare --config " + kConfig.string() + " --dataset " + data.string() + " --out " +
                   out.string() + " --no-plots --set output.progress=off",
               &status);
  ASSERT_EQ(status, 0) << output;
  for (const char* row :
       {"full", "gated", "seqslam", "descriptors computed", "average precision", "full / gated"})
    EXPECT_NE(output.find(row), std::string::npos) << row << "\n" << output;

  const auto compare = nlohmann::json::parse(testing::read_file(out / "compare.json"));
  for (const char* method : {"full", "gated", "seqslam", "seqslam-gated", "std-full", "std-gated"}) {
    ASSERT_TRUE(compare.contains(method)) << method;
    EXPECT_TRUE(fs::exists(out / method / "frames.csv")) << method;
    EXPECT_TRUE(fs::exists(out / method / "loops.csv")) << method;
    EXPECT_TRUE(compare[method]["evaluation"]["available"].get<bool>()) << method;
  }
  EXPECT_EQ(compare["full"]["mode"], "full");
  EXPECT_EQ(compare["gated"]["mode"], "gated");
  EXPECT_EQ(compare["seqslam"]["method"], "seqslam");
  EXPECT_EQ(compare["std-gated"]["mode"], "gated");
  EXPECT_EQ(compare["std-gated"]["standardize"]["mode"], "causal");
  EXPECT_FALSE(compare["gated"].contains("standardize"));
  EXPECT_EQ(compare["seqslam"]["score_order"], "lower_is_better");
  const auto& full = compare["full"];
  const auto& gated = compare["gated"];
  EXPECT_LT(gated["descriptors_computed"].get<std::size_t>(),
            full["descriptors_computed"].get<std::size_t>());
  EXPECT_LT(gated["similarities_computed"].get<std::size_t>(),
            full["similarities_computed"].get<std::size_t>());
  EXPECT_GT(full["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>(), 0u);
  EXPECT_EQ(gated["evaluation"]["loop_truth"]["loops_false"].get<std::size_t>(), 0u);
  EXPECT_GT(gated["evaluation"]["loop_truth"]["loops_true"].get<std::size_t>(), 0u);
  EXPECT_GT(compare["comparison"]["full_over_gated_descriptors"].get<double>(), 1.0);
  EXPECT_TRUE(fs::exists(out / "gated" / "candidate_areas.csv"));
  EXPECT_TRUE(fs::exists(out / "gated" / "descriptor.csv"));
  // Issue 14: the truth counted in 3-D, in the ground plane and before eval.min_travel_m, printed and stored.
  EXPECT_NE(output.find("ground-truth loop query frames: "), std::string::npos) << output;
  const auto& counts = compare["truth_counts"];
  EXPECT_EQ(counts["horizontal_plane"], "xy");  // the simulator's world is z up
  EXPECT_EQ(counts["min_travel_m"], 2.0);
  EXPECT_EQ(counts["positives"], full["evaluation"]["truth"]["positives"]);
  EXPECT_GT(counts["positives_3d"].get<int>(), 0);
  EXPECT_GE(counts["positives_horizontal"].get<int>(), counts["positives_3d"].get<int>());
  EXPECT_GE(counts["positives_without_min_travel"].get<int>(), counts["positives"].get<int>());
}

TEST(E2eCompare, UnknownMethodIsAClearError) {
  const fs::path out = testing::make_temp_dir("e2e-compare-bad");
  int status = -1;
  const std::string output = run("compare --config " + kConfig.string() +
                                     " --dataset /nonexistent --methods full,bogus --out " + out.string(),
                                 &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(output.find("'bogus' is not one of full,gated,seqslam,seqslam-gated,std-full,std-gated"),
            std::string::npos)
      << output;
}

}  // namespace
}  // namespace loopgate
