// Configuration of the pose gate and of the candidate areas (docs/gating.md,
// the paper §4 eq. 8-10). Section "gate".
#pragma once

#include <span>

#include "core/enum_names.hpp"
#include "core/revisit_rule.hpp"

namespace loopgate {

// gate.sigma_norm: sigma_i of eq. 10 from the position covariance P_i: sqrt(lambda_max(P_i)) ("max_eigen")
// or sqrt(trace(P_i)) ("trace").
enum class SigmaNorm { kMaxEigen, kTrace };
inline constexpr EnumName<SigmaNorm> kSigmaNormNames[] = {{SigmaNorm::kMaxEigen, "max_eigen"},
                                                          {SigmaNorm::kTrace, "trace"}};
constexpr std::span<const EnumName<SigmaNorm>> enum_names(SigmaNorm) {
  return kSigmaNormNames;
}

struct GateConfig {
  // Only past frames j <= i - gap_frames are searched (paper: 30; should follow the frame rate).
  int gap_frames = 30;
  // ... and only frames the odometry has travelled at least min_travel_m from since (the path length of the
  // positions the gate was given, from j to i): standing still or hovering, a camera sees the place it has
  // not left, and such a "revisit" is no loop. The same definition of a revisit as eval.min_travel_m's on the
  // ground truth (2 m). 0: no travel needed (the paper's gate: the frame gap only). Key min_travel_m.
  RevisitRule revisit{2.0};
  // beta: allowed drift between j and i, added to the threshold, in metres (per environment).
  double beta_m = 5.0;
  // sigma_i = sqrt(lambda_max(P_i)) ("max_eigen", the default) or sqrt(trace(P_i)) ("trace").
  SigmaNorm sigma_norm = SigmaNorm::kMaxEigen;
  // Threshold = confidence_scale * sigma_i + beta (1.96: 95 % of a Gaussian, eq. 10).
  double confidence_scale = 1.96;
  // Numerical noise allowed in a position covariance: eigenvalues down to -covariance_tolerance_m2 are
  // accepted (more negative ones, or non-finite entries, are bad input).
  double covariance_tolerance_m2 = 1e-9;
  // KD-tree leaf size (nanoflann) and the number of Euclidean nearest neighbours whose exact combined
  // distance seeds the search radius (speed only: the result is exact for any value >= 1).
  int kdtree_leaf_size = 10;
  int kdtree_seed_neighbours = 4;

  // Candidate areas (docs/gating.md § Candidate areas). Two gated query frames belong to one cluster when at
  // most area_max_hole_frames non-gated frames separate them and their nearest j differ by at most
  // area_j_tolerance_frames plus the number of query frames between them.
  int area_max_hole_frames = 10;
  int area_j_tolerance_frames = 30;
  // Margins of the rectangle [i_first - m_i, i_last] x [j_min - m_j, j_max + m_j]. m_i must be >= the
  // sequence length L of the DP (checked by CandidateAreaTracker against the L it is given).
  int area_margin_query_frames = 20;
  int area_margin_reference_frames = 20;
  // Streaming horizon: at frame i, rows (query frames) older than i - row_horizon_frames take no new
  // cells, so the matcher can consume a row once it is that old. Must be >= area_margin_query_frames (an
  // area opening at i has its history rows) and > area_max_hole_frames (an area resuming after a hole
  // covers the rows of the hole). Cells an area would add later to a frozen row (when its column range
  // widens long after the row) are not computed; the rectangle is then the bounding box of what was.
  int row_horizon_frames = 40;
  // Feedback of verified loop closures into the gate (docs/gating.md § Gate feedback): frame
  // i's pose and position covariance are re-anchored (stages/gate/reanchor.hpp) through the latest verified
  // loop whose query frame is at least L = run.max_in_flight + the method's verdict delay frames before i.
  // Needs verify.enabled and a streaming gated method (not run.method seqslam); no effect without the gate.
  bool feedback = false;

  // The keys, in order, for loading, printing and the JSON echo (Self is GateConfig or const GateConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("gap_frames", self.gap_frames);
    v("min_travel_m", self.revisit.min_travel_m);
    v("beta_m", self.beta_m);
    v("sigma_norm", self.sigma_norm);
    v("confidence_scale", self.confidence_scale);
    v("covariance_tolerance_m2", self.covariance_tolerance_m2);
    v("kdtree_leaf_size", self.kdtree_leaf_size);
    v("kdtree_seed_neighbours", self.kdtree_seed_neighbours);
    v("area_max_hole_frames", self.area_max_hole_frames);
    v("area_j_tolerance_frames", self.area_j_tolerance_frames);
    v("area_margin_query_frames", self.area_margin_query_frames);
    v("area_margin_reference_frames", self.area_margin_reference_frames);
    v("row_horizon_frames", self.row_horizon_frames);
    v("feedback", self.feedback);
  }
  // Throws ConfigError naming the key and its bounds: gap_frames in [1, 1e6], min_travel_m in [0, 1e6],
  // beta_m in [0, 1e5], confidence_scale in [0, 1000],
  // covariance_tolerance_m2 in [0, 0.25], kdtree_leaf_size in [1, 1e4], kdtree_seed_neighbours in [1, 1000],
  // area_* in [0, 1e4] (query rows) or [0, 1e5] (reference columns), row_horizon_frames in [0, 1e7].
  void validate() const;
  // Throws ConfigError unless area_margin_query_frames >= sequence_length (the DP's L) and
  // row_horizon_frames >= max(area_margin_query_frames, area_max_hole_frames + 1).
  void validate_for_sequence_length(int sequence_length) const;
};

}  // namespace loopgate
