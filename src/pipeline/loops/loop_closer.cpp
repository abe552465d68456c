// The loop closer's worker (loop_closer.hpp): poses in, loops queued and taken one by one in submission
// order, the streaming and the final pose-graph solves. Verification: loop_verification.cpp; which loops are
// skipped: loop_skip_policy.cpp; files and summary: loop_edge_writers.cpp.
#include "pipeline/loops/loop_closer.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/dataset.hpp"
#include "pipeline/loops/loop_timing.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

using loop_internal::ms_since;

LoopCloser::LoopCloser(const PipelineConfig& config, const Dataset& dataset, std::size_t first_frame,
                       std::size_t last_frame, bool detects)
    : dataset_(dataset),
      first_(first_frame),
      last_(last_frame),
      active_(detects && config.verify.enabled),
      verify_config_(config.verify),
      graph_config_(config.posegraph),
      verifier_(config.verify, dataset.camera()),
      drain_threads_(config.run.threads) {
  if (!active_) return;
  poses_.resize(last_ - first_);
  sigma_m_.assign(last_ - first_, 0.0);
  if (graph_config_.odometry_cov == PoseGraphOdometryCov::kOdometry) {
    step_cov_.assign(last_ - first_, PoseCov::Zero());
    has_step_cov_.assign(last_ - first_, 0);
  }
  pending_by_frame_.assign(last_ - first_, 0);
  if (!dataset.has_images()) {
    unusable_ = VerifyNote{VerifyReason::kImageMissing, "geometry: the dataset has no images"};
  } else if (const auto camera = dataset.camera()) {
    unusable_ = verifier_.unusable_reason(cv::Size(camera->width_px, camera->height_px));
  } else {
    unusable_ = verifier_.unusable_reason(cv::Size(0, 0));
  }
  if (unusable_) spdlog::warn("verify: loops are not verified: {}", unusable_->text);
  worker_ = std::thread([this] { work(); });
}

LoopCloser::~LoopCloser() {
  if (worker_.joinable()) {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    worker_.join();
  }
}

void LoopCloser::record_pose(std::size_t frame, const Eigen::Isometry3d& T_w_b, double sigma_m,
                             const std::optional<PoseCov>& step_cov) {
  if (!active_ || frame < first_ || frame >= last_) return;
  poses_[frame - first_] = T_w_b;
  sigma_m_[frame - first_] = sigma_m;
  if (!step_cov_.empty() && step_cov) {
    step_cov_[frame - first_] = *step_cov;
    has_step_cov_[frame - first_] = 1;
  }
}

PoseCov LoopCloser::odometry_edge_cov(std::size_t a, std::size_t b, double scale) const {
  const Eigen::Isometry3d& T_w_a = *poses_[a - first_];
  const Eigen::Isometry3d& T_w_b = *poses_[b - first_];
  const Eigen::Isometry3d T_a_w = T_w_a.inverse();
  if (step_cov_.empty()) return graph_config_.model_cov(T_a_w * T_w_b);
  PoseCov cov = PoseCov::Zero();
  const Eigen::Isometry3d* T_w_prev = &T_w_a;
  for (std::size_t f = a + 1; f <= b; ++f) {
    if (!poses_[f - first_]) continue;
    if (!has_step_cov_[f - first_]) return graph_config_.model_cov(T_a_w * T_w_b);
    const Eigen::Isometry3d& T_w_f = *poses_[f - first_];
    cov = compose_pose_cov(T_a_w * *T_w_prev, cov, T_w_prev->inverse() * T_w_f, step_cov_[f - first_]);
    T_w_prev = &T_w_f;
  }
  return graph_config_.with_floors(scale * cov);
}

