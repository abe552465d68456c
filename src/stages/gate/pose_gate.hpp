// The pose gate (paper eq. 8-10, docs/gating.md): for every frame i, the exact nearest
// past frame j <= i - gap under the combined distance, found with a dynamic KD-tree over past positions and
// an exact rescoring, and the decision d < 1.96 * sigma_i + beta.
//
// One serial node owns a PoseGate and feeds it one pose per frame in increasing frame order. Not
// thread-safe (nanoflann must not be mutated while queried).
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>

#include "core/types.hpp"
#include "stages/gate/gate_config.hpp"

namespace loopgate {

// What the gate decided for one frame i.
struct GateDecision {
  std::int64_t frame = -1;          // i
  bool has_nearest = false;         // false while no frame j <= i - gap has been seen
  std::int64_t nearest_frame = -1;  // j minimising d (ties: smallest j); -1 without a nearest
  double distance_m = std::numeric_limits<double>::infinity();  // d(U_i, U_j), eq. 8-9
  double sigma_m = 0.0;                                         // sigma_i (norm per GateConfig::sigma_norm)
  double threshold_m = 0.0;                                     // confidence_scale * sigma_i + beta
  bool gated = false;                                           // has_nearest && distance_m < threshold_m
  std::size_t candidates_rescored = 0;  // frames whose combined distance was evaluated exactly
};

class PoseGate {
 public:
  // Validates the config (ConfigError). `source` names the pose source in DataError messages.
  explicit PoseGate(const GateConfig& config, std::string source = "odometry");
  ~PoseGate();
  PoseGate(const PoseGate&) = delete;
  PoseGate& operator=(const PoseGate&) = delete;
  PoseGate(PoseGate&&) noexcept;
  PoseGate& operator=(PoseGate&&) noexcept;

  // Feeds frame `frame` (strictly increasing; gaps in the numbering are allowed): frames k <= frame - gap
  // enter the KD-tree first (delayed insertion), then the nearest is searched, then this frame is stored.
  // Throws DataError (source, frame, what was expected) for a non-increasing frame index, non-finite
  // position or covariance, or a covariance with an eigenvalue below -covariance_tolerance_m2.
  GateDecision process(std::int64_t frame, const PoseEstimate& pose);
  GateDecision process(std::int64_t frame, const Eigen::Vector3d& p_w_m, const Eigen::Matrix3d& P_m2);

  // The decision `process` would give against the frames already in the tree, without inserting or
  // storing anything (no delayed insertion either). Same input checks (DataError). For benchmarks and
  // diagnostics.
  GateDecision query(std::int64_t frame, const Eigen::Vector3d& p_w_m, const Eigen::Matrix3d& P_m2) const;

  // Room for `frames` frames (what the run may release), so that the per-frame storage neither keeps up to
  // twice its frames nor copies them as it grows (reserved pages not written take no memory).
  void reserve(std::size_t frames);

  std::size_t frames_seen() const;
  std::size_t frames_in_tree() const;
  // Running max of lambda_max(P_j) over the frames in the tree (m^2; 0 when empty).
  double max_tree_eigenvalue_m2() const;
  const GateConfig& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace loopgate
