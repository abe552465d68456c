#include "pipeline/loops/loop_oracle.hpp"

#include <spdlog/fmt/fmt.h>

#include <limits>
#include <map>

#include "core/error.hpp"
#include "io/dataset.hpp"

namespace loopgate {

OracleResult solve_loop_oracle(const OracleGraph& graph,
                               const std::vector<std::pair<std::size_t, std::size_t>>& truth_pairs,
                               const Dataset& dataset, const OracleOptions& options) {
  PoseGraphConfig config = options.graph;
  if (!options.robust) {
    config.loss = PoseGraphLoss::kNone;
    config.outlier_chi2 = std::numeric_limits<double>::infinity();
  }
  PoseGraph solver(config);
  std::map<std::size_t, std::size_t> node_of;  // frame -> node
  for (std::size_t n = 0; n < graph.frames.size(); ++n)
    node_of[graph.frames[n]] = solver.add_node(graph.T_w_b[n]);
  for (const OracleGraph::Edge& e : graph.odometry)
    solver.add_edge(e.a, e.b, EdgeKind::kOdometry, e.T_a_b, e.cov);
  PoseCov cov = PoseCov::Zero();
  cov.diagonal() << Eigen::Vector3d::Constant(options.sigma_position_m * options.sigma_position_m),
      Eigen::Vector3d::Constant(options.sigma_rotation_rad * options.sigma_rotation_rad);
  const auto truth = [&](std::size_t frame) {
    const auto T_w_b = dataset.ground_truth_T_w_b(frame);
    if (!T_w_b)
      throw DataError(dataset.root(), fmt::format("the loop oracle: no ground truth at frame {}", frame));
    return *T_w_b;
  };
  OracleResult result;
  long long last_i = std::numeric_limits<long long>::min() / 2;
  for (const auto& [i, j] : truth_pairs) {
    if (static_cast<long long>(i) - last_i < options.every || !node_of.contains(i) || !node_of.contains(j))
      continue;
    last_i = static_cast<long long>(i);
    solver.add_edge(node_of[j], node_of[i], EdgeKind::kLoop, truth(j).inverse() * truth(i), cov);
    ++result.loops;
  }
  const SolveReport report = solver.optimize(true, 0.0);
  result.outliers = report.outliers;
  result.iterations = report.iterations;
  for (std::size_t n = 0; n < solver.node_count(); ++n) result.T_w_b.push_back(solver.pose(n));
  return result;
}

}  // namespace loopgate
