// `loopgate aggregate` end to end: summaries the test writes (a run, a compare, an odometry run, a dataset
// folder and a run that stopped before its summary) become one table whose cells are the summaries' values;
// real run and compare outputs (a rendered aliasing excerpt) are read with the keys loopgate writes; bad
// JSON, a missing or mistyped key and an empty folder are errors naming the file (line, key) or folder.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct Result {
  int status = -1;
  std::string output;
};

Result loopgate(const std::string& args) {
  Result r;
  r.status =
      testing::run_command(testing::loopgate_binary().string() + " --log-level warn " + args, &r.output);
  return r;
}

void write(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file) << text;
}

// A summary as `loopgate run` writes it, with the fields the table reads.
json run_summary(const std::string& method, const std::string& mode, double ap, double wall_s) {
  return {
      {"mode", mode},
      {"method", method},
      {"wall_s", wall_s},
      {"realtime_factor", 12.5},
      {"frames_processed", 300},
      {"loops", 12},
      {"end_of_stream_ms", 5.0},
      {"stages", {{"describe", {{"total_ms", 100.0}}}, {"match", {{"total_ms", 20.25}}}}},
      {"config", {{"run", {{"dataset", "/data/demo"}}}, {"standardize", {{"mode", "off"}}}}},
      {"evaluation",
       {{"loop_truth", {{"loops_true", 10}, {"loops_false", 2}}},
        {"precision_recall",
         {{"average_precision", ap}, {"recall_at_100", 0.5}, {"recall_at_99", 0.6}, {"recall_at_95", 0.7}}}}},
      {"trajectory_accuracy", {{"available", true}, {"rmse_m", 0.72}}},
      {"provenance",
       {{"version", "0.1.0 (abc123)"},
        {"command_line", "build/release/loopgate run --config 'my configs/demo.yaml' --out x"},
        {"config_hash", "00112233aabbccdd"}}},
  };
}

// The rows of aggregate.csv by "run|method", each a map column -> cell.
std::map<std::string, std::map<std::string, std::string>> read_table(const fs::path& csv) {
  std::vector<std::string> header;
  const auto rows = testing::read_csv(csv, &header);
  std::map<std::string, std::map<std::string, std::string>> out;
  for (const auto& row : rows) {
    std::map<std::string, std::string> cells;
    for (std::size_t c = 0; c < header.size() && c < row.size(); ++c) cells[header[c]] = row[c];
    out[cells["run"] + "|" + cells["method"]] = cells;
  }
  return out;
}

