// Ground-truth loops (docs/evaluation.md): from positions (radius, gap, plane) or from a
// pairs file, and the true-match test used to score detections.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "core/geometry.hpp"
#include "core/revisit_rule.hpp"

namespace loopgate {

struct GroundTruthConfig {
  double radius_m = 2.0;  // r_true: query i is positive if some j <= i - gap lies within it
  int gap_frames = 20;    // minimum frame gap of a true loop
  // Distances in: xz (KITTI camera frame), xy, yz, or xyz (3-D, EuRoC).
  CoordinatePlane plane = CoordinatePlane::kXz;
  double accept_radius_m = 0.0;  // r_accept for scoring a detection; <= 0 means r_true
  // A revisit needs travel in between: a pair (query, reference) is a loop only when the ground-truth path
  // between them (3-D, summed over consecutive frames) is at least this long. Hovering or standing still
  // within r_true is not a loop. 0 = no such rule. Key min_travel_m.
  RevisitRule revisit;

  // The keys, in order, for loading, printing and the JSON echo (Self is GroundTruthConfig or const
  // GroundTruthConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("radius_m", self.radius_m);
    v("gap_frames", self.gap_frames);
    v("plane", self.plane);
    v("accept_radius_m", self.accept_radius_m);
    v("min_travel_m", self.revisit.min_travel_m);
  }
  void validate() const;  // throws ConfigError naming the key
  double effective_accept_radius_m() const { return accept_radius_m > 0.0 ? accept_radius_m : radius_m; }
};

// Which queries are positives and which (query, reference) pairs are true matches.
class LoopGroundTruth {
 public:
  LoopGroundTruth() = default;

  // From one position per frame (world frame, metres). A uniform grid of cell r_true finds the
  // neighbours (about O(n) for trajectories, not O(n^2)). A non-finite position (NaN) marks a frame
  // without ground truth: it is never positive and never part of a true match; the path across it is the
  // straight line between the frames with ground truth on either side.
  static LoopGroundTruth from_positions(const std::vector<Eigen::Vector3d>& p_w,
                                        const GroundTruthConfig& config);
  // From explicit (query, reference) pairs, 0-based (e.g. botw_pairs.csv). A detection is a true
  // match iff its pair is listed; a query is positive iff it has a listed pair. Pairs outside
  // [0, frame_count) throw std::out_of_range.
  static LoopGroundTruth from_pairs(std::size_t frame_count,
                                    const std::vector<std::pair<std::size_t, std::size_t>>& query_reference);

  std::size_t frame_count() const { return references_.size(); }
  bool is_positive(std::size_t query) const {
    return query < references_.size() && !references_[query].empty();
  }
  std::size_t positive_count() const;
  // Earlier frames that make `query` a positive (sorted): j <= query - gap within r_true, or the listed
  // pairs.
  const std::vector<std::size_t>& true_references(std::size_t query) const { return references_.at(query); }
  // Positions: GT positions of query and reference within r_accept (in the configured plane), whatever
  // their order or gap, and at least min_travel_m of ground-truth path apart. Pairs: the pair is listed.
  bool is_true_match(std::size_t query, std::size_t reference) const;
  // Positions only: the same place (within r_accept) but less than min_travel_m of path apart, e.g. a
  // drone hovering or a car at a light. Such a detection is neither a true nor a false loop: it is not
  // judged (dropped before the PR sweep and counted apart), because the place is right and only the
  // definition of a revisit excludes it. Always false for pairs and when min_travel_m is 0.
  bool is_same_place_without_travel(std::size_t query, std::size_t reference) const;
  bool uses_positions() const { return !positions_.empty(); }
  // All true loop pairs (query, reference), query ascending.
  std::vector<std::pair<std::size_t, std::size_t>> pairs() const;

 private:
  // Positions only, indices in range: within r_accept; less than min_travel_m of path apart (never when 0).
  bool within_accept_radius(std::size_t query, std::size_t reference) const;
  bool without_travel(std::size_t query, std::size_t reference) const;

  std::vector<std::vector<std::size_t>> references_;
  std::vector<Eigen::Vector3d> positions_;  // projected (unused axis zeroed); empty for pairs
  std::vector<double> travel_m_;            // ground-truth path length from frame 0 (3-D); empty for pairs
  double accept_radius_m_ = 0.0;
  double min_travel_m_ = 0.0;
};

}  // namespace loopgate
