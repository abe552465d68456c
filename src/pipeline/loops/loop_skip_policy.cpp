// Which loops the loop closer verifies (loop_closer.hpp, docs/loop-correction.md "Which loops are skipped"):
// the information a loop edge adds to the odometry's covariance from j to i, the skip window and the loops
// per query frame.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/geometry.hpp"
#include "pipeline/loops/loop_closer.hpp"

namespace loopgate {

bool LoopCloser::in_skip_window(const Detection& earlier, bool verified, const Detection& later) const {
  const int window =
      verified ? verify_config_.skip_after_verified_frames : verify_config_.skip_after_rejected_frames;
  const auto near = [window](std::size_t a, std::size_t b) {
    return (a > b ? a - b : b - a) <= static_cast<std::size_t>(window);
  };
  return window > 0 && near(earlier.query, later.query) && near(earlier.reference, later.reference);
}

void LoopCloser::extend_chain(std::size_t span) {
  span = std::min(span, poses_.size());
  if (chain_id_.size() >= span) return;
  std::size_t k = chain_id_.size();
  chain_id_.resize(span, -1);
  chain_cov_.resize(span, PoseCov::Zero());
  chain_T_.resize(span, Eigen::Isometry3d::Identity());
  for (; k < span; ++k) {
    if (!poses_[k]) continue;
    if (!chain_previous_ || !has_step_cov_[k]) {
      chain_id_[k] = ++chains_;
    } else {
      const std::size_t p = *chain_previous_;
      const Eigen::Isometry3d T_p_k = poses_[p]->inverse() * *poses_[k];
      chain_id_[k] = chain_id_[p];
      chain_T_[k] = chain_T_[p] * T_p_k;
      chain_cov_[k] = compose_pose_cov(chain_T_[p], chain_cov_[p], T_p_k, step_cov_[k]);
    }
    chain_previous_ = k;
  }
}

double LoopCloser::scale_now() const {
  if (step_cov_.empty()) return 1.0;
  if (graph_config_.odometry_cov_scale > 0) return graph_config_.odometry_cov_scale;
  return odometry_cov_scale_from_loops(innovations_, 3, 1e6);
}

PoseCov LoopCloser::relative_odometry_cov(std::size_t j, std::size_t i, double scale) {
  const Eigen::Isometry3d T_j_i = pose_of(j)->inverse() * *pose_of(i);
  if (step_cov_.empty()) return graph_config_.model_cov(T_j_i);
  const std::size_t a = j - first_, b = i - first_;
  extend_chain(std::max(a, b) + 1);
  if (chain_id_[a] < 0 || chain_id_[a] != chain_id_[b]) return graph_config_.model_cov(T_j_i);
  return with_node_floors(step_pose_cov(chain_T_[a], chain_cov_[a], chain_T_[b], chain_cov_[b]),
                          b > a ? b - a : a - b, scale);
}

PoseCov LoopCloser::with_node_floors(const PoseCov& cov, std::size_t frames, double scale) const {
  const double nodes = std::max(
      1.0, std::floor(static_cast<double>(frames) / static_cast<double>(graph_config_.node_every_frames)));
  return scale * cov + nodes * graph_config_.with_floors(PoseCov::Zero());
}

std::optional<LoopCloser::SkipBasis> LoopCloser::skip_basis(const Detection& loop) const {
  const std::size_t lo = std::min(loop.query, loop.reference), hi = std::max(loop.query, loop.reference);
  std::optional<SkipBasis> basis;
  for (const CheckedSpan& c : checked_spans_) {
    const std::size_t overlap_lo = std::max(lo, c.reference), overlap_hi = std::min(hi, c.query);
    const std::size_t shared = overlap_hi > overlap_lo ? overlap_hi - overlap_lo : 0;
    const std::size_t either = std::max(hi, c.query) - std::min(lo, c.reference);
    if (either == 0 || 2 * shared < either) continue;
    const double scale = std::max(basis ? basis->scale : 0.0, c.scale);
    basis = SkipBasis{scale, c.loop_cov};  // the most recent covering edge
  }
  if (!basis) return std::nullopt;
  if (step_cov_.empty() || graph_config_.odometry_cov_scale > 0)
    basis->scale = scale_now();
  else
    basis->scale = std::max(basis->scale, scale_now());
  return basis;
}

void LoopCloser::add_innovation(const LoopResult& r) {
  if (step_cov_.empty() || !r.result.verified || !pose_of(r.loop.query) || !pose_of(r.loop.reference)) return;
  const std::size_t i = r.loop.query - first_, j = r.loop.reference - first_;
  if (j >= i) return;
  extend_chain(i + 1);
  if (chain_id_[i] < 0 || chain_id_[i] != chain_id_[j]) return;
  LoopInnovation innovation;
  const Eigen::Isometry3d T_j_i = chain_T_[j].inverse() * chain_T_[i];
  innovation.error.head<3>() = r.result.T_j_i.translation() - T_j_i.translation();
  innovation.error.tail<3>() = so3_log(T_j_i.rotation().transpose() * r.result.T_j_i.rotation());
  innovation.odometry_cov = step_pose_cov(chain_T_[j], chain_cov_[j], chain_T_[i], chain_cov_[i]);
  innovation.loop_cov = r.result.cov;
  innovation.check_scale = odometry_check_scale(innovation.odometry_cov, sigma_m_[i], sigma_m_[j]);
  innovations_.push_back(innovation);
  checked_spans_.push_back(
      {r.loop.query, r.loop.reference, odometry_cov_scale_from_loops({innovation}, 1, 1e6), r.result.cov});
}

std::optional<VerifyNote> LoopCloser::skip_reason(const Detection& loop) {
  // A loop the odometry already knows (standing still, hovering, the frames just before a query): an edge as
  // certain as the last one verified over the same odometry would shrink the odometry's own uncertainty of
  // T_j_i, scaled by what the verified loops showed, by less than verify.min_information_gain. Such an edge
  // corrects nothing. A loop over odometry no verified loop has checked is never skipped for its gain.
  if (verify_config_.min_information_gain > 0 && pose_of(loop.query) && pose_of(loop.reference) &&
      loop.reference != loop.query) {
    const std::optional<SkipBasis> basis = skip_basis(loop);
    const PoseCov odometry =
        relative_odometry_cov(loop.reference, loop.query, basis ? basis->scale : scale_now());
    const PoseCov edge = basis ? basis->edge_cov : PoseCov(PoseCov::Identity());
    // The loops of one revisit correct the trajectory together: this one and those before it over the same
    // odometry, each an edge as certain as the last verified.
    std::size_t together = 1;
    const std::size_t lo = std::min(loop.query, loop.reference), hi = std::max(loop.query, loop.reference);
    for (const LoopResult& r : results_) {
      const std::size_t overlap_lo = std::max(lo, r.loop.reference), overlap_hi = std::min(hi, r.loop.query);
      const std::size_t shared = overlap_hi > overlap_lo ? overlap_hi - overlap_lo : 0;
      const std::size_t either = std::max(hi, r.loop.query) - std::min(lo, r.loop.reference);
      if (either > 0 && 2 * shared >= either) ++together;
    }
    const double gain = basis ? loop_information_gain(odometry, edge / static_cast<double>(together)) : 1.0;
    if (gain < verify_config_.min_information_gain) {
      const double sigma_m = std::sqrt(
          std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(odometry.topLeftCorner<3, 3>())
                            .eigenvalues()
                            .maxCoeff()));
      return VerifyNote{VerifyReason::kSmallInformationGain,
                        fmt::format("skipped: information gain {:.2f} < {} (the odometry's sigma from j "
                                    "to i {:.3f} m, a loop edge's {:.3f} m)",
                                    gain, verify_config_.min_information_gain, sigma_m,
                                    std::sqrt(edge.topLeftCorner<3, 3>().diagonal().maxCoeff()))};
    }
  }
  int tried_for_query = 0;
  for (auto it = results_.rbegin(); it != results_.rend(); ++it) {
    const LoopResult& r = *it;
    if (r.skipped) continue;
    if (r.loop.query == loop.query) ++tried_for_query;
    if (in_skip_window(r.loop, r.result.verified, loop))
      return VerifyNote{VerifyReason::kSkipWindow,
                        fmt::format("skipped: near ({}, {}) {}", r.loop.query, r.loop.reference,
                                    r.result.verified ? "verified" : "rejected")};
  }
  if (verify_config_.max_per_query > 0 && tried_for_query >= verify_config_.max_per_query)
    return VerifyNote{
        VerifyReason::kMaxPerQuery,
        fmt::format("skipped: {} loop(s) of frame {} already verified", tried_for_query, loop.query)};
  return std::nullopt;
}

bool LoopCloser::would_skip(const Detection& earlier, bool verified, const Detection& later) const {
  return in_skip_window(earlier, verified, later) ||
         (verify_config_.max_per_query > 0 && earlier.query == later.query);
}

}  // namespace loopgate
