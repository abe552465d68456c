// gate.feedback end to end: on a short rendered street drive with loops forced by a small match
// margin and a small lag, the gate is re-anchored through verified loops; 1 and 2 threads give the same
// files (the gate waits for exactly the loops of query frames <= i - L, never "what is ready"); every anchor
// is the latest loop verified among those frames; without verify.enabled it is a config error; off, nothing
// of it appears.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::column_index;
using testing::read_csv;
using testing::read_file;

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " --log-level warn " + args, &output);
  return output;
}

fs::path simulate_drive() {
  const fs::path sim = testing::make_temp_dir("e2e-feedback-sim");
  int status = -1;
  const std::string output = run("simulate --preset demo --frames 80 --force --out " + sim.string(), &status);
  EXPECT_EQ(status, 0) << output;
  return sim;
}

// configs/demo.yaml gated with verification, loops forced between frames ~5 m apart (gap 4, margin 4,
// min_score 0), and a short lag: L = max_in_flight 2 + row horizon 5 + sequence length 5 - 1 = 11 frames.
// Loops that short tell the graph nothing the odometry does not know (verify.min_information_gain would skip
// them): every one is verified here.
std::string forced_args(const fs::path& sim, const fs::path& out, int threads) {
  return "run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " + sim.string() +
         " --out " + out.string() + " --mode gated --threads " + std::to_string(threads) +
         " --set match.margin=4 --set dird_seqslam.min_score=0 --set output.progress=off --set "
         "verify.enabled=true --set verify.min_information_gain=0 --set gate.gap_frames=4 "
         "--set run.max_in_flight=2 --set match.sequence_length=5 --set gate.area_margin_query_frames=5 "
         "--set gate.area_max_hole_frames=2 --set gate.row_horizon_frames=5 ";
}

fs::path run_forced(const fs::path& sim, const std::string& name, int threads, const std::string& extra) {
  const fs::path out = testing::make_temp_dir(name);
  int status = -1;
  const std::string output = run(forced_args(sim, out, threads) + extra, &status);
  EXPECT_EQ(status, 0) << output;
  return out;
}

std::vector<std::vector<std::string>> edges_without_timing(const fs::path& out) {
  auto rows = read_csv(out / "loop_edges.csv");
  for (auto& row : rows) row.pop_back();
  return rows;
}

