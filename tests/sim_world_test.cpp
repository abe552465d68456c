#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "core/error.hpp"
#include "sim/world.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

const Eigen::Vector3d kKittiUp(0.0, -1.0, 0.0);
const Eigen::Vector3d kEurocUp(0.0, 0.0, 1.0);

// A rectangular block (width x depth metres, rounded corners) driven `laps` times, in a KITTI-like world
// (x right, z forward, up = -y), one point per metre; plus a straight spur crossing the first side.
std::vector<Eigen::Vector3d> block_route(double width_m, double depth_m, int laps) {
  std::vector<Eigen::Vector3d> path;
  const double r = 10.0;
  for (int lap = 0; lap < laps; ++lap) {
    const double lap_len = 2.0 * (width_m + depth_m - 4.0 * r) + 2.0 * M_PI * r;
    for (double s = 0.0; s < lap_len; s += 1.0) {
      // Walk the rounded rectangle: straight, quarter circle, ...
      double rem = s;
      const double straights[4] = {depth_m - 2 * r, width_m - 2 * r, depth_m - 2 * r, width_m - 2 * r};
      Eigen::Vector2d p(0.0, r), dir(0.0, 1.0);
      for (int k = 0; k < 4; ++k) {
        const double seg = std::min(rem, straights[k]);
        p += dir * seg;
        rem -= seg;
        if (rem <= 0.0) break;
        const double arc = std::min(rem, 0.5 * M_PI * r);
        const double a = arc / r;
        const Eigen::Vector2d centre = p + Eigen::Vector2d(dir.y(), -dir.x()) * r;
        const Eigen::Vector2d rel = p - centre;
        p = centre + Eigen::Vector2d(rel.x() * std::cos(a) + rel.y() * std::sin(a),
                                     -rel.x() * std::sin(a) + rel.y() * std::cos(a));
        dir = Eigen::Vector2d(dir.x() * std::cos(a) + dir.y() * std::sin(a),
                              -dir.x() * std::sin(a) + dir.y() * std::cos(a));
        rem -= arc;
        if (rem <= 0.0) break;
      }
      path.emplace_back(p.x(), -0.02 * p.y(), p.y());  // gentle slope
    }
  }
  return path;
}

