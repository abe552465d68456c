#include "stages/gate/pose_gate.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "stages/gate/combined_distance.hpp"

// nanoflann 1.4.2 copies trees with an uninitialised bounding box (filled by buildIndex() before any use);
// GCC 12 flags the copy when inlined.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <nanoflann.hpp>
#pragma GCC diagnostic pop

namespace loopgate {
namespace {

// nanoflann dataset adaptor over the stored positions; only the first `count` (inserted) are indexed.
struct PositionCloud {
  const std::vector<Eigen::Vector3d>* positions_m = nullptr;
  std::size_t count = 0;

  std::size_t kdtree_get_point_count() const { return count; }
  double kdtree_get_pt(std::uint32_t idx, std::size_t dim) const {
    return (*positions_m)[idx][static_cast<Eigen::Index>(dim)];
  }
  template <class Bbox>
  bool kdtree_get_bbox(Bbox& /*bb*/) const {
    return false;
  }
};

// A symmetric 3x3 covariance as its upper triangle (48 bytes a frame instead of 72): the gate symmetrises
// every covariance first (0.5 (P + P^T) is exactly symmetric), so matrix() gives back the same matrix.
struct SymmetricCov {
  double xx, xy, xz, yy, yz, zz;
  static SymmetricCov of(const Eigen::Matrix3d& P) {
    return {P(0, 0), P(0, 1), P(0, 2), P(1, 1), P(1, 2), P(2, 2)};
  }
  Eigen::Matrix3d matrix() const {
    Eigen::Matrix3d P;
    P << xx, xy, xz, xy, yy, yz, xz, yz, zz;
    return P;
  }
};

using Metric = nanoflann::L2_Simple_Adaptor<double, PositionCloud, double, std::uint32_t>;
using Tree = nanoflann::KDTreeSingleIndexDynamicAdaptor<Metric, PositionCloud, 3, std::uint32_t>;

// Collects every stored index with squared Euclidean distance < radius_sq_m2 (no ordering, no pairs).
class CollectWithinRadius {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;

  CollectWithinRadius(double radius_sq_m2, std::vector<std::uint32_t>& out)
      : radius_sq_m2_(radius_sq_m2), out_(out) {
    out_.clear();
  }
  std::size_t size() const { return out_.size(); }
  bool full() const { return true; }
  bool addPoint(double dist_sq_m2, std::uint32_t index) {
    if (dist_sq_m2 < radius_sq_m2_) out_.push_back(index);
    return true;
  }
  double worstDist() const { return radius_sq_m2_; }

 private:
  double radius_sq_m2_;
  std::vector<std::uint32_t>& out_;
};

}  // namespace

struct PoseGate::Impl {
  GateConfig config;
  std::string source;

  // Every frame seen, in order (index k = storage index, also the KD-tree index).
  std::vector<std::int64_t> frames;
  std::vector<Eigen::Vector3d> positions_m;
  std::vector<SymmetricCov> covariances_m2;  // symmetrised: the upper triangle holds it exactly
  std::vector<double> max_eigen_m2;          // lambda_max(P_k), clamped at 0
  std::vector<double> travel_m;              // path length of the positions from the first frame to frame k

  PositionCloud cloud;
  std::unique_ptr<Tree> tree;
  double max_tree_eigen_m2 = 0.0;

  // Scratch buffers of the search.
  struct Scratch {
    std::vector<std::uint32_t> seed_indices;
    std::vector<double> seed_dists_sq;
    std::vector<std::uint32_t> candidates;
  };
  Scratch scratch;

  Impl(const GateConfig& c, std::string s) : config(c), source(std::move(s)) {
    config.validate();
    cloud.positions_m = &positions_m;
    tree = std::make_unique<Tree>(
        3, cloud,
        nanoflann::KDTreeSingleIndexAdaptorParams(static_cast<std::size_t>(config.kdtree_leaf_size)));
  }

  [[noreturn]] void fail(std::int64_t frame, const std::string& what) const {
    throw DataError(source, "frame " + std::to_string(frame) + ": " + what);
  }

  // Delayed insertion: stored frames k with frame_k <= frame - gap and travel_k <= travel_now - min_travel
  // enter the tree (both hold for a prefix of the stored frames: frames and travel never decrease).
  void insert_up_to(std::int64_t frame, double travel_now_m) {
    const std::int64_t last_allowed = frame - static_cast<std::int64_t>(config.gap_frames);
    const double last_travel_m = travel_now_m - config.revisit.min_travel_m;
    const std::size_t first = cloud.count;
    std::size_t end = first;
    while (end < frames.size() && frames[end] <= last_allowed && travel_m[end] <= last_travel_m) {
      max_tree_eigen_m2 = std::max(max_tree_eigen_m2, max_eigen_m2[end]);
      ++end;
    }
    if (end == first) return;
    cloud.count = end;
    tree->addPoints(static_cast<std::uint32_t>(first), static_cast<std::uint32_t>(end - 1));
  }

