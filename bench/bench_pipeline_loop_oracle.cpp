// The floor of loop correction on a route (pipeline/loops/loop_oracle.hpp, which every run with ground truth
// and a pose graph reports in summary.json's loop_oracle): a finished run's odometry in the pose graph the
// loop closer builds, with PERFECT loop edges - the ground-truth relative pose, tight covariance - at every
// ground-truth revisit (truth_loops.csv, one edge per query frame every --every frames). The ATE printed is
// over the graph's nodes. Prints figures; not a timed benchmark.
//
// The odometry edges are the run's own: the nodes and odometry edges of RUN_DIR/pose_graph.g2o (written by a
// run with verify.enabled: the odometry's covariances scaled as that run scaled them; its loop edges are
// dropped; an odometry edge is one between consecutive nodes). With --model, or without that file, the nodes
// are the poses of trajectory.tum and the edges take the fixed model (posegraph.odometry_cov model).
//
//   build/release/bench_pipeline_loop_oracle RUN_DIR DATASET [--every N] [--sigma-position-m S]
//       [--sigma-rotation-rad R] [--model] [--robust]
//
// The perfect loop edges are plain least squares (no robust loss, none switched off: they are right); with
// --robust they get the run's Cauchy loss and outlier switch-off, as a run's verified loops do.
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "io/g2o_file.hpp"
#include "io/trajectory_io.hpp"
#include "pipeline/loops/loop_oracle.hpp"
#include "pipeline/outputs/run_metrics.hpp"

