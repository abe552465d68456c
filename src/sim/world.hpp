// The procedural world the simulator renders: textured planar quads around a trajectory, with an
// acceleration structure (BVH). Built once, immutable, shareable across threads.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "sim/texture.hpp"

namespace loopgate::sim {

// world.kind: a street (facades along the route) or a hall (walls, pillars, crates under a ceiling).
enum class WorldKind { kStreet, kHall };
inline constexpr EnumName<WorldKind> kWorldKindNames[] = {{WorldKind::kStreet, "street"},
                                                          {WorldKind::kHall, "hall"}};
constexpr std::span<const EnumName<WorldKind>> enum_names(WorldKind) {
  return kWorldKindNames;
}

struct WorldConfig {
  WorldKind kind = WorldKind::kStreet;  // street | hall
  std::int64_t seed = 1;
  double aliasing_fraction = 0.0;  // fraction of structures that reuse another structure's texture seed
  // Deterministic aliasing (a "copied place"): every structure except the ground and the road markings
  // (facades, posts, hall walls / floor / ceiling tiles, pillars, crates) whose centre lies within
  // alias_copy_radius_m (horizontally) of the target place takes the texture seed, style and height of the
  // structure of the same kind and width nearest to the corresponding position around the source place
  // (target = source rotated by alias_copy_rotation_deg about up, then moved to the target centre), if one
  // lies within alias_copy_tolerance_m of it. Structures the random knob already aliased are left alone.
  // Centres are horizontal world coordinates: x, y for up = +z (EuRoC); x, z for up = -y (KITTI).
  // alias_copy_radius_m = 0: off.
  double alias_copy_radius_m = 0.0;
  double alias_copy_source_x_m = 0.0;
  double alias_copy_source_y_m = 0.0;
  double alias_copy_target_x_m = 0.0;
  double alias_copy_target_y_m = 0.0;
  double alias_copy_rotation_deg = 0.0;
  double alias_copy_tolerance_m = 6.0;

  // street
  double street_facade_offset_m = 8.0;         // lateral distance of facades from the path
  double street_facade_offset_jitter_m = 1.5;  // random setback added per facade (0..jitter)
  double street_clearance_m = 4.5;             // no facade closer than this to ANY path point
  double street_facade_length_m = 12.0;        // facade width along the path
  double street_facade_gap_m = 0.6;            // gap between consecutive facades
  double street_facade_min_height_m = 6.0;
  double street_facade_max_height_m = 22.0;
  double street_camera_height_m = 1.65;    // ground lies this far below the path
  double street_edge_line_offset_m = 5.5;  // solid edge lines this far left and right of the path
  double street_ground_tile_m = 8.0;       // ground cells (two triangles each) of this size
  double street_facade_texels_per_m = 24.0;
  double street_road_texels_per_m = 48.0;
  // Key the ground cells exactly. false: the historical keys, under which some cells of a large map collide
  // and are missing from the ground (the distant ground shows through: nearly invisible by day, black holes
  // under the lamps night model, for which plan_simulation() therefore always sets this).
  bool street_ground_exact_cells = false;
  double street_pole_spacing_m = 25.0;  // lamp/sign posts along the kerb, alternating sides (0 = none)
  double street_pole_offset_m = 6.5;    // lateral distance of posts from the path (>= street_clearance_m)
  double street_pole_height_m = 6.0;
  double street_pole_width_m = 0.25;

  // hall
  double hall_margin_m = 4.0;         // horizontal distance from the path bounding box to the walls
  double hall_floor_below_m = 1.5;    // floor this far below the lowest path point (at least)
  double hall_ceiling_above_m = 3.0;  // ceiling this far above the highest path point (at least)
  double hall_wall_panel_m = 4.0;     // walls are split into panels (structures) of this width
  int hall_pillar_count = 8;
  int hall_crate_count = 14;
  double hall_clearance_m = 1.2;  // pillars and crates keep this distance from every path point
  double hall_texels_per_m = 64.0;

  // The keys, in order, for loading, printing and the JSON echo (Self is WorldConfig or const WorldConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("kind", self.kind);
    v("seed", self.seed);
    v("aliasing_fraction", self.aliasing_fraction);
    v("alias_copy_radius_m", self.alias_copy_radius_m);
    v("alias_copy_source_x_m", self.alias_copy_source_x_m);
    v("alias_copy_source_y_m", self.alias_copy_source_y_m);
    v("alias_copy_target_x_m", self.alias_copy_target_x_m);
    v("alias_copy_target_y_m", self.alias_copy_target_y_m);
    v("alias_copy_rotation_deg", self.alias_copy_rotation_deg);
    v("alias_copy_tolerance_m", self.alias_copy_tolerance_m);
    v("street_facade_offset_m", self.street_facade_offset_m);
    v("street_facade_offset_jitter_m", self.street_facade_offset_jitter_m);
    v("street_clearance_m", self.street_clearance_m);
    v("street_facade_length_m", self.street_facade_length_m);
    v("street_facade_gap_m", self.street_facade_gap_m);
    v("street_facade_min_height_m", self.street_facade_min_height_m);
    v("street_facade_max_height_m", self.street_facade_max_height_m);
    v("street_camera_height_m", self.street_camera_height_m);
    v("street_edge_line_offset_m", self.street_edge_line_offset_m);
    v("street_ground_tile_m", self.street_ground_tile_m);
    v("street_facade_texels_per_m", self.street_facade_texels_per_m);
    v("street_road_texels_per_m", self.street_road_texels_per_m);
    v("street_ground_exact_cells", self.street_ground_exact_cells);
    v("street_pole_spacing_m", self.street_pole_spacing_m);
    v("street_pole_offset_m", self.street_pole_offset_m);
    v("street_pole_height_m", self.street_pole_height_m);
    v("street_pole_width_m", self.street_pole_width_m);
    v("hall_margin_m", self.hall_margin_m);
    v("hall_floor_below_m", self.hall_floor_below_m);
    v("hall_ceiling_above_m", self.hall_ceiling_above_m);
    v("hall_wall_panel_m", self.hall_wall_panel_m);
    v("hall_pillar_count", self.hall_pillar_count);
    v("hall_crate_count", self.hall_crate_count);
    v("hall_clearance_m", self.hall_clearance_m);
    v("hall_texels_per_m", self.hall_texels_per_m);
  }
  // Throws loopgate::ConfigError naming the key and the allowed values / range.
  void validate() const;
};

