// A revisit driven in another lane (route.revisit_lateral_offset_m): the procedural route's poses that pass a
// street driven before are moved sideways, by a lane change before the revisit and back after it. The street
// itself (the world built around the path, the ground-truth loops) stays where the route without the offset
// runs, so that an offset revisit has the loop pairs of the same-lane one and the same street to look at.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/types.hpp"
#include "sim/trajectory.hpp"

namespace loopgate::sim {

// Per pose, whether it revisits the street: some earlier pose lies within config.revisit_radius_m
// (horizontally, up = +z) with at least config.revisit_min_travel_m of path between them.
std::vector<bool> find_revisit_poses(const std::vector<StampedPose>& poses,
                                     const ProceduralRouteConfig& config);

// Per pose, the fraction of the revisit offset applied: 1 on a revisit, a smooth ramp (smoothstep of the path
// distance) over config.revisit_lane_change_m before and after each revisit, 0 elsewhere.
std::vector<double> revisit_offset_weights(const std::vector<StampedPose>& poses,
                                           const std::vector<bool>& revisit, double lane_change_m);

// Moves the revisits of `poses` (the street path, from make_procedural_route) sideways by
// config.revisit_lateral_offset_m (positive: to the left of the direction of travel) and returns the shift
// applied to each pose, in world coordinates (all zero when the offset is 0). street = driven - shift.
std::vector<Eigen::Vector3d> apply_revisit_offset(const ProceduralRouteConfig& config,
                                                  std::vector<StampedPose>& poses);

}  // namespace loopgate::sim