LoopCloser::OdometryScales LoopCloser::odometry_cov_scale(const std::vector<LoopResult>& loops,
                                                          std::size_t span) const {
  if (step_cov_.empty()) return {};
  if (graph_config_.odometry_cov_scale > 0) return {graph_config_.odometry_cov_scale, 1.0};
  // Each recorded frame's covariance relative to the start of its chain of step covariances (a frame without
  // one starts a chain): the odometry's covariance of T_j_i is then step_pose_cov of j's and i's.
  std::vector<std::int64_t> chain(span, -1);
  std::vector<PoseCov> cov(span, PoseCov::Zero());
  std::vector<Eigen::Isometry3d> T_o_f(span, Eigen::Isometry3d::Identity());
  std::int64_t chains = -1;
  std::optional<std::size_t> previous;
  for (std::size_t k = 0; k < span; ++k) {
    if (!poses_[k]) continue;
    if (!previous || !has_step_cov_[k]) {
      chain[k] = ++chains;
    } else {
      const std::size_t p = *previous;
      chain[k] = chain[p];
      T_o_f[k] = T_o_f[p] * (poses_[p]->inverse() * *poses_[k]);
      cov[k] = compose_pose_cov(T_o_f[p], cov[p], poses_[p]->inverse() * *poses_[k], step_cov_[k]);
    }
    previous = k;
  }
  std::vector<LoopInnovation> innovations;
  std::vector<std::size_t> loop_gaps;  // i - j
  for (const LoopResult& r : loops) {
    if (r.loop.query < first_ || r.loop.reference < first_) continue;
    const std::size_t i = r.loop.query - first_, j = r.loop.reference - first_;
    if (i >= span || j >= i || chain[i] < 0 || chain[i] != chain[j]) continue;
    LoopInnovation innovation;
    const Eigen::Isometry3d T_j_i = T_o_f[j].inverse() * T_o_f[i];
    innovation.error.head<3>() = r.result.T_j_i.translation() - T_j_i.translation();
    innovation.error.tail<3>() = so3_log(T_j_i.rotation().transpose() * r.result.T_j_i.rotation());
    innovation.odometry_cov = step_pose_cov(T_o_f[j], cov[j], T_o_f[i], cov[i]);
    innovation.loop_cov = r.result.cov;
    innovation.check_scale = odometry_check_scale(innovation.odometry_cov, sigma_m_[i], sigma_m_[j]);
    innovations.push_back(innovation);
    loop_gaps.push_back(i - j);
  }
  const double scale = odometry_cov_scale_from_loops(innovations, 3, 1e6);
  if (innovations.size() < 3) {
    for (const LoopInnovation& n : innovations)
      spdlog::debug("posegraph: a loop's check scale {:.3g}, its NIS at scale 1 {:.3g}; scale {:.3g}",
                    n.check_scale, n.error.dot((n.odometry_cov + n.loop_cov).ldlt().solve(n.error)), scale);
  }
  // The loss sees the graph's covariance of T_j_i: the steps' scaled, plus the odometry edges' floors, one
  // per node between j and i (relative_odometry_cov()). The fraction of it the loops confirm, at most 1, down
  // to where it no longer counts beside the edges' (a numerical floor: the loss is then posegraph.loss_scale,
  // as for an odometry that knows T_j_i exactly).
  for (std::size_t n = 0; n < innovations.size(); ++n)
    innovations[n].odometry_cov = with_node_floors(innovations[n].odometry_cov, loop_gaps[n], scale);
  constexpr double kMinLossScale = 1e-6;
  return {scale, odometry_cov_scale_from_loops(innovations, 3, 1.0, kMinLossScale)};
}

std::optional<Eigen::Isometry3d> LoopCloser::pose_of(std::size_t frame) const {
  if (frame < first_ || frame >= last_) return std::nullopt;
  return poses_[frame - first_];
}

void LoopCloser::submit(const Detection& loop) {
  if (!active_) return;
  {
    std::lock_guard lock(mutex_);
    queue_.push_back(loop);
    if (loop.query >= first_ && loop.query < last_) ++pending_by_frame_[loop.query - first_];
  }
  wake_.notify_all();
}

std::optional<std::string> LoopCloser::geometry_cell(std::size_t frame) const {
  if (!active_) return std::string();
  std::lock_guard lock(mutex_);
  if (frame >= first_ && frame < last_ && pending_by_frame_[frame - first_] > 0) return std::nullopt;
  std::string cell;
  for (const LoopResult& r : results_) {
    if (r.loop.query != frame) continue;
    cell += (cell.empty() ? "" : "; ") +
            (r.result.verified ? fmt::format("verified j={} ({} inliers)", r.loop.reference, r.result.inliers)
                               : fmt::format("j={} {}", r.loop.reference, r.result.reason));
  }
  return cell;
}

