// What the loop closer writes after the stream (loop_closer.hpp): loop_edges.csv, pose_graph.g2o,
// trajectory_corrected.tum, loops.csv's verification columns, the oracle report and the summary fields.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "io/g2o_file.hpp"
#include "io/writers.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loop_oracle.hpp"
#include "pipeline/loops/loop_timing.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/outputs/run_metrics.hpp"

namespace loopgate {

using loop_internal::ms_since;
using loop_internal::stats_json;

LoopCloser::ReasonCounts LoopCloser::reason_counts() const {
  ReasonCounts counts;
  for (const LoopResult& r : results_) {
    if (r.result.verified) continue;
    ++(r.skipped ? counts.skipped : counts.rejected)[std::string(enum_name(r.result.key))];
  }
  return counts;
}

std::vector<StampedPose> LoopCloser::corrected(const std::vector<StampedPose>& tracked) const {
  return corrected_by(tracked, node_poses_);
}

std::vector<StampedPose> LoopCloser::corrected_by(const std::vector<StampedPose>& tracked,
                                                  const std::vector<Eigen::Isometry3d>& node_poses) const {
  if (nodes_.empty() || node_poses.size() != nodes_.size()) return tracked;
  std::vector<StampedPose> out;
  out.reserve(tracked.size());
  // tracked poses are in frame order; nodes_ too. A frame takes the correction of the last node at or before
  // it (the first node for frames before it): T_corr(f) = T_corr(node) T_odo(node)^-1 T_odo(f).
  std::size_t n = 0;
  for (const StampedPose& pose : tracked) {
    while (n + 1 < nodes_.size() && dataset_.frame_t_ns(nodes_[n + 1]) <= pose.t_ns) ++n;
    const Eigen::Isometry3d& T_odo_node = *poses_[nodes_[n] - first_];
    out.push_back({pose.t_ns, node_poses[n] * T_odo_node.inverse() * pose.T_w_b});
  }
  return out;
}

nlohmann::json LoopCloser::oracle_report(
    const std::vector<StampedPose>& tracked,
    const std::vector<std::pair<std::size_t, std::size_t>>& truth_pairs) const {
  if (!active_ || !graph_config_.enabled) return {{"available", false}, {"why", "no pose graph"}};
  if (!dataset_.has_ground_truth()) return {{"available", false}, {"why", "the dataset has no ground truth"}};
  if (nodes_.size() < 2) return {{"available", false}, {"why", "no final pose-graph solve"}};
  const auto start = std::chrono::steady_clock::now();
  OracleGraph graph;
  graph.frames = nodes_;
  for (const std::size_t frame : nodes_) graph.T_w_b.push_back(*poses_[frame - first_]);
  for (const PoseGraphEdge& e : final_edges_) {
    if (e.kind != EdgeKind::kOdometry) continue;
    graph.odometry.push_back(
        {e.a, e.b, e.T_a_b, (e.sqrt_information.transpose() * e.sqrt_information).inverse()});
  }
  OracleOptions options;
  options.graph = graph_config_;
  OracleResult oracle;
  try {
    oracle = solve_loop_oracle(graph, truth_pairs, dataset_, options);
  } catch (const std::exception& e) {
    return {{"available", false}, {"why", std::string("the oracle's solve failed: ") + e.what()}};
  }
  const auto rmse = [&](const std::vector<StampedPose>& poses) -> std::optional<double> {
    const nlohmann::json accuracy = trajectory_accuracy_json(poses, dataset_);
    if (!accuracy.value("available", false)) return std::nullopt;
    return accuracy.at("rmse_m").get<double>();
  };
  const std::optional<double> odometry = rmse(tracked);
  const std::optional<double> corrected_m = rmse(corrected(tracked));
  const std::optional<double> floor_m = rmse(corrected_by(tracked, oracle.T_w_b));
  if (!odometry || !corrected_m || !floor_m) return {{"available", false}, {"why", "no trajectory accuracy"}};
  nlohmann::json share = nullptr;
  std::string share_why;
  const double attainable_m = *odometry - *floor_m;
  if (oracle.loops == 0) {
    share_why = "no ground-truth revisit between two nodes of the graph";
  } else if (!(attainable_m >= kOracleMinGain * *odometry)) {
    share_why = fmt::format("the oracle gains {:.1f}% < {:.0f}% of the odometry's ATE",
                            *odometry > 0 ? 100.0 * attainable_m / *odometry : 0.0, 100.0 * kOracleMinGain);
  } else {
    share = (*odometry - *corrected_m) / attainable_m;
  }
  return {{"available", true},
          {"ate_odometry_m", *odometry},
          {"ate_corrected_m", *corrected_m},
          {"ate_oracle_m", *floor_m},
          {"share_of_attainable_gain", share},
          {"share_why", share_why},
          {"oracle_loop_edges", oracle.loops},
          {"truth_pairs", truth_pairs.size()},
          {"every_query_frames", options.every},
          {"sigma_position_m", options.sigma_position_m},
          {"sigma_rotation_rad", options.sigma_rotation_rad},
          {"iterations", oracle.iterations},
          {"ms", ms_since(start)}};
}

// loops.csv's verification cells of a loop (also the start of its loop_edges.csv row).
std::vector<std::string> LoopCloser::verification_cells(const LoopResult& r) {
  const Eigen::Vector3d t = r.result.T_j_i.translation();
  const Eigen::Quaterniond q(r.result.T_j_i.rotation());
  const bool v = r.result.verified;
  const auto num = [v](double x) { return v ? format_fixed(x, 6) : std::string(); };
  return std::vector<std::string>{v ? "y" : (r.skipped ? "skipped" : "n"),
                                  std::to_string(r.result.inliers),
                                  r.result.reason,
                                  num(t.x()),
                                  num(t.y()),
                                  num(t.z()),
                                  num(q.x()),
                                  num(q.y()),
                                  num(q.z()),
                                  num(q.w())};
}

void LoopCloser::write_corrected(const std::filesystem::path& out_dir,
                                 const std::vector<StampedPose>& tracked) const {
  if (!final_solve_error_.empty()) return;  // nothing was corrected: no file claims it was
  TumWriter file(out_dir / "trajectory_corrected.tum");
  for (const StampedPose& pose : corrected(tracked)) file.write(pose.t_ns, pose.T_w_b);
  file.close();
}

void LoopCloser::write_graph(const std::filesystem::path& out_dir) const {
  if (!active_ || nodes_.empty()) return;
  G2oGraph file;
  for (const std::size_t frame : nodes_)
    file.vertices.push_back({static_cast<std::int64_t>(frame), *poses_[frame - first_]});
  file.fixed.push_back(static_cast<std::int64_t>(nodes_.front()));
  for (const PoseGraphEdge& e : final_edges_) {
    if (e.outlier) continue;
    file.edges.push_back({static_cast<std::int64_t>(nodes_[e.a]), static_cast<std::int64_t>(nodes_[e.b]),
                          e.T_a_b, e.sqrt_information.transpose() * e.sqrt_information});
  }
  write_g2o(out_dir / "pose_graph.g2o", file);
}

void LoopCloser::write_edges(const std::filesystem::path& out_dir) const {
  if (!active_) return;
  CsvWriter edges(out_dir / "loop_edges.csv", {"i",
                                               "j",
                                               "neighbour",
                                               "verified",
                                               "inliers",
                                               "matches",
                                               "points",
                                               "reason",
                                               "x_m",
                                               "y_m",
                                               "z_m",
                                               "qx",
                                               "qy",
                                               "qz",
                                               "qw",
                                               "sigma_position_m",
                                               "sigma_rotation_rad",
                                               "graph_outlier",
                                               "chi2",
                                               "verify_ms"});
  for (const LoopResult& r : results_) {
    const std::vector<std::string> c = verification_cells(r);
    const bool v = r.result.verified;
    edges.write_row({std::to_string(r.loop.query),
                     std::to_string(r.loop.reference),
                     r.neighbour ? std::to_string(r.neighbour) : "",
                     c[0],
                     c[1],
                     std::to_string(r.result.matches),
                     std::to_string(r.result.points),
                     c[2],
                     c[3],
                     c[4],
                     c[5],
                     c[6],
                     c[7],
                     c[8],
                     c[9],
                     v ? format_fixed(std::sqrt(r.result.cov(0, 0)), 6) : "",
                     v ? format_fixed(std::sqrt(r.result.cov(3, 3)), 6) : "",
                     v ? (r.outlier ? "y" : "n") : "",
                     v ? format_fixed(r.chi2, 3) : "",
                     format_fixed(r.verify_ms, 3)});
  }
  edges.close();
}

void LoopCloser::annotate_loops(LoopsWriter& loops) const {
  if (!active_) return;
  // loops.csv: one row per loop written, in the same order as the loops were submitted.
  if (loops.count() == results_.size()) {
    loops.rewrite_with(
        {"verified", "inliers", "geometry_reason", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw"},
        [&](std::size_t k) { return verification_cells(results_[k]); });
  }
}

nlohmann::json LoopCloser::summary() const {
  std::size_t verified = 0, tracked = 0, outliers = 0, skipped = 0;
  std::vector<double> verify_ms;
  for (const LoopResult& r : results_) {
    verified += r.result.verified ? 1 : 0;
    tracked += r.result.tracked ? 1 : 0;  // set on verified loops only
    outliers += r.outlier ? 1 : 0;
    skipped += r.skipped ? 1 : 0;
    if (!r.skipped) verify_ms.push_back(r.verify_ms);
  }
  const ReasonCounts counts = reason_counts();
  return {{"enabled", active_},
          {"unusable_reason", unusable_ ? unusable_->text : std::string()},
          {"loops", results_.size()},
          {"verified", verified},
          {"verified_by_tracking", tracked},
          {"rejected_geometry", results_.size() - verified - skipped},
          {"skipped", skipped},
          {"rejected_by_reason", counts.rejected},
          {"skipped_by_reason", counts.skipped},
          {"graph_outliers", outliers},
          {"graph_nodes", nodes_.size()},
          {"odometry_cov", std::string(enum_name(graph_config_.odometry_cov))},
          {"odometry_cov_scale", final_odometry_cov_scale_},
          {"loss_odometry_cov_fraction", final_loss_fraction_},
          {"verify", stats_json(verify_ms)},
          {"optimize_streaming", stats_json(solve_ms_)},
          {"end_of_stream",
           {{"loops_verified", drain_verified_},
            {"loops_verified_in_parallel", drain_verified_ahead_},
            {"features_detected_in_parallel", drain_prefetched_}}},
          {"optimize_final",
           {{"ms", final_solve_ms_},
            {"iterations", final_report_.iterations},
            {"initial_cost", final_report_.initial_cost},
            {"final_cost", final_report_.final_cost},
            {"converged", final_report_.converged}}}};
}

nlohmann::json LoopCloser::summary_fields(const std::vector<StampedPose>& tracked) const {
  nlohmann::json closure = summary();
  nlohmann::json corrected;
  if (!final_solve_error_.empty()) {
    corrected = {{"available", false}, {"why", "the final pose-graph solve failed: " + final_solve_error_}};
    closure["final_solve_error"] = final_solve_error_;
  } else {
    corrected = trajectory_accuracy_json(this->corrected(tracked), dataset_);
    if (corrected.value("available", false))
      corrected["poses"] = "odometry poses with status tracking, corrected by the pose graph";
  }
  return {{"loops_verified", closure["verified"]},
          {"loops_rejected_geometry", closure["rejected_geometry"]},
          {"loops_skipped_geometry", closure["skipped"]},
          {"trajectory_accuracy_corrected", std::move(corrected)},
          {"loop_closure", std::move(closure)}};
}

std::string LoopCloser::profile_line() const {
  if (!active_) return {};
  std::vector<double> verify_ms;
  for (const LoopResult& r : results_)
    if (!r.skipped) verify_ms.push_back(r.verify_ms);
  const double verify_total = std::accumulate(verify_ms.begin(), verify_ms.end(), 0.0);
  const double solve_total = std::accumulate(solve_ms_.begin(), solve_ms_.end(), 0.0);
  return fmt::format(
      "loop closure (off the frame path): verify {} loops {:.1f} ms ({:.1f} ms/loop); {} streaming solves "
      "{:.1f} ms; final solve {:.1f} ms\n",
      verify_ms.size(), verify_total,
      verify_ms.empty() ? 0.0 : verify_total / static_cast<double>(verify_ms.size()), solve_ms_.size(),
      solve_total, final_solve_ms_);
}

}  // namespace loopgate