double horizontal_distance_to_quad_base(const Quad& q, const Eigen::Vector3d& p, const Eigen::Vector3d& up) {
  const Eigen::Vector3d a = q.origin_w.cast<double>();
  const Eigen::Vector3d b = a + q.axis_u_w.cast<double>() * q.width_m;
  const auto flat = [&](const Eigen::Vector3d& x) { return Eigen::Vector3d(x - up * up.dot(x)); };
  const Eigen::Vector3d fa = flat(a), fb = flat(b), fp = flat(p);
  const Eigen::Vector3d ab = fb - fa;
  const double t = std::clamp((fp - fa).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (fa + t * ab - fp).norm();
}

int count_kind(const World& w, const std::string& kind) {
  int n = 0;
  for (const Structure& s : w.structures) n += enum_name(s.kind) == kind ? 1 : 0;
  return n;
}

TEST(World, StreetFacadesKeepClearOfEveryPathPoint) {
  const auto path = block_route(120.0, 80.0, 1);
  WorldConfig config;
  const World world = build_world(config, path, kKittiUp);
  const int facades = count_kind(world, "facade");
  EXPECT_GT(facades, 25);  // ~400 m of street, both sides
  EXPECT_GT(count_kind(world, "ground"), 50);
  EXPECT_GT(count_kind(world, "marking"), 50);
  for (const Quad& q : world.quads) {
    if (world.structures[static_cast<std::size_t>(q.structure)].kind != StructureKind::kFacade) continue;
    // Vertical, and never within the clearance of any path point.
    EXPECT_NEAR(q.axis_v_w.cast<double>().dot(kKittiUp), 1.0, 1e-6);
    for (const Eigen::Vector3d& p : path) {
      ASSERT_GE(horizontal_distance_to_quad_base(q, p, kKittiUp), config.street_clearance_m - 1e-3);
    }
  }
  // Ground lies below the camera by about the camera height, right under the path.
  float t = 0, u = 0, v = 0;
  for (std::size_t k = 0; k < path.size(); k += 37) {
    const int hit = world.intersect(path[k].cast<float>(), -kKittiUp.cast<float>(), 0.0f, 100.0f, &t, &u, &v);
    ASSERT_GE(hit, 0);
    const StructureKind kind =
        world.structures[static_cast<std::size_t>(world.quads[static_cast<std::size_t>(hit)].structure)].kind;
    EXPECT_TRUE(kind == StructureKind::kGround || kind == StructureKind::kMarking) << enum_name(kind);
    EXPECT_NEAR(t, config.street_camera_height_m, 0.3);
  }
}

TEST(World, RevisitsReuseTheSameFacades) {
  WorldConfig config;
  const World once = build_world(config, block_route(120.0, 80.0, 1), kKittiUp);
  const World twice = build_world(config, block_route(120.0, 80.0, 2), kKittiUp);
  // The second lap adds (almost) nothing: at most a few pieces where the lap closes on itself.
  EXPECT_LE(count_kind(twice, "facade"), count_kind(once, "facade") + 3);
  EXPECT_GE(count_kind(twice, "facade"), count_kind(once, "facade"));
  EXPECT_LE(count_kind(twice, "marking"), count_kind(once, "marking") + 4);
  EXPECT_EQ(count_kind(once, "ground"), count_kind(twice, "ground"));
}

TEST(World, AliasingKnobReusesTheRequestedFractionOfSeeds) {
  const auto path = block_route(160.0, 120.0, 1);
  for (double fraction : {0.0, 0.1, 0.25}) {
    WorldConfig config;
    config.aliasing_fraction = fraction;
    const World world = build_world(config, path, kKittiUp);
    const int aliasable = world.aliasable_structure_count();
    ASSERT_GT(aliasable, 20);
    EXPECT_EQ(world.aliased_structure_count(), static_cast<int>(std::lround(fraction * aliasable)))
        << fraction;
    for (const Structure& s : world.structures) {
      if (s.aliased_from < 0) continue;
      const Structure& src = world.structures[static_cast<std::size_t>(s.aliased_from)];
      EXPECT_EQ(s.texture_seed, src.texture_seed);
      EXPECT_EQ(s.texture, src.texture);
      EXPECT_EQ(s.kind, src.kind);
      EXPECT_LT(src.aliased_from, 0);
    }
  }
}

// Horizontal centre of a structure's first quad (EuRoC up = +z: x, y).
Eigen::Vector2d structure_centre_xy(const World& world, int structure) {
  for (const Quad& q : world.quads) {
    if (q.structure != structure) continue;
    const Eigen::Vector3f c = q.origin_w + 0.5f * q.width_m * q.axis_u_w + 0.5f * q.height_m * q.axis_v_w;
    return Eigen::Vector2d(c.x(), c.y());
  }
  return Eigen::Vector2d(NAN, NAN);
}

// Height of the (vertical) facade quad of a structure.
float facade_height(const World& world, int structure) {
  for (const Quad& q : world.quads) {
    if (q.structure == structure) return q.height_m;
  }
  return -1.0f;
}

TEST(World, PlaceCopyGivesTheTargetPlaceTheSourcePlaceTextures) {
  // A straight street along +x (EuRoC up), 300 m, one point per metre. Copy the place around x = 60 to the
  // place around x = 220, rotated by 0 (rotation 180 is what the aliasing preset uses: see
  // sim_simulator_test).
  std::vector<Eigen::Vector3d> path;
  for (int k = 0; k <= 300; ++k) path.emplace_back(k, 0.0, 1.65);
  WorldConfig config;
  config.street_facade_offset_jitter_m = 0.0;
  const World plain = build_world(config, path, kEurocUp);
  EXPECT_EQ(plain.aliased_structure_count(), 0);
  EXPECT_EQ(plain.copied_structure_count(), 0);
  config.alias_copy_radius_m = 25.0;
  config.alias_copy_source_x_m = 60.0;
  config.alias_copy_target_x_m = 220.0;
  const World world = build_world(config, path, kEurocUp);
  ASSERT_EQ(world.structures.size(), plain.structures.size());
  int in_target = 0;
  for (std::size_t k = 0; k < world.structures.size(); ++k) {
    const Structure& s = world.structures[k];
    const Eigen::Vector2d c = structure_centre_xy(world, static_cast<int>(k));
    const bool target = s.kind == StructureKind::kFacade && (c - Eigen::Vector2d(220.0, 0.0)).norm() <= 25.0;
    in_target += target ? 1 : 0;
    EXPECT_EQ(s.copied, target) << "structure " << k << " at " << c.transpose();
    if (!s.copied) {
      // Everything else is untouched.
      EXPECT_EQ(s.texture_seed, plain.structures[k].texture_seed);
      continue;
    }
    ASSERT_GE(s.aliased_from, 0);
    const Structure& src = world.structures[static_cast<std::size_t>(s.aliased_from)];
    EXPECT_FALSE(src.copied);
    EXPECT_EQ(s.texture_seed, src.texture_seed);
    EXPECT_EQ(s.style, src.style);
    EXPECT_EQ(s.texture, src.texture);
    EXPECT_EQ(facade_height(world, static_cast<int>(k)), facade_height(world, s.aliased_from));
    // The source stands where the target stands, 160 m back (within the facade pitch's phase).
    const Eigen::Vector2d src_c = structure_centre_xy(world, s.aliased_from);
    EXPECT_LE((src_c + Eigen::Vector2d(160.0, 0.0) - c).norm(), config.alias_copy_tolerance_m);
  }
  EXPECT_GE(in_target, 6);  // ~50 m of street, both sides
  EXPECT_EQ(world.copied_structure_count(), in_target);
  EXPECT_EQ(world.aliased_structure_count(), in_target);

  config.alias_copy_radius_m = -1.0;
  EXPECT_THROW(config.validate(), ConfigError);
  config.alias_copy_radius_m = 25.0;
  config.alias_copy_tolerance_m = 0.0;
  EXPECT_THROW(config.validate(), ConfigError);
}

TEST(World, BuildIsDeterministicAndSeedDependent) {
  const auto path = block_route(100.0, 60.0, 1);
  WorldConfig config;
  config.aliasing_fraction = 0.2;
  const World a = build_world(config, path, kKittiUp);
  const World b = build_world(config, path, kKittiUp);
  ASSERT_EQ(a.quads.size(), b.quads.size());
  ASSERT_EQ(a.textures.size(), b.textures.size());
  for (std::size_t k = 0; k < a.quads.size(); ++k) {
    ASSERT_EQ(a.quads[k].origin_w, b.quads[k].origin_w);
    ASSERT_EQ(a.quads[k].texture, b.quads[k].texture);
  }
  std::uint64_t sum_a = 0, sum_b = 0;
  for (std::size_t k = 0; k < a.textures.size(); ++k) {
    for (int v = 0; v < a.textures[k].height_px(); v += 3) {
      for (int u = 0; u < a.textures[k].width_px(); u += 3) {
        sum_a = sum_a * 31 + a.textures[k].texel(u, v);
        sum_b = sum_b * 31 + b.textures[k].texel(u, v);
      }
    }
  }
  EXPECT_EQ(sum_a, sum_b);
  config.seed = 2;
  const World c = build_world(config, path, kKittiUp);
  bool differs = c.quads.size() != a.quads.size();
  for (std::size_t k = 0; !differs && k < a.textures.size() && k < c.textures.size(); ++k) {
    differs = a.textures[k].width_px() != c.textures[k].width_px() ||
              a.textures[k].texel(5, 5) != c.textures[k].texel(5, 5);
  }
  EXPECT_TRUE(differs);
}

TEST(World, HallEnclosesThePathWithClearObstacles) {
  // A lawnmower flight in an EuRoC-like world (z up).
  std::vector<Eigen::Vector3d> path;
  for (int k = 0; k < 400; ++k) {
    const double s = k * 0.05;
    path.emplace_back(8.0 * std::sin(0.3 * s), 5.0 * std::sin(0.5 * s), 1.0 + 0.5 * std::sin(0.7 * s));
  }
  WorldConfig config;
  config.kind = sim::WorldKind::kHall;
  config.aliasing_fraction = 0.1;
  const World world = build_world(config, path, kEurocUp);
  EXPECT_GT(count_kind(world, "wall"), 8);
  EXPECT_GT(count_kind(world, "pillar"), 0);
  EXPECT_GT(count_kind(world, "crate"), 0);
  EXPECT_GT(count_kind(world, "floor"), 0);
  EXPECT_GT(count_kind(world, "ceiling"), 0);
  // Enclosed: from every few path points, rays in many directions all hit something within the room.
  float t = 0, u = 0, v = 0;
  for (std::size_t k = 0; k < path.size(); k += 40) {
    for (int d = 0; d < 26; ++d) {
      const Eigen::Vector3f dir(std::cos(d * 0.7f) * std::sin(d * 0.37f + 0.2f),
                                std::sin(d * 0.7f) * std::sin(d * 0.37f + 0.2f), std::cos(d * 0.37f + 0.2f));
      ASSERT_GE(world.intersect(path[k].cast<float>(), dir.normalized(), 0.0f, 1000.0f, &t, &u, &v), 0);
      EXPECT_LT(t, 40.0f);
    }
  }
  for (const Quad& q : world.quads) {
    const StructureKind kind = world.structures[static_cast<std::size_t>(q.structure)].kind;
    if (kind != StructureKind::kPillar && kind != StructureKind::kCrate) continue;
    for (const Eigen::Vector3d& p : path) {
      ASSERT_GE(horizontal_distance_to_quad_base(q, p, kEurocUp), config.hall_clearance_m - 1e-3);
    }
  }
}

// Rays straight down from points within 12 m of a straight 400 m street through the origin (the ground
// reaches 16 m from the path) that hit nothing.
int ground_holes(const WorldConfig& config) {
  std::vector<Eigen::Vector3d> path;
  for (int k = -200; k <= 200; ++k) path.emplace_back(0.0, 0.0, k);  // KITTI-like: up = -y, along z
  const World world = build_world(config, path, kKittiUp);
  int holes = 0;
  for (int k = -195; k <= 195; k += 3) {
    for (double lateral = -12.0; lateral <= 12.0; lateral += 2.0) {
      float t = 0, u = 0, v = 0;
      const int quad =
          world.intersect(Eigen::Vector3f(static_cast<float>(lateral), 0.0f, static_cast<float>(k)),
                          Eigen::Vector3f::UnitY(), 0.0f, 100.0f, &t, &u, &v);
      holes += quad < 0 ? 1 : 0;  // (a ray may hit a road marking first)
    }
  }
  return holes;
}

TEST(World, ExactGroundCellsLeaveNoHoles) {
  // The legacy cell keys collide for cells such as (1, -24) and (-1, 22): one of them is missing.
  WorldConfig config;
  config.street_facade_offset_jitter_m = 0.0;
  EXPECT_GT(ground_holes(config), 0) << "the legacy keys (kept by default for the first presets' bytes)";
  config.street_ground_exact_cells = true;
  EXPECT_EQ(ground_holes(config), 0);
}

TEST(World, RejectsBadConfigAndInput) {
  WorldConfig config;
  config.aliasing_fraction = 0.9;
  EXPECT_THROW(config.validate(), ConfigError);
  EXPECT_THROW(build_world(WorldConfig{}, {}, kKittiUp), DataError);
  EXPECT_THROW(build_world(WorldConfig{}, {Eigen::Vector3d(NAN, 0, 0)}, kKittiUp), DataError);
}

TEST(World, Kitti00StreetKeepsClearOfTheWholeRoute) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/poses.txt");
  std::ifstream in(loopgate::testing::shared_data_dir() / "kitti/00/poses.txt");
  std::vector<Eigen::Vector3d> path;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    double m[12];
    for (double& x : m) ss >> x;
    path.emplace_back(m[3], m[7], m[11]);
  }
  ASSERT_EQ(path.size(), 4541u);
  WorldConfig config;
  config.aliasing_fraction = 0.1;
  const World world = build_world(config, path, kKittiUp);
  EXPECT_GT(count_kind(world, "facade"), 300);
  EXPECT_NEAR(static_cast<double>(world.aliased_structure_count()) / world.aliasable_structure_count(), 0.1,
              0.01);
  for (const Quad& q : world.quads) {
    if (world.structures[static_cast<std::size_t>(q.structure)].kind != StructureKind::kFacade) continue;
    for (const Eigen::Vector3d& p : path) {
      ASSERT_GE(horizontal_distance_to_quad_base(q, p, kKittiUp), config.street_clearance_m - 1e-3);
    }
  }
}

}  // namespace
}  // namespace loopgate::sim
