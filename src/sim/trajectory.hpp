// Trajectories for the simulator: sources (KITTI poses, EuRoC ground truth, TUM, a procedural route with
// revisits) and a smooth C2 fit with analytic derivatives, so that images, IMU and ground truth all come
// from one continuous motion.
//
// The fit is a uniform cubic B-spline on position and a cumulative cubic B-spline on SO(3) for the
// orientation (Kim et al. 1995; Sommer et al. 2020), on a common knot grid. Both are C2: velocity,
// acceleration and angular velocity are continuous, so the synthesised IMU is smooth.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "core/types.hpp"

namespace loopgate::sim {

struct TrajectoryFitConfig {
  // Knot spacing of the spline; 0 picks the median spacing of the input samples.
  double knot_spacing_s = 0.0;
  // Weight of the squared second differences of the control points (keeps the least-squares problem
  // well posed where knots outnumber samples, and damps jitter). Relative to the unit data weight.
  double smoothing_weight = 1e-3;
  // Gauss-Newton iterations of the rotation fit, stopped early below `rotation_tolerance_rad`.
  int rotation_iterations = 20;
  double rotation_tolerance_rad = 1e-10;

  // The keys, in order, for loading, printing and the JSON echo (Self is TrajectoryFitConfig or const
  // TrajectoryFitConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("knot_spacing_s", self.knot_spacing_s);
    v("smoothing_weight", self.smoothing_weight);
    v("rotation_iterations", self.rotation_iterations);
    v("rotation_tolerance_rad", self.rotation_tolerance_rad);
  }
  void validate() const;  // throws ConfigError
};

// Kinematic state of the body at one instant, all derived analytically from the spline.
struct TrajectoryState {
  Timestamp t_ns = 0;
  Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
  Eigen::Vector3d v_w_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d a_w_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d omega_b_radps = Eigen::Vector3d::Zero();  // angular velocity in the body frame
};

class SplineTrajectory {
 public:
  // Control points on a uniform grid: segment s spans [start + s*dt, start + (s+1)*dt] and uses controls
  // s..s+3; there are segments + 3 controls. `end_t_ns` (<= start + segments*dt) bounds the valid span.
  SplineTrajectory(Timestamp start_t_ns, Timestamp end_t_ns, double knot_spacing_s,
                   std::vector<Eigen::Vector3d> position_controls_w,
                   std::vector<Eigen::Matrix3d> rotation_controls_w_b);

  // Least-squares fit through time-ordered poses (strictly increasing t_ns, at least 2).
  // Throws std::invalid_argument on unusable input.
  static SplineTrajectory fit(const std::vector<StampedPose>& poses, const TrajectoryFitConfig& config = {});

  Timestamp start_t_ns() const { return start_t_ns_; }
  Timestamp end_t_ns() const { return end_t_ns_; }
  double knot_spacing_s() const { return dt_s_; }
  std::size_t control_count() const { return positions_.size(); }

  // State at t_ns. Outside [start, end] the end pose is held, with zero derivatives.
  TrajectoryState evaluate(Timestamp t_ns) const;
  Eigen::Isometry3d pose(Timestamp t_ns) const { return evaluate(t_ns).T_w_b; }

 private:
  Timestamp start_t_ns_;
  Timestamp end_t_ns_;
  double dt_s_;
  std::vector<Eigen::Vector3d> positions_;
  std::vector<Eigen::Matrix3d> rotations_;
  std::vector<Eigen::Vector3d> rotation_deltas_;  // Log(R_k^T R_{k+1}), precomputed
};

// ---- Trajectory sources (all return body poses T_w_b with timestamps) ----

// KITTI: poses.txt + times.txt (camera-0 poses; the body is the camera).
std::vector<StampedPose> load_kitti_trajectory(const std::filesystem::path& poses_file,
                                               const std::filesystem::path& times_file);
// EuRoC state_groundtruth_estimate0/data.csv.
std::vector<StampedPose> load_euroc_trajectory(const std::filesystem::path& csv_file);
// TUM "t tx ty tz qx qy qz qw".
std::vector<StampedPose> load_tum_trajectory(const std::filesystem::path& file);