TEST(E2eAggregate, RunsAndComparesBecomeOneTable) {
  const fs::path root = testing::make_temp_dir("e2e-aggregate");
  json run = run_summary("dird-seqslam", "gated", 0.9, 2.5);
  run["trajectory_accuracy_corrected"] = {{"available", true}, {"rmse_m", 0.4}};
  write(root / "a-run" / "summary.json", run.dump(1));
  write(root / "a-run" / "frames.csv", "seq,frame\n");

  json gated = run_summary("dird", "gated", 0.8, 1.5);
  gated["loop_correction"] = {{"trajectory_accuracy_corrected", {{"available", true}, {"rmse_m", 0.3}}}};
  json seqslam = run_summary("seqslam", "full", 0.0, 3.0);
  seqslam.erase("evaluation");  // no ground truth: empty cells
  seqslam.erase("provenance");  // read from the compare's top level
  const json compare = {{"methods", {"gated", "seqslam"}},
                        {"gated", gated},
                        {"seqslam", seqslam},
                        {"comparison", json::object()},
                        {"provenance", {{"version", "0.1.0 (top)"}, {"command_line", "loopgate compare"}}}};
  write(root / "groups" / "b-compare" / "compare.json", compare.dump(1));
  write(root / "groups" / "b-compare" / "gated" / "summary.json", gated.dump(1));  // not read twice

  json odometry = run_summary("dird", "odometry", 0.0, 0.5);
  odometry.erase("evaluation");
  odometry.erase("stages");
  write(root / "c-odometry" / "summary.json", odometry.dump(1));
  write(root / "rendered" / "mav0" / "cam0" / "data.csv", "#t,file\n");  // a dataset: no run, not named
  write(root / "stopped" / "frames.csv", "seq,frame\n");                 // a run without its summary

  const fs::path out = root / "table";
  const Result r = loopgate("aggregate " + root.string() + " --out " + out.string() + " --no-plots");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find((root / "stopped").string() + ": a run's files but no summary.json"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("rendered"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("| run | dataset | config | method | mode |"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("4 rows from 3 summaries (1 compare, 2 run)"), std::string::npos) << r.output;
  const std::string markdown = testing::read_file(out / "aggregate.md");
  EXPECT_NE(r.output.find(markdown), std::string::npos) << r.output;  // printed as written

  const auto table = read_table(out / "aggregate.csv");
  ASSERT_EQ(table.size(), 4u);
  const auto& a = table.at("a-run|dird-seqslam-gated");
  EXPECT_EQ(a.at("dataset"), "/data/demo");
  EXPECT_EQ(a.at("config"), "my configs/demo.yaml");
  EXPECT_EQ(a.at("config_hash"), "00112233aabbccdd");
  EXPECT_EQ(a.at("mode"), "gated");
  EXPECT_EQ(a.at("status"), "ok");
  EXPECT_EQ(a.at("frames"), "300");
  EXPECT_EQ(a.at("loops"), "12");
  EXPECT_EQ(a.at("loops_true"), "10");
  EXPECT_EQ(a.at("loops_false"), "2");
  EXPECT_EQ(a.at("average_precision"), "0.9");
  EXPECT_EQ(a.at("recall_at_100"), "0.5");
  EXPECT_EQ(a.at("recall_at_99"), "0.6");
  EXPECT_EQ(a.at("recall_at_95"), "0.7");
  EXPECT_EQ(a.at("wall_s"), "2.5");
  EXPECT_EQ(a.at("describe_match_ms"), "125.25");  // describe + match + end of stream, as compare sums it
  EXPECT_EQ(a.at("realtime_factor"), "12.5");
  EXPECT_EQ(a.at("ate_m"), "0.72");
  EXPECT_EQ(a.at("ate_corrected_m"), "0.4");
  EXPECT_EQ(a.at("version"), "0.1.0 (abc123)");

  const auto& g = table.at("groups/b-compare|gated");
  EXPECT_EQ(g.at("average_precision"), "0.8");
  EXPECT_EQ(g.at("ate_corrected_m"), "0.3");  // compare keeps it in the method's loop_correction
  const auto& s = table.at("groups/b-compare|seqslam");
  EXPECT_EQ(s.at("average_precision"), "");
  EXPECT_EQ(s.at("loops_true"), "");
  EXPECT_EQ(s.at("ate_corrected_m"), "");
  EXPECT_EQ(s.at("version"), "0.1.0 (top)");
  EXPECT_EQ(s.at("config"), "");
  const auto& o = table.at("c-odometry|odometry");
  EXPECT_EQ(o.at("describe_match_ms"), "");
  EXPECT_EQ(o.at("wall_s"), "0.5");
}

// Real outputs: the keys the table reads are the ones run and compare write.
TEST(E2eAggregate, ReadsWhatRunAndCompareWrite) {
  const fs::path data = testing::make_temp_dir("e2e-aggregate-data");
  Result r = loopgate("simulate --preset aliasing --frames 150 --out " + data.string());
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path root = testing::make_temp_dir("e2e-aggregate-real");
  const std::string config = (fs::path(LOOPGATE_SOURCE_DIR) / "configs" / "aliasing.yaml").string();
  const std::string common =
      " --config " + config + " --dataset " + data.string() +
      " --set output.progress=off --set match.margin=50 --set seqslam.exclusion_margin_frames=50";
  r = loopgate("run" + common + " --mode gated --method seqslam --out " + (root / "run-gated").string());
  ASSERT_EQ(r.status, 0) << r.output;
  r = loopgate("compare" + common + " --methods full,dird-seqslam-gated --no-plots --out " +
               (root / "cmp").string());
  ASSERT_EQ(r.status, 0) << r.output;

  const bool plots = testing::run_command("/usr/bin/python3 -c 'import matplotlib'") == 0;
  r = loopgate("aggregate " + root.string() + (plots ? "" : " --no-plots"));
  ASSERT_EQ(r.status, 0) << r.output;
  const fs::path out = root / "aggregate";
  if (plots) {
    EXPECT_TRUE(fs::is_regular_file(out / "aggregate.png")) << r.output;
  }
  const auto table = read_table(out / "aggregate.csv");
  ASSERT_EQ(table.size(), 3u) << testing::read_file(out / "aggregate.csv");
  const json run = json::parse(testing::read_file(root / "run-gated" / "summary.json"));
  const json compare = json::parse(testing::read_file(root / "cmp" / "compare.json"));
  const std::vector<std::pair<std::string, json>> expected = {
      {"run-gated|seqslam-gated", run},
      {"cmp|full", compare["full"]},
      {"cmp|dird-seqslam-gated", compare["dird-seqslam-gated"]}};
  for (const auto& [key, summary] : expected) {
    ASSERT_TRUE(table.count(key)) << key << "\n" << testing::read_file(out / "aggregate.csv");
    const auto& row = table.at(key);
    EXPECT_EQ(row.at("mode"), summary["mode"].get<std::string>()) << key;
    EXPECT_EQ(row.at("dataset"), data.string()) << key;
    EXPECT_EQ(row.at("config"), config) << key;
    EXPECT_EQ(row.at("version"), summary["provenance"]["version"].get<std::string>()) << key;
    EXPECT_EQ(std::stod(row.at("wall_s")), summary["wall_s"].get<double>()) << key;
    EXPECT_EQ(std::stoll(row.at("loops")), summary["loops"].get<long long>()) << key;
    EXPECT_FALSE(row.at("describe_match_ms").empty()) << key;
    EXPECT_FALSE(row.at("realtime_factor").empty()) << key;
    EXPECT_FALSE(row.at("ate_m").empty()) << key;  // drift odometry against the ground truth
    const json& pr = summary["evaluation"]["precision_recall"];
    if (pr.contains("average_precision")) {
      EXPECT_EQ(std::stod(row.at("average_precision")), pr["average_precision"].get<double>()) << key;
    } else {
      EXPECT_EQ(row.at("average_precision"), "") << key;
    }
  }
}

// Two folders of one name (a/out, b/out) gave rows of one label; the same folder given twice, two rows of
// one label too. Folders of one name are labelled by their paths; a folder given twice is refused.
TEST(E2eAggregate, RowLabelsAreUnique) {
  const fs::path root = testing::make_temp_dir("e2e-aggregate-labels");
  write(root / "a" / "out" / "r" / "summary.json", run_summary("dird", "full", 0.9, 1.0).dump(1));
  write(root / "b" / "out" / "r" / "summary.json", run_summary("dird", "full", 0.5, 1.0).dump(1));
  Result r = loopgate("aggregate " + (root / "a" / "out").string() + " " + (root / "b" / "out").string() +
                      " --out " + (root / "table").string() + " --no-plots");
  ASSERT_EQ(r.status, 0) << r.output;
  const auto table = read_table(root / "table" / "aggregate.csv");
  ASSERT_EQ(table.size(), 2u) << r.output;
  EXPECT_EQ(table.count((root / "a" / "out").generic_string() + "/r|full"), 1u) << r.output;
  EXPECT_EQ(table.count((root / "b" / "out").generic_string() + "/r|full"), 1u) << r.output;

  r = loopgate("aggregate " + (root / "a" / "out").string() + " " + (root / "a" / "out").string() +
               "/ --out " + (root / "table2").string() + " --no-plots");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("is also that of " + (root / "a" / "out" / "r" / "summary.json").string() +
                          " (the same file: a folder given twice, or inside another argument): give each "
                          "folder once"),
            std::string::npos)
      << r.output;
}

TEST(E2eAggregate, BadInputNamesTheFileAndWhatWasExpected) {
  const fs::path root = testing::make_temp_dir("e2e-aggregate-bad");
  const fs::path broken = root / "broken" / "summary.json";
  write(broken, "{\n  \"mode\": \"gated\",\n  oops\n}\n");
  Result r = loopgate("aggregate " + (root / "broken").string() + " --no-plots");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(broken.string() + ":3: not valid JSON"), std::string::npos) << r.output;

  const fs::path missing = root / "missing" / "summary.json";
  json summary = run_summary("dird", "gated", 0.5, 1.0);
  summary.erase("wall_s");
  write(missing, summary.dump(1));
  r = loopgate("aggregate " + (root / "missing").string() + " --no-plots");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(missing.string() + ": key 'wall_s': expected a number, absent"), std::string::npos)
      << r.output;

  const fs::path typed = root / "typed" / "compare.json";
  json bad = run_summary("dird", "gated", 0.5, 1.0);
  bad["evaluation"]["precision_recall"]["average_precision"] = "high";
  write(typed, json{{"methods", {"gated", "full"}}, {"gated", bad}}.dump(1));
  r = loopgate("aggregate " + (root / "typed").string() + " --no-plots");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(typed.string() + ": key 'gated.evaluation.precision_recall.average_precision': "
                                           "expected a number (or absent), got string"),
            std::string::npos)
      << r.output;
  write(typed,
        json{{"methods", {"gated", "full"}}, {"gated", run_summary("dird", "gated", 0.5, 1.0)}}.dump(1));
  r = loopgate("aggregate " + (root / "typed").string() + " --no-plots");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(typed.string() + ": key 'full': expected an object holding the summary of method "
                                           "'full' (listed in 'methods'), absent"),
            std::string::npos)
      << r.output;

  const fs::path empty = testing::make_temp_dir("e2e-aggregate-empty");
  fs::create_directories(empty / "sub");
  r = loopgate("aggregate " + empty.string() + " --no-plots");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(empty.string() + ": no summary.json or compare.json in this folder or below it"),
            std::string::npos)
      << r.output;
  r = loopgate("aggregate " + (root / "absent").string() + " --no-plots");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find((root / "absent").string() + ": no such folder"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace loopgate
