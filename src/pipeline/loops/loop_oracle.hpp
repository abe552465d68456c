// The floor of loop correction on a route: a run's odometry in the pose graph the loop closer builds, with
// PERFECT loop edges - the ground-truth relative pose, a tight covariance - at the ground-truth revisits (one
// edge every `every` query frames). No verifier can give better edges or more of them, so the trajectory it
// gives is the best any loop closure reaches on this odometry and route with this graph: a run's corrected
// ATE is read against it (the share of the attainable gain, LoopCloser::oracle_report()). A target below the
// floor needs better odometry (or a Sim(3) graph), not better loops.
//
// The perfect loop edges are plain least squares (no robust loss, none switched off: they are right; a graph
// whose odometry edges are overconfident would otherwise reject the truth and give a floor that is not one);
// `robust` gives them the graph's Cauchy loss and outlier switch-off, as a run's verified loops get.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <utility>
#include <vector>

#include "core/pose_covariance.hpp"
#include "stages/posegraph/pose_graph.hpp"

namespace loopgate {

class Dataset;

// The odometry part of a pose graph: nodes (dataset frames, increasing) at their odometry poses and the
// odometry edges between consecutive nodes.
struct OracleGraph {
  std::vector<std::size_t> frames;
  std::vector<Eigen::Isometry3d> T_w_b;
  struct Edge {
    std::size_t a = 0, b = 0;  // node indices, b = a + 1
    Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
    PoseCov cov = PoseCov::Identity();
  };
  std::vector<Edge> odometry;
};

struct OracleOptions {
  int every = 5;                  // one perfect edge per this many query frames
  double sigma_position_m = 0.1;  // the perfect edges' covariance
  double sigma_rotation_rad = 0.005;
  bool robust = false;    // the graph's robust loss and outlier switch-off on them too
  PoseGraphConfig graph;  // the graph's settings (loss, iterations, solver)
};

struct OracleResult {
  std::vector<Eigen::Isometry3d> T_w_b;  // the nodes corrected by the perfect edges
  std::size_t loops = 0;                 // perfect edges added
  std::size_t outliers = 0;              // of them switched off (robust only)
  int iterations = 0;
};

// `truth_pairs`: ground-truth revisits (query frame i, reference frame j) as dataset frame indices, in
// increasing i; a pair whose frames are not both nodes is left out. Throws DataError when the dataset has no
// ground truth at a frame an edge needs; std::runtime_error when the solve fails.
OracleResult solve_loop_oracle(const OracleGraph& graph,
                               const std::vector<std::pair<std::size_t, std::size_t>>& truth_pairs,
                               const Dataset& dataset, const OracleOptions& options);

}  // namespace loopgate