// A street-like drive, world up +z; the body frame is x forward, y left, z up, at camera height above the
// ground plane z = 0. Two shapes:
//  - "circuit": a closed rounded-rectangle circuit (length_x_m x length_y_m, centred on the origin, starting
//    mid-way along the bottom straight, counter-clockwise) driven `laps` times, with a lateral offset and a
//    speed variation between laps so that revisits are close but not identical;
//  - "waypoints": a street map as a polyline "x0,y0; x1,y1; ..." (metres) driven once from the first to the
//    last point, every corner rounded with corner_radius_m, so that a drive can revisit some streets (a
//    waypoint sequence that repeats a street) and not others. `laps` and the length_* keys are unused;
//    speed_cycles_per_lap periods of the speed modulation span the whole route, and the lateral offset grows
//    linearly from 0 to lap_lateral_offset_m along it (two passes of one street run that far apart times the
//    fraction of the route between them).
// route.shape: "circuit" or "waypoints" (see ProceduralRouteConfig).
enum class RouteShape { kCircuit, kWaypoints };
inline constexpr EnumName<RouteShape> kRouteShapeNames[] = {{RouteShape::kCircuit, "circuit"},
                                                            {RouteShape::kWaypoints, "waypoints"}};
constexpr std::span<const EnumName<RouteShape>> enum_names(RouteShape) {
  return kRouteShapeNames;
}

struct ProceduralRouteConfig {
  RouteShape shape = RouteShape::kCircuit;  // circuit | waypoints
  std::string waypoints;          // shape "waypoints": "x0,y0; x1,y1; ..." in metres, at least 2 points
  double length_x_m = 90.0;       // circuit extent along x
  double length_y_m = 50.0;       // circuit extent along y
  double corner_radius_m = 14.0;  // radius of the four rounded corners
  int laps = 2;
  int frames = 600;  // poses generated, at rate_hz
  double rate_hz = 10.0;
  double camera_height_m = 1.65;
  double lap_lateral_offset_m = 0.6;  // lateral shift of lap k: k * offset (alternating sign)
  double speed_variation = 0.15;      // relative speed modulation amplitude (< 1)
  double speed_cycles_per_lap = 1.5;  // periods of the speed modulation per lap
  double heading_wobble_rad = 0.02;   // small steering wobble amplitude
  double heading_wobble_period_s = 7.0;
  std::int64_t start_t_ns = 0;
  // A revisit in another lane (sim/revisit.hpp): the poses that pass a street driven before (an earlier pose
  // within revisit_radius_m horizontally, with at least revisit_min_travel_m of path in between) are moved
  // this far to the left of the direction of travel (negative: to the right), with a smooth lane change over
  // revisit_lane_change_m of path before and after. 0 = off. The world and the ground-truth loops stay on
  // the route without this offset: the offset revisit keeps the same-lane revisit's loop pairs.
  double revisit_lateral_offset_m = 0.0;
  double revisit_radius_m = 3.0;
  double revisit_min_travel_m = 30.0;
  double revisit_lane_change_m = 30.0;

  // The keys, in order, for loading, printing and the JSON echo (Self is ProceduralRouteConfig or const
  // ProceduralRouteConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("shape", self.shape);
    v("waypoints", self.waypoints);
    v("length_x_m", self.length_x_m);
    v("length_y_m", self.length_y_m);
    v("corner_radius_m", self.corner_radius_m);
    v("laps", self.laps);
    v("frames", self.frames);
    v("rate_hz", self.rate_hz);
    v("camera_height_m", self.camera_height_m);
    v("lap_lateral_offset_m", self.lap_lateral_offset_m);
    v("speed_variation", self.speed_variation);
    v("speed_cycles_per_lap", self.speed_cycles_per_lap);
    v("heading_wobble_rad", self.heading_wobble_rad);
    v("heading_wobble_period_s", self.heading_wobble_period_s);
    v("start_t_ns", self.start_t_ns);
    v("revisit_lateral_offset_m", self.revisit_lateral_offset_m);
    v("revisit_radius_m", self.revisit_radius_m);
    v("revisit_min_travel_m", self.revisit_min_travel_m);
    v("revisit_lane_change_m", self.revisit_lane_change_m);
  }
  void validate() const;  // throws ConfigError
};

std::vector<StampedPose> make_procedural_route(const ProceduralRouteConfig& config);

// The points of a "waypoints" string ("x0,y0; x1,y1; ..."). Throws ConfigError naming route.waypoints and
// what was expected for a malformed list (a bad number, a point without two coordinates, fewer than 2).
std::vector<Eigen::Vector2d> parse_route_waypoints(const std::string& text);

}  // namespace loopgate::sim