  // Exact combined distance to stored frame k; keeps the minimum, ties to the smallest frame.
  void rescore(std::uint32_t k, const Eigen::Vector3d& p_m, const Eigen::Matrix3d& P_m2,
               GateDecision& best) const {
    const double d = combined_distance(p_m, P_m2, positions_m[k], covariances_m2[k].matrix());
    ++best.candidates_rescored;
    const std::int64_t j = frames[k];
    if (!best.has_nearest || d < best.distance_m || (d == best.distance_m && j < best.nearest_frame)) {
      best.has_nearest = true;
      best.distance_m = d;
      best.nearest_frame = j;
    }
  }

  // Checks the pose; returns the symmetrised covariance and its largest eigenvalue (clamped at 0).
  std::pair<Eigen::Matrix3d, double> checked_covariance(std::int64_t frame, const Eigen::Vector3d& p_m,
                                                        const Eigen::Matrix3d& P_in_m2) const {
    if (!p_m.allFinite()) fail(frame, "position is not finite");
    if (!P_in_m2.allFinite()) fail(frame, "position covariance is not finite");
    const Eigen::Matrix3d P_m2 = 0.5 * (P_in_m2 + P_in_m2.transpose());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(P_m2, Eigen::EigenvaluesOnly);
    const double lmin_m2 = eig.eigenvalues()(0);
    const double lmax_m2 = std::max(0.0, eig.eigenvalues()(2));
    if (lmin_m2 < -config.covariance_tolerance_m2) {
      fail(frame, "position covariance is not positive semi-definite (smallest eigenvalue " +
                      std::to_string(lmin_m2) + " m^2, expected >= -" +
                      std::to_string(config.covariance_tolerance_m2) + ")");
    }
    return {P_m2, lmax_m2};
  }

  // Decision against the frames currently in the tree.
  GateDecision decide(std::int64_t frame, const Eigen::Vector3d& p_m, const Eigen::Matrix3d& P_m2,
                      double lmax_m2, Scratch& buffers) const {
    GateDecision decision;
    decision.frame = frame;
    decision.sigma_m = position_sigma_m(P_m2, config.sigma_norm);
    decision.threshold_m = gate_threshold_m(decision.sigma_m, config.confidence_scale, config.beta_m);
    if (cloud.count > 0) {
      search(p_m, P_m2, lmax_m2, buffers, decision);
      decision.gated = decision.distance_m < decision.threshold_m;
    }
    return decision;
  }

  GateDecision process(std::int64_t frame, const Eigen::Vector3d& p_m, const Eigen::Matrix3d& P_in_m2) {
    if (!frames.empty() && frame <= frames.back()) {
      fail(frame, "frame indices must be strictly increasing (previous frame " +
                      std::to_string(frames.back()) + ")");
    }
    if (frame < 0) fail(frame, "frame index must be >= 0");
    if (frames.size() >= std::numeric_limits<std::uint32_t>::max()) fail(frame, "more than 2^32 - 1 frames");
    const auto [P_m2, lmax_m2] = checked_covariance(frame, p_m, P_in_m2);
    const double travel_now_m = travel_m.empty() ? 0.0 : travel_m.back() + (p_m - positions_m.back()).norm();
    insert_up_to(frame, travel_now_m);
    const GateDecision decision = decide(frame, p_m, P_m2, lmax_m2, scratch);
    frames.push_back(frame);
    travel_m.push_back(travel_now_m);
    positions_m.push_back(p_m);
    covariances_m2.push_back(SymmetricCov::of(P_m2));
    max_eigen_m2.push_back(lmax_m2);
    return decision;
  }

  // Exact nearest neighbour under the combined distance among the frames in the tree.
  //
  // Why the Euclidean pre-filter cannot miss the true nearest. Write A_j = I + P_i + P_j (P symmetric,
  // eigenvalues >= -tol with tol <= 0.25, so A_j is positive definite with lambda_min(A_j) >= 0.5). Then
  //   d_j^2 = dp^T A_j^-1 dp >= |dp|^2 / lambda_max(A_j)                  (Rayleigh quotient of A_j^-1)
  //   lambda_max(A_j) <= 1 + lambda_max(P_i) + lambda_max(P_j)            (Weyl: lambda_max is subadditive)
  //                   <= 1 + lmax_i + lmax_tree =: K^2                     (lmax_* clamped at 0; lmax_tree is
  //                                                                          the running max over the tree)
  // so d_j >= |dp_j| / K for every frame j in the tree. Let d_0 be the exact combined distance of any frame
  // already scored. The true minimum d* <= d_0, and every frame j with d_j <= d_0 has
  // |dp_j| <= K * d_j <= K * d_0 =: R. A Euclidean search of radius R therefore reaches every frame that can
  // tie or beat d_0, including all minimisers; rescoring those exactly and keeping the minimum (ties: the
  // smallest frame index, as a brute-force scan in increasing j would) gives the exact answer.
  //
  // Here d_0 is the best combined distance among the Euclidean k nearest (k = kdtree_seed_neighbours),
  // then one radius search. (A single branch-and-bound traversal with a radius shrinking with the best
  // combined distance was tried: it is exact too, but nanoflann's dynamic index is a list of sub-trees
  // searched one after the other, and the first ones seen give loose bounds, so it rescored 100x more.)
  //
  // Floating point: the computed combined distance has a relative error bounded by c * eps *
  // lambda_max(A) / lambda_min(A) <= 2 c * eps * K^2 (Cholesky and the triangular solve are backward
  // stable, and the identity floor keeps lambda_min(A) >= 0.5); nanoflann's squared distances and its
  // incremental box distances are accurate to a few eps, and it keeps points strictly inside the radius.
  // The radius is inflated by a relative slack far above those bounds and floored at the smallest positive
  // double so an exact duplicate position (|dp| = 0) is always reached. Inflating only adds candidates.
  static constexpr double kRelativeSlack = 1e-9;
  static constexpr double kRoundingFactor = 1024.0;