bool LoopCloser::odometry_unbroken(std::size_t from, std::size_t to) const {
  if (from < first_ || to >= last_ || from > to) return false;
  for (std::size_t f = from; f <= to; ++f)
    if (!poses_[f - first_]) return false;
  return true;
}

void LoopCloser::work() {
  for (;;) {
    Detection loop;
    bool draining = false;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;  // stopping, nothing left
      loop = queue_.front();
      draining = stopping_;
    }
    if (draining) verify_ahead();
    LoopResult result = verify_one(loop, draining);
    if (result_listener_) result_listener_(loop, result.result);
    if (verify_config_.min_information_gain > 0 && !result.skipped) add_innovation(result);
    bool solve_now = false;
    {
      std::lock_guard lock(mutex_);
      queue_.pop_front();
      if (!result.skipped) ms_by_frame_[loop.query].verify_ms += result.verify_ms;
      results_.push_back(std::move(result));
      const std::size_t verified = static_cast<std::size_t>(std::count_if(
          results_.begin(), results_.end(), [](const LoopResult& r) { return r.result.verified; }));
      solve_now = graph_config_.enabled && graph_config_.optimize_on_loop && queue_.empty() && !stopping_ &&
                  verified > verified_at_last_solve_;
      if (solve_now) verified_at_last_solve_ = verified;
    }
    double solve_ms = 0;
    if (solve_now) {
      try {
        solve_ms = solve(loop.query, false);
      } catch (const std::exception& e) {
        spdlog::warn("posegraph: solve while streaming failed: {}", e.what());
      }
    }
    // The frame's rows (frames.csv, timing.csv) wait until its loop is verified and the solve it started is
    // done, so that timing.csv books that solve on it.
    std::lock_guard lock(mutex_);
    if (solve_now) ms_by_frame_[loop.query].optimize_ms += solve_ms;
    if (loop.query >= first_ && loop.query < last_) --pending_by_frame_[loop.query - first_];
  }
}

LoopCloser::FrameMs LoopCloser::frame_ms(std::size_t frame) const {
  std::lock_guard lock(mutex_);
  const auto it = ms_by_frame_.find(frame);
  return it != ms_by_frame_.end() ? it->second : FrameMs{};
}

