// `loopgate compare` end to end on the rendered aliasing street (configs/aliasing.yaml): full DIRD, gated
// DIRD and SeqSLAM in one command; compare.json holds one summary per method plus the ratios, the table names
// every method, the runs' folders exist, and the gated run computes fewer descriptors and no false loop
// while full DIRD reports the aliased ones; the time parts (decode + describe + match + rest = total) add up
// in every method's column. Bad --methods is a clear error.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

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

// One compare of every method on the rendered aliasing street, shared by the tests below.
class E2eCompare : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const fs::path data = testing::make_temp_dir("e2e-compare-data");
    int status = -1;
    output_ = new std::string(run("simulate --preset aliasing --out " + data.string(), &status));
    ASSERT_EQ(status, 0) << *output_;
    out_ = new fs::path(testing::make_temp_dir("e2e-compare-out"));
    *output_ = run("compare --config " + kConfig.string() + " --dataset " + data.string() + " --out " +
                       out_->string() + " --no-plots --set output.progress=off",
                   &status);
    status_ = status;
  }
  static void TearDownTestSuite() {
    delete output_;
    delete out_;
    output_ = nullptr;
    out_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(out_, nullptr);
    ASSERT_EQ(status_, 0) << *output_;
  }
  static inline std::string* output_ = nullptr;
  static inline fs::path* out_ = nullptr;
  static inline int status_ = -1;
};

TEST_F(E2eCompare, EveryMethodSideBySide) {
  const std::string& output = *output_;
  const fs::path& out = *out_;
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
  // The truth counted in 3-D, in the ground plane and before eval.min_travel_m, printed and stored.
  EXPECT_NE(output.find("ground-truth loop query frames: "), std::string::npos) << output;
  const auto& counts = compare["truth_counts"];
  EXPECT_EQ(counts["horizontal_plane"], "xy");  // the simulator's world is z up
  EXPECT_EQ(counts["min_travel_m"], 2.0);
  EXPECT_EQ(counts["positives"], full["evaluation"]["truth"]["positives"]);
  EXPECT_GT(counts["positives_3d"].get<int>(), 0);
  EXPECT_GE(counts["positives_horizontal"].get<int>(), counts["positives_3d"].get<int>());
  EXPECT_GE(counts["positives_without_min_travel"].get<int>(), counts["positives"].get<int>());
}

// The time accounting (docs/architecture.md § Time accounting): in every method's column decode + describe +
// match + rest = total, in summary.json, in compare.json's comparison and in the printed table; the total is
// every stage's CPU time plus the parallel helpers' and the end of the stream's (nothing left out, nothing
// counted twice); the images a gated method reads inside describe are booked as decode (the decode stage's
// own time plus those reads), and a full method reads none there.
TEST_F(E2eCompare, TimePartsAddUpInEveryMethod) {
  const auto compare = nlohmann::json::parse(testing::read_file(*out_ / "compare.json"));
  const auto& methods = compare["methods"];
  ASSERT_EQ(methods.size(), 8u);
  const auto near = [](double a, double b) { return std::abs(a - b) <= 1e-6 * std::max(1.0, std::abs(b)); };
  for (const auto& name_json : methods) {
    const std::string name = name_json.get<std::string>();
    SCOPED_TRACE(name);
    const auto& s = compare[name];
    const auto& t = s["time_accounting"];
    const double decode = t["decode_ms"], describe = t["describe_ms"], match = t["match_ms"],
                 rest = t["rest_ms"], total = t["total_ms"];
    EXPECT_TRUE(near(decode + describe + match + rest, total)) << t.dump();
    double stages = 0;
    for (const char* stage : {"sync", "decode", "odometry", "gate", "describe", "match", "sink"})
      stages += t["stages_cpu_ms"][stage].get<double>();
    EXPECT_TRUE(
        near(total, stages + t["parallel_ms"].get<double>() + t["end_of_stream_cpu_ms"].get<double>()))
        << t.dump();
    EXPECT_TRUE(near(decode, t["stages_cpu_ms"]["decode"].get<double>() +
                                 t["decode_in_describe_ms"].get<double>() -
                                 t["odometry_in_decode_ms"].get<double>()))
        << t.dump();
    EXPECT_GE(t["odometry_in_decode_ms"].get<double>(), 0.0);
    for (const double part : {decode, describe, match, rest}) EXPECT_GE(part, 0.0) << t.dump();
    EXPECT_GT(describe, 0.0);
    EXPECT_GT(match, 0.0);
    const bool gated = s["mode"] == "gated";
    if (gated) {
      ASSERT_GT(s["images_read_for_description"].get<std::size_t>(), 0u);
      EXPECT_GT(t["decode_in_describe_ms"].get<double>(), 0.0);
    } else {
      EXPECT_EQ(t["decode_in_describe_ms"].get<double>(), 0.0);
      EXPECT_EQ(s["images_read_for_description"].get<std::size_t>(), 0u);
    }
    // Full DIRD computes most similarities of a row inside describe (rows in parallel): booked as match.
    if (name == "full") {
      EXPECT_GT(t["match_in_describe_ms"].get<double>(), 0.0);
    }
    if (gated) {
      EXPECT_EQ(t["match_in_describe_ms"].get<double>(), 0.0);
    }
    const auto& stored = compare["comparison"]["time_parts_ms"][name];
    for (const char* part : {"decode_ms", "describe_ms", "match_ms", "rest_ms", "total_ms"})
      EXPECT_EQ(stored[part].get<double>(), t[part].get<double>()) << part;
  }
  for (const char* ratio :
       {"full_over_gated_decode_time", "full_over_gated_describe_time", "full_over_gated_match_time",
        "full_over_gated_total_time", "full_over_gated_describe_and_match_time"})
    EXPECT_GT(compare["comparison"][ratio].get<double>(), 0.0) << ratio;
  EXPECT_EQ(compare["comparison"]["paper_ratio_compares_with"], "full_over_gated_describe_and_match_time");

  // The printed rows add up too (each cell rounded to 0.1 ms).
  const auto cells = [&](const std::string& label) {
    const std::size_t at = output_->find("\n" + label + " ");
    EXPECT_NE(at, std::string::npos) << label << "\n" << *output_;
    std::istringstream line(output_->substr(at + 1 + label.size(), output_->find('\n', at + 1) - at - 1));
    std::vector<double> values;
    for (double v = 0; line >> v;) values.push_back(v);
    return values;
  };
  const auto decode = cells("  decode"), describe = cells("  describe"), match = cells("  match"),
             rest = cells("  rest"), total = cells("  total");
  ASSERT_EQ(total.size(), methods.size()) << *output_;
  for (std::size_t k = 0; k < total.size(); ++k) {
    ASSERT_EQ(decode.size(), total.size());
    ASSERT_EQ(describe.size(), total.size());
    ASSERT_EQ(match.size(), total.size());
    ASSERT_EQ(rest.size(), total.size());
    EXPECT_NEAR(decode[k] + describe[k] + match[k] + rest[k], total[k], 0.25) << methods[k];
  }
  EXPECT_NE(output_->find("compares with this one"), std::string::npos) << *output_;
}

TEST(E2eCompareOptions, UnknownMethodIsAClearError) {
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