// A textured planar patch: a parallelogram origin_w + a * edge_u + b * edge_v (a in [0, width_m], b in
// [0, height_m], edges along axis_u_w / axis_v_w), or the triangle half of it where a / width_m + b /
// height_m <= 1. The hit point p gives (a, b) = ((p - origin_w) . dual_u_w, (p - origin_w) . dual_v_w); for a
// rectangle the duals are the axes. Texture coordinates (texels) = (u_offset_tx + u_sign * a * texels_per_m,
// v_offset_tx + v_sign * b * texels_per_m).
struct Quad {
  Eigen::Vector3f origin_w = Eigen::Vector3f::Zero();
  Eigen::Vector3f axis_u_w = Eigen::Vector3f::UnitX();  // unit edge direction
  Eigen::Vector3f axis_v_w = Eigen::Vector3f::UnitY();  // unit edge direction
  Eigen::Vector3f normal_w = Eigen::Vector3f::UnitZ();  // unit, axis_u_w x axis_v_w
  Eigen::Vector3f dual_u_w = Eigen::Vector3f::UnitX();
  Eigen::Vector3f dual_v_w = Eigen::Vector3f::UnitY();
  float width_m = 1.0f;
  float height_m = 1.0f;
  bool triangle = false;
  float texels_per_m = 32.0f;
  float u_sign = 1.0f;
  float v_sign = 1.0f;
  float u_offset_tx = 0.0f;
  float v_offset_tx = 0.0f;
  int texture = 0;     // index into World::textures
  int structure = -1;  // index into World::structures
};

// What a structure of the world is (street: facades, ground strips, road markings, lamp posts; hall: wall
// panels, floor and ceiling tiles, pillars, crates); named in logs and in the world's metadata.
enum class StructureKind { kFacade, kGround, kMarking, kPole, kWall, kFloor, kCeiling, kPillar, kCrate };
inline constexpr EnumName<StructureKind> kStructureKindNames[] = {
    {StructureKind::kFacade, "facade"},   {StructureKind::kGround, "ground"},
    {StructureKind::kMarking, "marking"}, {StructureKind::kPole, "pole"},
    {StructureKind::kWall, "wall"},       {StructureKind::kFloor, "floor"},
    {StructureKind::kCeiling, "ceiling"}, {StructureKind::kPillar, "pillar"},
    {StructureKind::kCrate, "crate"}};
constexpr std::span<const EnumName<StructureKind>> enum_names(StructureKind) {
  return kStructureKindNames;
}

// A building / wall panel / pillar / crate / ground strip: one texture (from texture_seed) shared by its
// quads.
struct Structure {
  StructureKind kind = StructureKind::kFacade;
  TextureStyle style = TextureStyle::kFacadeWindows;
  std::uint64_t texture_seed = 0;
  int aliased_from = -1;  // index of the structure whose texture seed this one reuses, -1 if own
  int texture = 0;        // index into World::textures
  bool aliasable = true;  // ground strips are excluded from the aliasing knob
  bool copied = false;    // aliased by the deterministic place copy (WorldConfig alias_copy_*)
};

// Flattened BVH node: leaf when count > 0 (quads quad_index[first .. first + count)), else children
// at left_or_first and left_or_first + 1.
struct BvhNode {
  float min[3] = {0, 0, 0};
  float max[3] = {0, 0, 0};
  int left_or_first = 0;
  int count = 0;
};

struct World {
  WorldConfig config;
  WorldKind kind = WorldKind::kStreet;
  Eigen::Vector3d up_w = Eigen::Vector3d::UnitZ();
  std::vector<Quad> quads;
  std::vector<Structure> structures;
  std::vector<Texture> textures;
  std::vector<BvhNode> bvh_nodes;
  std::vector<int> bvh_quad_index;

  // Closest hit along origin + t * dir (dir need not be unit) with t in (t_min, t_max).
  // Returns the quad index or -1; *t_hit and the hit texture coordinates (texels) when hit.
  int intersect(const Eigen::Vector3f& origin_w, const Eigen::Vector3f& dir_w, float t_min, float t_max,
                float* t_hit, float* u_tx, float* v_tx) const;
  // Number of structures whose texture seed is borrowed from another structure (aliasing knob).
  int aliased_structure_count() const;
  // Of those, the ones copied by the deterministic alias_copy_* place copy.
  int copied_structure_count() const;
  int aliasable_structure_count() const;
};

// (Re)builds world->bvh_nodes / bvh_quad_index from world->quads (for worlds assembled by hand, e.g. tests).
void rebuild_acceleration(World* world);

// path_w: camera positions along the trajectory (corridor / room extent and clearance);
// up_w: world "up" unit vector (KITTI camera world: -y; EuRoC world: +z). Throws ConfigError for a bad
// config and DataError (file "<path>") for an empty path.
World build_world(const WorldConfig& config, const std::vector<Eigen::Vector3d>& path_w,
                  const Eigen::Vector3d& up_w);

}  // namespace loopgate::sim