TEST(E2eGateFeedback, ReanchorsByTheRuleAndOneAndTwoThreadsAgree) {
  const fs::path sim = simulate_drive();
  const fs::path one = run_forced(sim, "e2e-feedback-1", 1, "--set gate.feedback=true");
  const fs::path two = run_forced(sim, "e2e-feedback-2", 2, "--set gate.feedback=true");

  for (const char* file :
       {"frames.csv", "loops.csv", "candidate_cells.csv", "candidate_areas.csv", "trajectory_corrected.tum"})
    EXPECT_EQ(read_file(one / file), read_file(two / file)) << file;
  EXPECT_EQ(edges_without_timing(one), edges_without_timing(two));

  const auto summary = nlohmann::json::parse(read_file(one / "summary.json"));
  const auto& feedback = summary["gate"]["feedback"];
  ASSERT_TRUE(feedback["enabled"].get<bool>()) << summary["gate"].dump();
  const auto lag = feedback["lag_frames"].get<std::size_t>();
  EXPECT_EQ(lag, 11u);
  EXPECT_GT(summary["loops_verified"].get<int>(), 0);
  EXPECT_GT(feedback["frames_reanchored"].get<int>(), 0) << feedback.dump();

  // The verified loops (i, j), in submission order.
  std::vector<std::pair<std::size_t, std::size_t>> verified;
  for (const auto& row : read_csv(one / "loop_edges.csv"))
    if (row[3] == "y") verified.emplace_back(std::stoul(row[0]), std::stoul(row[1]));
  // Every frame's anchor is the latest loop verified among the query frames <= frame - L (largest query,
  // then the last verified; every frame of this drive has a pose), and none before the first such loop.
  std::vector<std::string> header;
  const auto frames = read_csv(one / "frames.csv", &header);
  const std::size_t c_frame = column_index(header, "frame"), c_i = column_index(header, "gate_anchor_i"),
                    c_j = column_index(header, "gate_anchor_j"),
                    c_sigma = column_index(header, "gate_sigma_m");
  std::size_t anchored = 0;
  for (const auto& row : frames) {
    const std::size_t frame = std::stoul(row[c_frame]);
    std::optional<std::pair<std::size_t, std::size_t>> expected;
    for (const auto& loop : verified) {
      if (frame < lag || loop.first > frame - lag) continue;
      if (!expected || loop.first >= expected->first) expected = loop;
    }
    if (!expected) {
      EXPECT_EQ(row[c_i], "") << "frame " << frame;
      continue;
    }
    ++anchored;
    EXPECT_EQ(row[c_i], std::to_string(expected->first)) << "frame " << frame;
    EXPECT_EQ(row[c_j], std::to_string(expected->second)) << "frame " << frame;
    EXPECT_FALSE(row[c_sigma].empty());
  }
  EXPECT_EQ(anchored, feedback["frames_reanchored"].get<std::size_t>());

  // The same drive without feedback: no feedback columns, and the gate's sigma is the odometry's.
  const fs::path off = run_forced(sim, "e2e-feedback-off", 2, "");
  std::vector<std::string> off_header;
  read_csv(off / "frames.csv", &off_header);
  EXPECT_EQ(off_header.size() + 3, header.size());
  const auto off_summary = nlohmann::json::parse(read_file(off / "summary.json"));
  EXPECT_FALSE(off_summary["gate"]["feedback"]["enabled"].get<bool>());
  EXPECT_FALSE(off_summary["config"]["gate"]["feedback"].get<bool>()) << off_summary["config"].dump();
  // Re-anchoring moved the gate's input: some gate distance differs from the run without it.
  const auto off_frames = read_csv(off / "frames.csv");
  ASSERT_EQ(off_frames.size(), frames.size());
  const std::size_t c_d = column_index(header, "gate_d_m");
  bool differs = false;
  for (std::size_t k = 0; k < frames.size(); ++k) differs = differs || frames[k][c_d] != off_frames[k][c_d];
  EXPECT_TRUE(differs);
}

// The lag rule holds for the other streaming gated methods (raw and standardised DIRD): a lag shorter than
// their verdict delay would stop the run with a logic error (GateFeedback::anchor_through).
TEST(E2eGateFeedback, DirdMethodsRunWithFeedback) {
  const fs::path sim = simulate_drive();
  for (const std::string method : {"--method dird", "--method dird --set standardize.mode=causal"}) {
    const fs::path out = testing::make_temp_dir("e2e-feedback-dird");
    int status = -1;
    const std::string output =
        run(forced_args(sim, out, 1) + "--set gate.feedback=true --set match.nms_half_window=3 " + method,
            &status);
    ASSERT_EQ(status, 0) << method << "\n" << output;
    const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
    EXPECT_TRUE(summary["gate"]["feedback"]["enabled"].get<bool>());
    // L = max_in_flight 2 + row horizon 5 + the NMS delay 2 x 3: the gate asks from frame 13 on.
    EXPECT_EQ(summary["gate"]["feedback"]["lag_frames"].get<int>(), 13) << method;
  }
}

TEST(E2eGateFeedback, NeedsVerification) {
  const fs::path sim = simulate_drive();
  const fs::path out = testing::make_temp_dir("e2e-feedback-noverify");
  int status = -1;
  const std::string output =
      run(forced_args(sim, out, 1) + "--set gate.feedback=true --set verify.enabled=false", &status);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(
      output.find("gate.feedback: the gate is re-anchored on verified loop closures, and verify.enabled "
                  "is false"),
      std::string::npos)
      << output;
}

}  // namespace
}  // namespace loopgate
