// The revisit in another lane (route.revisit_lateral_offset_m, sim/revisit.hpp): the second lap of the
// night loop driven 3.5 m to the side keeps every ground-truth loop pair of the same-lane drive, its camera
// is moved by the offset on the revisit and not elsewhere, and bad values are clear errors.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "sim/revisit.hpp"
#include "sim/simulator.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

std::vector<std::pair<std::int64_t, std::int64_t>> pairs_of(const std::vector<LoopInterval>& loops) {
  std::vector<std::pair<std::int64_t, std::int64_t>> pairs;
  for (const LoopInterval& loop : loops)
    for (std::int64_t j = loop.first; j <= loop.last; ++j) pairs.emplace_back(loop.query, j);
  return pairs;
}

TEST(SimRevisit, OtherLaneRevisitKeepsTheLoopPairsAndMovesTheCamera) {
  SimulationConfig same_lane = make_preset("night-loop", "");
  SimulationConfig other_lane = make_preset("night-loop", "");
  other_lane.route.revisit_lateral_offset_m = 3.5;
  const SimulationPlan a = plan_simulation(same_lane);
  const SimulationPlan b = plan_simulation(other_lane);
  ASSERT_EQ(a.frames_used, b.frames_used);
  const std::vector<LoopInterval> loops_a = plan_loop_truth(a, same_lane.loops);
  const std::vector<LoopInterval> loops_b = plan_loop_truth(b, other_lane.loops);
  ASSERT_FALSE(loops_a.empty());
  // The same pairs up to the trajectory fit's smoothing of the lane change (a few centimetres on the street).
  const auto pa = pairs_of(loops_a), pb = pairs_of(loops_b);
  std::vector<std::pair<std::int64_t, std::int64_t>> common;
  std::set_intersection(pa.begin(), pa.end(), pb.begin(), pb.end(), std::back_inserter(common));
  EXPECT_GE(common.size(), 0.97 * static_cast<double>(pa.size()));
  EXPECT_GE(common.size(), 0.97 * static_cast<double>(pb.size()));

  // The camera: 3.5 m to the side on every query frame of a loop, unmoved on the first half of the first lap.
  std::vector<double> query_offsets;
  for (const LoopInterval& loop : loops_b) {
    const auto q = static_cast<std::size_t>(loop.query);
    query_offsets.push_back((b.T_w_c[q].translation() - a.T_w_c[q].translation()).norm());
  }
  const auto [lo, hi] = std::minmax_element(query_offsets.begin(), query_offsets.end());
  EXPECT_GT(*lo, 3.0);
  EXPECT_LT(*hi, 3.6);
  for (std::size_t f = 0; f < 100; ++f)
    EXPECT_LT((b.T_w_c[f].translation() - a.T_w_c[f].translation()).norm(), 1e-6) << f;
  // The street stays: the driven positions moved back by the shift are the same-lane ones (up to the fit's
  // smoothing of the lane change).
  for (std::size_t f = 0; f < b.frames_used; f += 7)
    EXPECT_LT((b.street_T_w_c(f).translation() - a.T_w_c[f].translation()).norm(), 0.15) << f;
  // Which is why the truth is taken on the street: by camera positions within 2 m the revisit is lost.
  std::vector<Eigen::Isometry3d> driven(b.T_w_c.begin(),
                                        b.T_w_c.begin() + static_cast<std::ptrdiff_t>(b.frames_used));
  EXPECT_LT(pairs_of(find_loop_truth(driven, b.up_w, other_lane.loops)).size(),
            pairs_of(loops_b).size() / 10);
}

TEST(SimRevisit, TruthPairsFileReadsBackAsTheLoops) {
  SimulationConfig config = make_preset("night-loop", "");
  config.route.revisit_lateral_offset_m = -2.5;
  const SimulationPlan plan = plan_simulation(config);
  const std::vector<LoopInterval> loops = plan_loop_truth(plan, config.loops);
  const auto file = testing::make_temp_dir("sim-revisit") / kLoopTruthFile;
  write_loop_truth_pairs(file, loops);
  // "query,reference" then one pair per line, in the intervals' order.
  std::ifstream in(file);
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line, "query,reference");
  std::vector<std::pair<std::int64_t, std::int64_t>> read;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    std::int64_t q = -1, r = -1;
    char comma = 0;
    ASSERT_TRUE(row >> q >> comma >> r) << line;
    read.emplace_back(q, r);
  }
  EXPECT_FALSE(read.empty());
  EXPECT_EQ(read, pairs_of(loops));
}

TEST(SimRevisit, LaneChangeIsSmoothAndOnlyAroundRevisits) {
  std::vector<StampedPose> poses(200);
  for (std::size_t i = 0; i < poses.size(); ++i)
    poses[i].T_w_b.translation() = Eigen::Vector3d(i * 1.0, 0, 0);
  std::vector<bool> revisit(poses.size(), false);
  for (std::size_t i = 100; i < 150; ++i) revisit[i] = true;
  const std::vector<double> w = revisit_offset_weights(poses, revisit, 20.0);
  EXPECT_EQ(w[50], 0.0);
  EXPECT_EQ(w[79], 0.0);
  EXPECT_GT(w[90], 0.0);
  EXPECT_LT(w[90], 1.0);
  EXPECT_EQ(w[100], 1.0);
  EXPECT_EQ(w[149], 1.0);
  EXPECT_EQ(w[175], 0.0);
  for (std::size_t i = 81; i < 100; ++i) EXPECT_LE(w[i - 1], w[i]) << i;
}

TEST(SimRevisit, BadValuesAreClearErrors) {
  SimulationConfig config = make_preset("night-loop", "");
  config.route.revisit_radius_m = 0.0;
  try {
    config.validate();
    FAIL() << "revisit_radius_m 0 accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("route.revisit_radius_m"), std::string::npos) << e.what();
  }
  config = make_preset("night-loop", "");
  config.route.revisit_lateral_offset_m = 35.0;
  EXPECT_THROW(config.validate(), ConfigError);
  config = make_preset("kitti00", "/data");
  config.route.revisit_lateral_offset_m = 3.5;
  try {
    config.validate();
    FAIL() << "an offset on a recorded trajectory accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("procedural"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace loopgate::sim
