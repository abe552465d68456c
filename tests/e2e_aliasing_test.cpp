// Perceptual aliasing end to end: `loopgate simulate --preset aliasing` renders a street where
// place B is a copy of place A (same facade textures, 80+ m apart, each driven once) plus one genuine
// revisit. With configs/aliasing.yaml, `run --mode full` (DIRD on every frame) reports false loops between A
// and B; `run --mode gated` (the pose gate: the odometry keeps A and B far apart) reports none and still
// finds the genuine loop. Ground truth is read from the simulated dataset itself.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io/config.hpp"
#include "io/trajectory_io.hpp"
#include "pipeline/pipeline_config.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

const fs::path kConfig = fs::path(LOOPGATE_SOURCE_DIR) / "configs" / "aliasing.yaml";
// Camera positions this close to a place centre are "at" the place (the copy radius is 38 m; 30 m keeps the
// pass by A clear of the approach to the genuine revisit).
constexpr double kPlaceRadiusM = 30.0;
// Every detection between the two aliased places is at least this far from its query in truth.
constexpr double kAliasedPlacesApartM = 50.0;

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " --log-level warn " + args, &output);
  return output;
}

// The simulated dataset, rendered once for all tests of this file.
struct Scenario {
  fs::path dir;
  std::vector<Eigen::Vector3d> p_w;  // ground-truth body position per frame
  Eigen::Vector2d place_a = Eigen::Vector2d::Zero();
  Eigen::Vector2d place_b = Eigen::Vector2d::Zero();
  std::string error;  // non-empty when the simulation failed
};

const Scenario& scenario() {
  static const Scenario s = [] {
    Scenario out;
    out.dir = testing::make_temp_dir("e2e-aliasing-data");
    int status = -1;
    const std::string log = run("simulate --preset aliasing --out " + out.dir.string(), &status);
    if (status != 0) {
      out.error = log;
      return out;
    }
    const fs::path mav0 = out.dir / "mav0";
    std::map<Timestamp, Eigen::Vector3d> gt;
    for (const GroundTruthState& state :
         read_euroc_groundtruth(mav0 / "state_groundtruth_estimate0" / "data.csv"))
      gt[state.t_ns] = state.T_w_b.translation();
    for (const EurocImageEntry& image : read_euroc_camera_csv(mav0 / "cam0" / "data.csv")) {
      const auto it = gt.find(image.t_ns);
      if (it == gt.end()) {
        out.error = "no ground truth at frame time " + std::to_string(image.t_ns);
        return out;
      }
      out.p_w.push_back(it->second);
    }
    const auto meta = nlohmann::json::parse(testing::read_file(out.dir / "simulation.json"));
    const auto& world = meta["parameters"]["world"];
    out.place_a = {world["alias_copy_source_x_m"].get<double>(),
                   world["alias_copy_source_y_m"].get<double>()};
    out.place_b = {world["alias_copy_target_x_m"].get<double>(),
                   world["alias_copy_target_y_m"].get<double>()};
    return out;
  }();
  return s;
}

bool at_place(const Scenario& s, std::size_t frame, const Eigen::Vector2d& place) {
  return (s.p_w[frame].head<2>() - place).norm() <= kPlaceRadiusM;
}

struct Loop {
  std::size_t i = 0;  // query
  std::size_t j = 0;  // reference
  double truth_distance_m = 0;
};

std::vector<Loop> read_loops(const fs::path& out_dir, const Scenario& s) {
  std::vector<std::string> header;
  const auto rows = testing::read_csv(out_dir / "loops.csv", &header);
  std::size_t col_i = header.size(), col_j = header.size();
  for (std::size_t c = 0; c < header.size(); ++c) {
    if (header[c] == "i") col_i = c;
    if (header[c] == "j") col_j = c;
  }
  EXPECT_LT(col_i, header.size()) << "loops.csv has no column i";
  EXPECT_LT(col_j, header.size()) << "loops.csv has no column j";
  std::vector<Loop> loops;
  if (col_i == header.size() || col_j == header.size()) return loops;
  for (const auto& row : rows) {
    Loop loop;
    loop.i = std::stoul(row.at(col_i));
    loop.j = std::stoul(row.at(col_j));
    EXPECT_LT(loop.i, s.p_w.size());
    EXPECT_LT(loop.j, s.p_w.size());
    if (loop.i >= s.p_w.size() || loop.j >= s.p_w.size()) continue;
    loop.truth_distance_m = (s.p_w[loop.i] - s.p_w[loop.j]).norm();
    loops.push_back(loop);
  }
  return loops;
}

// r_accept of configs/aliasing.yaml (what the run's own evaluation uses).
double accept_radius_m() {
  return load_config<PipelineConfig>(kConfig).eval.effective_accept_radius_m();
}

struct Counts {
  std::size_t loops = 0;
  std::size_t genuine = 0;      // within r_accept of the truth
  std::size_t false_loops = 0;  // beyond r_accept
  std::size_t aliased = 0;      // false, between place A and place B (either way round)
};