  // Squared search radius (m^2) for a best combined distance d_best.
  static double radius_sq_m2(double d_best, double K_sq, double slack) {
    const double radius_m = d_best * std::sqrt(K_sq) * slack;
    return std::max(radius_m * radius_m * slack, std::numeric_limits<double>::min());
  }

  void search(const Eigen::Vector3d& p_m, const Eigen::Matrix3d& P_m2, double lmax_m2, Scratch& buffers,
              GateDecision& best) const {
    const double query[3] = {p_m.x(), p_m.y(), p_m.z()};
    const double K_sq = 1.0 + lmax_m2 + max_tree_eigen_m2;
    const double slack =
        1.0 + kRelativeSlack + kRoundingFactor * std::numeric_limits<double>::epsilon() * K_sq;
    const nanoflann::SearchParams params(0, 0.0f, false);

    // 1. The Euclidean k nearest give an upper bound d_0 on the best combined distance.
    const std::size_t k = std::min(cloud.count, static_cast<std::size_t>(config.kdtree_seed_neighbours));
    buffers.seed_indices.assign(k, 0);
    buffers.seed_dists_sq.assign(k, 0.0);
    nanoflann::KNNResultSet<double, std::uint32_t> knn(k);
    knn.init(buffers.seed_indices.data(), buffers.seed_dists_sq.data());
    tree->findNeighbors(knn, query, params);
    for (std::size_t s = 0; s < knn.size(); ++s) rescore(buffers.seed_indices[s], p_m, P_m2, best);
    if (!best.has_nearest) return;  // unreachable: the tree is not empty
    // 2. Radius search |dp| <= K * d_0 (with slack), then exact rescoring of everything inside.
    CollectWithinRadius within(radius_sq_m2(best.distance_m, K_sq, slack), buffers.candidates);
    tree->findNeighbors(within, query, params);
    const auto seeds_begin = buffers.seed_indices.begin();
    const auto seeds_end = seeds_begin + static_cast<std::ptrdiff_t>(knn.size());
    for (const std::uint32_t c : buffers.candidates) {
      if (std::find(seeds_begin, seeds_end, c) == seeds_end) rescore(c, p_m, P_m2, best);
    }
  }
};

PoseGate::PoseGate(const GateConfig& config, std::string source)
    : impl_(std::make_unique<Impl>(config, std::move(source))) {}
PoseGate::~PoseGate() = default;
PoseGate::PoseGate(PoseGate&&) noexcept = default;
PoseGate& PoseGate::operator=(PoseGate&&) noexcept = default;

GateDecision PoseGate::process(std::int64_t frame, const PoseEstimate& pose) {
  return impl_->process(frame, pose.T_w_b.translation(), pose.position_cov_m2());
}

GateDecision PoseGate::process(std::int64_t frame, const Eigen::Vector3d& p_w_m,
                               const Eigen::Matrix3d& P_m2) {
  return impl_->process(frame, p_w_m, P_m2);
}

GateDecision PoseGate::query(std::int64_t frame, const Eigen::Vector3d& p_w_m,
                             const Eigen::Matrix3d& P_m2) const {
  const auto [P_sym_m2, lmax_m2] = impl_->checked_covariance(frame, p_w_m, P_m2);
  Impl::Scratch buffers;
  return impl_->decide(frame, p_w_m, P_sym_m2, lmax_m2, buffers);
}

void PoseGate::reserve(std::size_t frames) {
  impl_->frames.reserve(frames);
  impl_->positions_m.reserve(frames);
  impl_->covariances_m2.reserve(frames);
  impl_->max_eigen_m2.reserve(frames);
  impl_->travel_m.reserve(frames);
}

std::size_t PoseGate::frames_seen() const {
  return impl_->frames.size();
}
std::size_t PoseGate::frames_in_tree() const {
  return impl_->cloud.count;
}
double PoseGate::max_tree_eigenvalue_m2() const {
  return impl_->max_tree_eigen_m2;
}
const GateConfig& PoseGate::config() const {
  return impl_->config;
}

}  // namespace loopgate