double LoopCloser::solve(std::size_t last, bool final) {
  std::vector<LoopResult> loops;
  {
    std::lock_guard lock(mutex_);
    for (const LoopResult& r : results_)
      if (r.result.verified) loops.push_back(r);
  }
  const std::size_t span = std::min(last + 1, last_) - first_;
  std::vector<char> is_node(span, 0);
  const auto every = static_cast<std::size_t>(graph_config_.node_every_frames);
  for (std::size_t k = 0; k < span; ++k) is_node[k] = (k % every == 0) && poses_[k].has_value();
  for (const LoopResult& r : loops) {
    for (const std::size_t f : {r.loop.query, r.loop.reference})
      if (f >= first_ && f - first_ < span && poses_[f - first_]) is_node[f - first_] = 1;
  }
  PoseGraph graph(graph_config_);
  std::vector<std::int64_t> node_of(span, -1);
  std::vector<std::size_t> frames;
  for (std::size_t k = 0; k < span; ++k) {
    if (!is_node[k]) continue;
    node_of[k] = static_cast<std::int64_t>(graph.add_node(*poses_[k]));
    frames.push_back(first_ + k);
  }
  const OdometryScales scales = odometry_cov_scale(loops, span);
  const double scale = scales.graph;
  for (std::size_t n = 1; n < frames.size(); ++n) {
    const Eigen::Isometry3d T_a_b = graph.initial_pose(n - 1).inverse() * graph.initial_pose(n);
    graph.add_edge(n - 1, n, EdgeKind::kOdometry, T_a_b, odometry_edge_cov(frames[n - 1], frames[n], scale));
  }
  // Loop edges (the loop's query and reference frame must both be nodes), keyed by (i, j) for the report.
  std::vector<std::pair<std::pair<std::size_t, std::size_t>, std::size_t>> edge_of_loop;
  for (const LoopResult& r : loops) {
    if (r.loop.query - first_ >= span) continue;
    const std::int64_t a = node_of[r.loop.reference - first_];
    const std::int64_t b = node_of[r.loop.query - first_];
    if (a < 0 || b < 0) continue;
    edge_of_loop.push_back({{r.loop.query, r.loop.reference}, graph.edges().size()});
    // The robust loss as wide as the odometry's uncertainty of T_j_i that the loops confirm makes a true
    // loop's residual.
    const PoseCov odometry_ji =
        scales.loss_fraction * relative_odometry_cov(r.loop.reference, r.loop.query, scale);
    graph.add_edge(static_cast<std::size_t>(a), static_cast<std::size_t>(b), EdgeKind::kLoop, r.result.T_j_i,
                   r.result.cov, loop_loss_scale(graph_config_, odometry_ji, r.result.cov));
  }
  const auto start = std::chrono::steady_clock::now();
  const SolveReport report = graph.optimize(final, final ? 0.0 : graph_config_.max_solve_s);
  const double ms = ms_since(start);
  spdlog::debug(
      "posegraph: {} nodes, {} loop edges ({} outliers), odometry covariance x {:.3g} (loss x {:.3g}), {} "
      "iterations, cost {:.3g} -> {:.3g}, {:.1f} ms",
      graph.node_count(), report.loop_edges, report.outliers, scale, scales.loss_fraction, report.iterations,
      report.initial_cost, report.final_cost, ms);
  if (!final) {
    solve_ms_.push_back(ms);
    return ms;
  }
  final_solve_ms_ = ms;
  final_report_ = report;
  final_odometry_cov_scale_ = scale;
  final_loss_fraction_ = scales.loss_fraction;
  nodes_ = frames;
  final_edges_ = graph.edges();
  node_poses_.clear();
  for (std::size_t n = 0; n < graph.node_count(); ++n) node_poses_.push_back(graph.pose(n));
  // Mark the outlier loops (in submission order, like edge_of_loop).
  std::size_t next = 0;
  std::lock_guard lock(mutex_);
  for (LoopResult& r : results_) {
    if (!r.result.verified || next >= edge_of_loop.size()) continue;
    if (edge_of_loop[next].first != std::pair(r.loop.query, r.loop.reference)) continue;
    const PoseGraphEdge& edge = graph.edges().at(edge_of_loop[next++].second);
    r.outlier = edge.outlier;
    r.chi2 = edge.chi2;
  }
  return ms;
}

void LoopCloser::finish() {
  if (!active_) return;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (worker_.joinable()) worker_.join();
  if (!graph_config_.enabled) return;
  try {
    solve(last_ - 1, true);
  } catch (const std::exception& e) {
    final_solve_error_ = e.what();
    if (final_solve_error_.empty()) final_solve_error_ = "unknown error";
    spdlog::error("posegraph: the final solve failed: {}", final_solve_error_);
    nodes_.clear();
    node_poses_.clear();
    final_edges_.clear();
  }
  std::size_t verified = 0, skipped = 0;
  for (const LoopResult& r : results_) {
    verified += r.result.verified ? 1 : 0;
    skipped += r.skipped ? 1 : 0;
  }
  spdlog::info(
      "loop closure: {} loops, {} verified, {} rejected by geometry, {} skipped, {} outliers in the pose "
      "graph; final solve {:.1f} ms",
      results_.size(), verified, results_.size() - verified - skipped, skipped, final_report_.outliers,
      final_solve_ms_);
  const ReasonCounts counts = reason_counts();
  const auto listed = [](const std::map<std::string, std::size_t>& m) {
    std::string text;
    for (const auto& [key, n] : m) text += fmt::format("{}{} {}", text.empty() ? "" : ", ", key, n);
    return text.empty() ? std::string("none") : text;
  };
  spdlog::info("loop closure: rejected by reason: {}; skipped by reason: {}", listed(counts.rejected),
               listed(counts.skipped));
}

}  // namespace loopgate