Counts classify(const std::vector<Loop>& loops, const Scenario& s, double accept_m) {
  Counts c;
  c.loops = loops.size();
  for (const Loop& loop : loops) {
    if (loop.truth_distance_m <= accept_m) {
      ++c.genuine;
      continue;
    }
    ++c.false_loops;
    const bool a_b = (at_place(s, loop.i, s.place_a) && at_place(s, loop.j, s.place_b)) ||
                     (at_place(s, loop.i, s.place_b) && at_place(s, loop.j, s.place_a));
    if (a_b) {
      ++c.aliased;
      EXPECT_GT(loop.truth_distance_m, kAliasedPlacesApartM) << loop.i << " -> " << loop.j;
    }
  }
  return c;
}

TEST(E2eAliasing, FullDirdReportsAFalseLoopBetweenTheAliasedPlaces) {
  const Scenario& s = scenario();
  ASSERT_TRUE(s.error.empty()) << s.error;
  ASSERT_EQ(s.p_w.size(), 490u);
  const fs::path out = testing::make_temp_dir("e2e-aliasing-full");
  int status = -1;
  const std::string log = run("run --config " + kConfig.string() + " --dataset " + s.dir.string() +
                                  " --mode full --out " + out.string() + " --set output.progress=off",
                              &status);
  ASSERT_EQ(status, 0) << log;
  const double accept_m = accept_radius_m();
  const std::vector<Loop> loops = read_loops(out, s);
  const Counts c = classify(loops, s, accept_m);
  std::printf("full: %zu loops, %zu within %.1f m of the truth, %zu false (%zu between the aliased places)\n",
              c.loops, c.genuine, accept_m, c.false_loops, c.aliased);
  EXPECT_GE(c.aliased, 1u) << "full DIRD should confuse the copied place with its source";
  EXPECT_GE(c.genuine, 1u) << "full DIRD should find the genuine revisit";

  // The odometry (drift) keeps the two aliased places far apart: every aliased detection joins frames whose
  // estimated positions are as far apart as the truth says, far beyond any gate threshold.
  std::vector<std::string> header;
  const auto frames = testing::read_csv(out / "frames.csv", &header);
  ASSERT_EQ(frames.size(), s.p_w.size());
  std::size_t col_x = header.size(), col_y = header.size();
  for (std::size_t k = 0; k < header.size(); ++k) {
    if (header[k] == "x_m") col_x = k;
    if (header[k] == "y_m") col_y = k;
  }
  ASSERT_LT(col_x, header.size());
  ASSERT_LT(col_y, header.size());
  const auto odometry_xy = [&](std::size_t f) {
    return Eigen::Vector2d(std::stod(frames[f][col_x]), std::stod(frames[f][col_y]));
  };
  for (const Loop& loop : loops) {
    if (loop.truth_distance_m <= kAliasedPlacesApartM) continue;
    EXPECT_GT((odometry_xy(loop.i) - odometry_xy(loop.j)).norm(), kAliasedPlacesApartM)
        << loop.i << " -> " << loop.j;
  }
}

TEST(E2eAliasing, GatedModeReportsNoFalseLoopAndFindsTheGenuineOne) {
  const Scenario& s = scenario();
  ASSERT_TRUE(s.error.empty()) << s.error;
  const fs::path out = testing::make_temp_dir("e2e-aliasing-gated");
  int status = -1;
  const std::string log = run("run --config " + kConfig.string() + " --dataset " + s.dir.string() +
                                  " --mode gated --out " + out.string() + " --set output.progress=off",
                              &status);
  if (status != 0 && log.find("run.mode") != std::string::npos) {
    FAIL() << "`loopgate run --mode gated` was rejected: the gated mode is not wired yet.\n" << log;
  }
  ASSERT_EQ(status, 0) << log;
  const double accept_m = accept_radius_m();
  const Counts c = classify(read_loops(out, s), s, accept_m);
  std::printf(
      "gated: %zu loops, %zu within %.1f m of the truth, %zu false (%zu between the aliased places)\n",
      c.loops, c.genuine, accept_m, c.false_loops, c.aliased);
  EXPECT_EQ(c.false_loops, 0u) << "the pose gate should remove every false loop";
  EXPECT_EQ(c.aliased, 0u);
  EXPECT_GE(c.genuine, 1u) << "the genuine revisit must stay inside a candidate area";

  // No frame at place A or B passes the gate (when the run reports the gate decision per frame).
  std::vector<std::string> header;
  const auto frames = testing::read_csv(out / "frames.csv", &header);
  ASSERT_EQ(frames.size(), s.p_w.size());
  for (std::size_t k = 0; k < header.size(); ++k) {
    if (header[k] != "gated") continue;
    for (std::size_t f = 0; f < frames.size(); ++f) {
      if (at_place(s, f, s.place_a) || at_place(s, f, s.place_b)) {
        EXPECT_EQ(frames[f][k], "n") << "frame " << f << " at an aliased place was gated";
      }
    }
  }
}

}  // namespace
}  // namespace loopgate