namespace {

using namespace loopgate;
namespace fs = std::filesystem;

struct Options {
  fs::path run_dir, dataset;
  int every = 5;
  double sigma_position_m = 0.1;
  double sigma_rotation_rad = 0.005;
  bool model = false;
  bool robust = false;  // the run's robust loss and outlier switch-off on the perfect loops too
};

// truth_loops.csv as the run writes it: header "i,j", then one pair per line.
std::vector<std::pair<std::size_t, std::size_t>> read_truth_loops(const fs::path& file) {
  std::ifstream in(file);
  if (!in) throw DataError(file, "cannot be read (a run with ground truth writes it)");
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  std::string line;
  for (std::size_t line_no = 1; std::getline(in, line); ++line_no) {
    if (line_no == 1 && line == "i,j") continue;
    std::size_t i = 0, j = 0;
    if (std::sscanf(line.c_str(), "%zu,%zu", &i, &j) != 2)
      throw DataError(file, fmt::format("line {}: expected 'i,j', got '{}'", line_no, line));
    pairs.emplace_back(i, j);
  }
  return pairs;
}

double rmse(const nlohmann::json& accuracy) {
  return accuracy.value("available", false) ? accuracy.at("rmse_m").get<double>() : -1.0;
}

int run(const Options& o) {
  const auto dataset = open_dataset(o.dataset);
  if (!dataset->has_ground_truth()) throw DataError(o.dataset, "the oracle needs ground truth");
  OracleOptions options;
  options.every = o.every;
  options.sigma_position_m = o.sigma_position_m;
  options.sigma_rotation_rad = o.sigma_rotation_rad;
  options.robust = o.robust;
  OracleGraph graph;
  const fs::path graph_file = o.run_dir / "pose_graph.g2o";
  std::string edges_from;
  if (!o.model && fs::exists(graph_file)) {
    G2oGraph run_graph = read_g2o(graph_file);
    std::sort(run_graph.vertices.begin(), run_graph.vertices.end(),
              [](const G2oVertex& a, const G2oVertex& b) { return a.id < b.id; });
    std::map<std::int64_t, std::size_t> node_of;
    for (const G2oVertex& v : run_graph.vertices) {
      if (v.id < 0 || static_cast<std::size_t>(v.id) >= dataset->frame_count())
        throw DataError(graph_file, fmt::format("vertex {} is not a frame of the dataset", v.id));
      node_of[v.id] = graph.frames.size();
      graph.frames.push_back(static_cast<std::size_t>(v.id));
      graph.T_w_b.push_back(v.T_w_b);
    }
    std::size_t dropped = 0;
    for (const G2oEdge& e : run_graph.edges) {
      const auto a = node_of.find(e.a), b = node_of.find(e.b);
      if (a == node_of.end() || b == node_of.end())
        throw DataError(graph_file, fmt::format("edge {} -> {} joins an unknown vertex", e.a, e.b));
      if (b->second != a->second + 1) {
        ++dropped;
        continue;
      }
      graph.odometry.push_back({a->second, b->second, e.T_a_b, e.information.inverse()});
    }
    edges_from =
        fmt::format("the run's odometry edges ({}; its {} loop edges dropped)", graph_file.string(), dropped);
  } else {
    const std::vector<StampedPose> odometry = read_tum(o.run_dir / "trajectory.tum");
    std::map<Timestamp, std::size_t> frame_of;
    for (std::size_t f = 0; f < dataset->frame_count(); ++f) frame_of[dataset->frame_t_ns(f)] = f;
    for (const StampedPose& pose : odometry) {
      const auto it = frame_of.lower_bound(pose.t_ns - 1000);  // TUM keeps 1 ns; allow its rounding
      if (it == frame_of.end() || it->first > pose.t_ns + 1000) continue;
      if (!graph.frames.empty() && it->second <= graph.frames.back()) continue;
      graph.frames.push_back(it->second);
      graph.T_w_b.push_back(pose.T_w_b);
    }
    for (std::size_t n = 1; n < graph.frames.size(); ++n) {
      const Eigen::Isometry3d T_a_b = graph.T_w_b[n - 1].inverse() * graph.T_w_b[n];
      graph.odometry.push_back({n - 1, n, T_a_b, options.graph.model_cov(T_a_b)});
    }
    edges_from = "the fixed model's odometry edges (trajectory.tum)";
  }
  if (graph.frames.size() < 2) throw DataError(o.run_dir, "fewer than 2 poses at frame times");
  const std::vector<std::pair<std::size_t, std::size_t>> pairs =
      read_truth_loops(o.run_dir / "truth_loops.csv");
  const OracleResult oracle = solve_loop_oracle(graph, pairs, *dataset, options);
  std::vector<StampedPose> before, corrected;
  for (std::size_t n = 0; n < graph.frames.size(); ++n) {
    before.push_back({dataset->frame_t_ns(graph.frames[n]), graph.T_w_b[n]});
    corrected.push_back({dataset->frame_t_ns(graph.frames[n]), oracle.T_w_b[n]});
  }
  std::printf("odometry edges: %s\n", edges_from.c_str());
  std::printf(
      "%s: %zu nodes, %zu perfect loop edges (one per %d query frames of %zu ground-truth pairs; %zu "
      "switched "
      "off), %d iterations\nATE odometry %.3f m -> oracle-corrected %.3f m (posyaw alignment, as "
      "summary.json)\n",
      o.run_dir.c_str(), graph.frames.size(), oracle.loops, o.every, pairs.size(), oracle.outliers,
      oracle.iterations, rmse(trajectory_accuracy_json(before, *dataset)),
      rmse(trajectory_accuracy_json(corrected, *dataset)));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  std::vector<std::string> args(argv + 1, argv + argc);
  std::vector<std::string> positional;
  try {
    for (std::size_t k = 0; k < args.size(); ++k) {
      const auto value = [&]() -> const std::string& {
        if (k + 1 >= args.size()) throw ConfigError(args[k] + ": needs a value");
        return args[++k];
      };
      if (args[k] == "--every") {
        o.every = std::stoi(value());
      } else if (args[k] == "--sigma-position-m") {
        o.sigma_position_m = std::stod(value());
      } else if (args[k] == "--model") {
        o.model = true;
      } else if (args[k] == "--robust") {
        o.robust = true;
      } else if (args[k] == "--sigma-rotation-rad") {
        o.sigma_rotation_rad = std::stod(value());
      } else {
        positional.push_back(args[k]);
      }
    }
    if (positional.size() != 2 || o.every < 1 || o.sigma_position_m <= 0 || o.sigma_rotation_rad <= 0) {
      std::fprintf(stderr,
                   "usage: %s RUN_DIR DATASET [--every N>=1] [--sigma-position-m S>0] [--sigma-rotation-rad "
                   "R>0] [--model] [--robust]\n",
                   argv[0]);
      return 2;
    }
    o.run_dir = positional[0];
    o.dataset = positional[1];
    return run(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_pipeline_loop_oracle: error: %s\n", e.what());
    return 1;
  }
}
