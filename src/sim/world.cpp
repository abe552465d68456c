#include "sim/world.hpp"

#include <spdlog/spdlog.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <unordered_map>

#include "core/error.hpp"
#include "sim/render_bvh.hpp"
#include "sim/render_random.hpp"

namespace loopgate::sim {
namespace {

using render_detail::hash_combine;
using render_detail::Rng;

// Fixed layout constants of the street (visual design, not tuning knobs of an algorithm).
constexpr double kFacadeBelowGroundM = 1.0;    // facades reach below the local ground (slopes)
constexpr double kGroundFitRadiusM = 18.0;     // path points averaged into a ground vertex height
constexpr double kGroundFitSigmaM = 5.0;       // fall-off of the path-height weights
constexpr double kGroundBeyondFacadesM = 8.0;  // ground extends this far beyond the facade line
constexpr double kRoadTextureM = 16.0;         // road texture tile (wraps)
constexpr int kRoadTextureVariants = 3;
constexpr double kMarkingLiftM = 0.05;  // paint floats above the asphalt
constexpr double kDashLengthM = 3.0;
constexpr double kDashPeriodM = 7.0;
constexpr double kEdgeLineLengthM = 6.0;
constexpr double kMarkingWidthM = 0.15;
constexpr double kMarkingTextureLengthM = 8.0;
constexpr double kFacadeDedupLateralM = 3.0;
constexpr double kMinPathStepM = 1e-3;
constexpr double kAliasMinDistanceFraction = 0.5;  // alias sources come from the farther half

struct Frame {
  Eigen::Vector3d up, e1, e2;
  Eigen::Vector3d to_world(double x, double y, double z) const { return e1 * x + e2 * y + up * z; }
};

Frame make_frame(const Eigen::Vector3d& up_w) {
  Frame f;
  f.up = up_w.normalized();
  int best = 0;
  for (int k = 1; k < 3; ++k) {
    if (std::abs(f.up[k]) < std::abs(f.up[best])) best = k;
  }
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();
  axis[best] = 1.0;
  f.e1 = (axis - f.up * f.up.dot(axis)).normalized();
  f.e2 = f.up.cross(f.e1);
  return f;
}

// Uniform 2D grid over points (horizontal coordinates) for clearance queries.
class PointGrid {
 public:
  explicit PointGrid(double cell_m) : cell_m_(cell_m) {}
  void add(const Eigen::Vector2d& p) {
    cells_[key(cell_of(p.x()), cell_of(p.y()))].push_back(static_cast<int>(points_.size()));
    points_.push_back(p);
  }
  // Minimum distance from segment ab to any point, looking only within `radius` (returns >= radius if none).
  double min_distance_to_segment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double radius) const {
    double best = std::numeric_limits<double>::infinity();
    const Eigen::Vector2d lo = a.cwiseMin(b).array() - radius;
    const Eigen::Vector2d hi = a.cwiseMax(b).array() + radius;
    const Eigen::Vector2d ab = b - a;
    const double len2 = std::max(ab.squaredNorm(), 1e-12);
    for (long long cx = cell_of(lo.x()); cx <= cell_of(hi.x()); ++cx) {
      for (long long cy = cell_of(lo.y()); cy <= cell_of(hi.y()); ++cy) {
        const auto it = cells_.find(key(cx, cy));
        if (it == cells_.end()) continue;
        for (int idx : it->second) {
          const Eigen::Vector2d& p = points_[static_cast<std::size_t>(idx)];
          const double t = std::clamp((p - a).dot(ab) / len2, 0.0, 1.0);
          best = std::min(best, (a + t * ab - p).norm());
        }
      }
    }
    return best;
  }
  template <class F>
  void for_each_within(const Eigen::Vector2d& c, double radius, F&& f) const {
    for (long long cx = cell_of(c.x() - radius); cx <= cell_of(c.x() + radius); ++cx) {
      for (long long cy = cell_of(c.y() - radius); cy <= cell_of(c.y() + radius); ++cy) {
        const auto it = cells_.find(key(cx, cy));
        if (it == cells_.end()) continue;
        for (int idx : it->second) {
          if ((points_[static_cast<std::size_t>(idx)] - c).norm() <= radius) f(idx);
        }
      }
    }
  }
  const Eigen::Vector2d& point(int idx) const { return points_[static_cast<std::size_t>(idx)]; }

 private:
  long long cell_of(double v) const { return static_cast<long long>(std::floor(v / cell_m_)); }
  static std::uint64_t key(long long cx, long long cy) {
    return (static_cast<std::uint64_t>(cx) * 0x9E3779B97F4A7C15ull) ^ static_cast<std::uint64_t>(cy);
  }
  double cell_m_;
  std::vector<Eigen::Vector2d> points_;
  std::unordered_map<std::uint64_t, std::vector<int>> cells_;
};

// Horizontal polyline of the path with arc length, for sampling positions and heights.
struct PathCurve {
  std::vector<Eigen::Vector2d> xy;
  std::vector<double> z;
  std::vector<double> s;
  double length() const { return s.empty() ? 0.0 : s.back(); }
  void sample(double at, Eigen::Vector2d* p, double* height) const {
    if (xy.size() == 1) {
      *p = xy[0];
      *height = z[0];
      return;
    }
    at = std::clamp(at, 0.0, length());
    const auto it = std::upper_bound(s.begin(), s.end(), at);
    std::size_t i = static_cast<std::size_t>(std::max<std::ptrdiff_t>(1, it - s.begin()));
    i = std::min(i, s.size() - 1);
    const double span = s[i] - s[i - 1];
    const double t = span > 0 ? (at - s[i - 1]) / span : 0.0;
    *p = xy[i - 1] + t * (xy[i] - xy[i - 1]);
    *height = z[i - 1] + t * (z[i] - z[i - 1]);
  }
};

// What build_world collects before textures are made.
struct PendingStructure {
  Structure info;
  double width_m = 0;
  double height_m = 0;
  Eigen::Vector3d center_w = Eigen::Vector3d::Zero();
  std::vector<int> quads;
};

struct Builder {
  const WorldConfig& config;
  Frame frame;
  World world;
  std::vector<PendingStructure> pending;

  int add_structure(StructureKind kind, TextureStyle style, std::uint64_t seed, double width_m,
                    double height_m, const Eigen::Vector3d& center_w, bool aliasable) {
    PendingStructure s;
    s.info.kind = kind;
    s.info.style = style;
    s.info.texture_seed = seed;
    s.info.aliasable = aliasable;
    s.width_m = width_m;
    s.height_m = height_m;
    s.center_w = center_w;
    pending.push_back(std::move(s));
    return static_cast<int>(pending.size()) - 1;
  }

  // Parallelogram (or its triangle half) origin + a / |edge_u| * edge_u + b / |edge_v| * edge_v.
  int add_patch(int structure, const Eigen::Vector3d& origin, const Eigen::Vector3d& edge_u,
                const Eigen::Vector3d& edge_v, bool triangle, double texels_per_m, double u_offset_tx,
                double v_offset_tx, double u_sign = 1.0, double v_sign = 1.0) {
    Quad q;
    const double width = edge_u.norm(), height = edge_v.norm();
    Eigen::Matrix2d gram;
    gram << edge_u.dot(edge_u), edge_u.dot(edge_v), edge_v.dot(edge_u), edge_v.dot(edge_v);
    const Eigen::Matrix2d inv = gram.inverse();
    q.origin_w = origin.cast<float>();
    q.axis_u_w = (edge_u / width).cast<float>();
    q.axis_v_w = (edge_v / height).cast<float>();
    q.normal_w = edge_u.cross(edge_v).normalized().cast<float>();
    q.dual_u_w = (width * (inv(0, 0) * edge_u + inv(0, 1) * edge_v)).cast<float>();
    q.dual_v_w = (height * (inv(1, 0) * edge_u + inv(1, 1) * edge_v)).cast<float>();
    q.width_m = static_cast<float>(width);
    q.height_m = static_cast<float>(height);
    q.triangle = triangle;
    q.texels_per_m = static_cast<float>(texels_per_m);
    q.u_sign = static_cast<float>(u_sign);
    q.v_sign = static_cast<float>(v_sign);
    q.u_offset_tx = static_cast<float>(u_offset_tx);
    q.v_offset_tx = static_cast<float>(v_offset_tx);
    q.structure = structure;
    world.quads.push_back(q);
    const int idx = static_cast<int>(world.quads.size()) - 1;
    if (structure >= 0) pending[static_cast<std::size_t>(structure)].quads.push_back(idx);
    return idx;
  }
  // Rectangle from origin along directions u, v (made orthonormal).
  int add_quad(int structure, const Eigen::Vector3d& origin, const Eigen::Vector3d& u,
               const Eigen::Vector3d& v, double width_m, double height_m, double texels_per_m,
               double u_offset_tx, double v_offset_tx) {
    const Eigen::Vector3d un = u.normalized();
    const Eigen::Vector3d vn = (v - un * un.dot(v)).normalized();
    return add_patch(structure, origin, un * width_m, vn * height_m, false, texels_per_m, u_offset_tx,
                     v_offset_tx);
  }
};

PathCurve make_curve(const std::vector<Eigen::Vector3d>& path_w, const Frame& f) {
  PathCurve c;
  for (const Eigen::Vector3d& p : path_w) {
    const Eigen::Vector2d xy(p.dot(f.e1), p.dot(f.e2));
    const double z = p.dot(f.up);
    if (!c.xy.empty() && (xy - c.xy.back()).norm() < kMinPathStepM) continue;
    c.s.push_back(c.xy.empty() ? 0.0 : c.s.back() + (xy - c.xy.back()).norm());
    c.xy.push_back(xy);
    c.z.push_back(z);
  }
  return c;
}

// ----------------------------------------------------------------------------------------------- street

struct PlacedFacade {
  Eigen::Vector2d a, b, normal;  // normal towards the road
};

// The street's ground: world-aligned grid cells near the path, each two triangles over vertex heights fitted
// to the path (so neighbouring cells share their edges exactly: no cracks).
class StreetGround {
 public:
  StreetGround(const WorldConfig& cfg, const PathCurve& curve, const PointGrid& path_grid)
      : cfg_(cfg), curve_(curve), path_grid_(path_grid) {
    const double ground_reach_m =
        cfg.street_facade_offset_m + cfg.street_facade_offset_jitter_m + kGroundBeyondFacadesM;
    const double tile_m = cfg.street_ground_tile_m;
    for (const Eigen::Vector2d& p : curve.xy) {
      const long long r = static_cast<long long>(std::ceil(ground_reach_m / tile_m));
      const long long px = static_cast<long long>(std::floor(p.x() / tile_m));
      const long long py = static_cast<long long>(std::floor(p.y() / tile_m));
      for (long long ix = px - r; ix <= px + r; ++ix) {
        for (long long iy = py - r; iy <= py + r; ++iy) {
          const double cx = (ix + 0.5) * tile_m, cy = (iy + 0.5) * tile_m;
          const double dx = std::max(0.0, std::abs(p.x() - cx) - 0.5 * tile_m);
          const double dy = std::max(0.0, std::abs(p.y() - cy) - 0.5 * tile_m);
          if (std::hypot(dx, dy) > ground_reach_m) continue;
          if (cell_set_.emplace(cell_key(ix, iy), 1).second) cells_.emplace_back(ix, iy);
        }
      }
    }
    std::sort(cells_.begin(), cells_.end());
  }

  // The historical key of a cell (its texture seed): different cells can share it, e.g. (1, -24) and
  // (-1, 22). As the key of the cell set and the vertex heights it drops such cells from the ground (holes
  // through which the distant ground shows) and gives their vertices one height; street_ground_exact_cells
  // keys those by the cell itself (the legacy keys stay the default: they are what the first presets render).
  static std::uint64_t seed_key(long long ix, long long iy) {
    return (static_cast<std::uint64_t>(ix) * 0x9E3779B97F4A7C15ull) ^ static_cast<std::uint64_t>(iy);
  }

  // The cells near the path, sorted.
  const std::vector<std::pair<long long, long long>>& cells() const { return cells_; }

  // Height of grid vertex (ix, iy) below the camera path; remembered by cell key (the first asked fixes it).
  double vertex_height(long long ix, long long iy) {
    const auto found = vertex_heights_.find(cell_key(ix, iy));
    if (found != vertex_heights_.end()) return found->second;
    const Eigen::Vector2d c(ix * cfg_.street_ground_tile_m, iy * cfg_.street_ground_tile_m);
    // Weighted mean of the nearby path heights (no extrapolated slopes away from the road).
    double sum_w = 0.0, sum_wz = 0.0;
    double radius = kGroundFitRadiusM;
    while (sum_w == 0.0) {
      path_grid_.for_each_within(c, radius, [&](int idx) {
        const Eigen::Vector2d& p = path_grid_.point(idx);
        const double w = 1.0 / (1.0 + (p - c).squaredNorm() / (kGroundFitSigmaM * kGroundFitSigmaM));
        sum_w += w;
        sum_wz += w * (curve_.z[static_cast<std::size_t>(idx)] - cfg_.street_camera_height_m);
      });
      radius *= 2.0;
    }
    const double h = sum_wz / sum_w;
    vertex_heights_.emplace(cell_key(ix, iy), h);
    return h;
  }

  // Ground height at horizontal position p (fallback outside the ground cells).
  double height(const Eigen::Vector2d& p, double fallback) {
    const double tile_m = cfg_.street_ground_tile_m;
    const long long ix = static_cast<long long>(std::floor(p.x() / tile_m));
    const long long iy = static_cast<long long>(std::floor(p.y() / tile_m));
    if (cell_set_.find(cell_key(ix, iy)) == cell_set_.end()) return fallback;
    const double fx = p.x() / tile_m - ix, fy = p.y() / tile_m - iy;
    const double h00 = vertex_height(ix, iy), h10 = vertex_height(ix + 1, iy);
    const double h01 = vertex_height(ix, iy + 1), h11 = vertex_height(ix + 1, iy + 1);
    if (fx + fy <= 1.0) return h00 + fx * (h10 - h00) + fy * (h01 - h00);
    return h11 + (1.0 - fx) * (h01 - h11) + (1.0 - fy) * (h10 - h11);
  }

 private:
  std::uint64_t cell_key(long long ix, long long iy) const {
    if (!cfg_.street_ground_exact_cells) return seed_key(ix, iy);
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(ix)) << 32) |
           static_cast<std::uint64_t>(static_cast<std::uint32_t>(iy));
  }

  const WorldConfig& cfg_;
  const PathCurve& curve_;
  const PointGrid& path_grid_;
  std::unordered_map<std::uint64_t, char> cell_set_;
  std::vector<std::pair<long long, long long>> cells_;
  std::unordered_map<std::uint64_t, double> vertex_heights_;
};

// The street's building site: the path, its clearance grid and the ground.
struct StreetSite {
  const WorldConfig& cfg;
  const Frame& f;
  const PathCurve& curve;
  const PointGrid& path_grid;
  StreetGround& ground;
  std::uint64_t seed;
};

// The ground cells as road-textured triangle pairs.
void add_street_ground(Builder& bld, const StreetSite& site) {
  const WorldConfig& cfg = site.cfg;
  std::vector<int> road_textures;
  for (int k = 0; k < kRoadTextureVariants; ++k) {
    road_textures.push_back(static_cast<int>(bld.world.textures.size()));
    const int px = static_cast<int>(std::lround(kRoadTextureM * cfg.street_road_texels_per_m));
    bld.world.textures.push_back(make_texture(TextureStyle::kRoad, hash_combine(site.seed, 0x70AD00u + k), px,
                                              px, kRoadTextureM, kRoadTextureM));
  }
  const double tpm_road = cfg.street_road_texels_per_m;
  StreetGround& ground = site.ground;
  for (const auto& [ix, iy] : ground.cells()) {
    const double x0 = ix * cfg.street_ground_tile_m, y0 = iy * cfg.street_ground_tile_m;
    const double x1 = x0 + cfg.street_ground_tile_m, y1 = y0 + cfg.street_ground_tile_m;
    const Eigen::Vector3d p00 = site.f.to_world(x0, y0, ground.vertex_height(ix, iy));
    const Eigen::Vector3d p10 = site.f.to_world(x1, y0, ground.vertex_height(ix + 1, iy));
    const Eigen::Vector3d p01 = site.f.to_world(x0, y1, ground.vertex_height(ix, iy + 1));
    const Eigen::Vector3d p11 = site.f.to_world(x1, y1, ground.vertex_height(ix + 1, iy + 1));
    const std::uint64_t tile_seed = hash_combine(site.seed, StreetGround::seed_key(ix, iy));
    const int s =
        bld.add_structure(StructureKind::kGround, TextureStyle::kRoad, tile_seed, cfg.street_ground_tile_m,
                          cfg.street_ground_tile_m, 0.25 * (p00 + p10 + p01 + p11), false);
    bld.pending[static_cast<std::size_t>(s)].info.texture =
        road_textures[static_cast<std::size_t>(tile_seed % road_textures.size())];
    bld.add_patch(s, p00, p10 - p00, p01 - p00, true, tpm_road, x0 * tpm_road, y0 * tpm_road);
    bld.add_patch(s, p11, p01 - p11, p10 - p11, true, tpm_road, x1 * tpm_road, y1 * tpm_road, -1.0, -1.0);
  }
}

// Road markings: a dashed centre line along the path and solid edge lines, deduplicated on revisits.
void add_street_markings(Builder& bld, const StreetSite& site) {
  const WorldConfig& cfg = site.cfg;
  const Frame& f = site.f;
  const PathCurve& curve = site.curve;
  const int marking_texture = static_cast<int>(bld.world.textures.size());
  {
    const int px_u = static_cast<int>(std::lround(kMarkingTextureLengthM * cfg.street_road_texels_per_m));
    const int px_v =
        std::max(2, static_cast<int>(std::lround(kMarkingWidthM * cfg.street_road_texels_per_m)));
    bld.world.textures.push_back(make_texture(TextureStyle::kMarking, hash_combine(site.seed, 0x3A4Bu), px_u,
                                              px_v, kMarkingTextureLengthM, kMarkingWidthM));
  }
  PointGrid dash_grid(kDashPeriodM);
  PointGrid edge_grid(kEdgeLineLengthM);
  const double edge_offset_m = cfg.street_edge_line_offset_m;
  const auto add_marking = [&](PointGrid& marking_grid, double dedup_m, double s0, double length_m,
                               double lateral_m) {
    Eigen::Vector2d p0, p1;
    double z0 = 0, z1 = 0;
    curve.sample(s0, &p0, &z0);
    curve.sample(s0 + length_m, &p1, &z1);
    const Eigen::Vector2d d = p1 - p0;
    if (d.norm() < 0.5 * length_m) return;  // sharp turn or a stop: skip
    const Eigen::Vector2d t = d.normalized();
    const Eigen::Vector2d n(-t.y(), t.x());
    const Eigen::Vector2d a = p0 + n * (lateral_m - 0.5 * kMarkingWidthM);
    const Eigen::Vector2d b = p1 + n * (lateral_m - 0.5 * kMarkingWidthM);
    const Eigen::Vector2d center = 0.5 * (a + b) + n * 0.5 * kMarkingWidthM;
    bool duplicate = false;  // revisits reuse the markings already painted
    marking_grid.for_each_within(center, dedup_m, [&](int) { duplicate = true; });
    if (duplicate) return;
    marking_grid.add(center);
    const double za = site.ground.height(a, z0 - cfg.street_camera_height_m) + kMarkingLiftM;
    const double zb = site.ground.height(b, z1 - cfg.street_camera_height_m) + kMarkingLiftM;
    const Eigen::Vector3d origin = f.to_world(a.x(), a.y(), za);
    const Eigen::Vector3d du = f.to_world(b.x(), b.y(), zb) - origin;
    Eigen::Vector3d dv = f.to_world(n.x(), n.y(), 0.0);
    dv -= du.normalized() * dv.dot(du.normalized());
    const int s = bld.add_structure(StructureKind::kMarking, TextureStyle::kMarking, 0, du.norm(),
                                    kMarkingWidthM, origin + 0.5 * du, false);
    bld.pending[static_cast<std::size_t>(s)].info.texture = marking_texture;
    bld.add_quad(s, origin, du, dv, du.norm(), kMarkingWidthM, cfg.street_road_texels_per_m, 0.0, 0.0);
  };
  for (double s = 0.0; s + kDashLengthM < curve.length(); s += kDashPeriodM) {
    add_marking(dash_grid, 0.5 * kDashPeriodM, s, kDashLengthM, 0.0);
  }
  for (double s = 0.0; s + kEdgeLineLengthM < curve.length(); s += kEdgeLineLengthM) {
    add_marking(edge_grid, 0.5 * kEdgeLineLengthM, s, kEdgeLineLengthM - 0.2, edge_offset_m);
    add_marking(edge_grid, 0.5 * kEdgeLineLengthM, s, kEdgeLineLengthM - 0.2, -edge_offset_m);
  }
}

// Posts along the kerb (lamp / sign posts): four faces each, clear of every path point, once per place.
void add_street_posts(Builder& bld, const StreetSite& site) {
  const WorldConfig& cfg = site.cfg;
  const Frame& f = site.f;
  const PathCurve& curve = site.curve;
  if (!(cfg.street_pole_spacing_m > 0.0)) return;
  PointGrid pole_grid(cfg.street_pole_spacing_m);
  int pole_index = 0;
  for (double s = 0.5 * cfg.street_pole_spacing_m; s < curve.length(); s += cfg.street_pole_spacing_m) {
    Eigen::Vector2d p0, p1, pc;
    double z0 = 0, z1 = 0, zc = 0;
    curve.sample(s - 1.0, &p0, &z0);
    curve.sample(s + 1.0, &p1, &z1);
    curve.sample(s, &pc, &zc);
    if ((p1 - p0).norm() < 1.0) continue;
    const Eigen::Vector2d t = (p1 - p0).normalized();
    const double side = (pole_index++ % 2 == 0) ? 1.0 : -1.0;
    const Eigen::Vector2d c = pc + Eigen::Vector2d(-t.y(), t.x()) * side * cfg.street_pole_offset_m;
    const double half = 0.5 * cfg.street_pole_width_m;
    if (site.path_grid.min_distance_to_segment(c, c, cfg.street_clearance_m + half) <
        cfg.street_clearance_m + half) {
      continue;
    }
    bool duplicate = false;
    pole_grid.for_each_within(c, 0.5 * cfg.street_pole_spacing_m, [&](int) { duplicate = true; });
    if (duplicate) continue;
    pole_grid.add(c);
    const double base = site.ground.height(c, zc - cfg.street_camera_height_m) - kFacadeBelowGroundM;
    const double height = cfg.street_pole_height_m + kFacadeBelowGroundM;
    const double w = cfg.street_pole_width_m;
    const std::uint64_t pole_seed =
        hash_combine(site.seed, 0x9013ull + static_cast<std::uint64_t>(pole_index));
    const int sidx = bld.add_structure(StructureKind::kPole, TextureStyle::kPillar, pole_seed, 4.0 * w,
                                       height, f.to_world(c.x(), c.y(), base + 0.5 * height), false);
    const Eigen::Vector2d corners[4] = {{c.x() - half, c.y() - half},
                                        {c.x() + half, c.y() - half},
                                        {c.x() + half, c.y() + half},
                                        {c.x() - half, c.y() + half}};
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d a = corners[k], b = corners[(k + 1) % 4];
      bld.add_quad(sidx, f.to_world(a.x(), a.y(), base), f.to_world(b.x() - a.x(), b.y() - a.y(), 0.0), f.up,
                   w, height, cfg.street_facade_texels_per_m * 2.0,
                   k * w * cfg.street_facade_texels_per_m * 2.0, 0.0);
    }
  }
}

// Facades on both sides of the street, placed one by one (deduplicated on revisits).
class FacadePlacer {
 public:
  FacadePlacer(Builder& bld, const StreetSite& site)
      : bld_(bld), site_(site), cfg_(site.cfg), facade_grid_(site.cfg.street_facade_length_m) {}

  // Places a facade of length_m centred at arc length s_center on `side` (+1 left, -1 right) unless it
  // would come too close to the path or repeat a facade already placed there.
  bool try_place(double s_center, double length_m, double side) {
    const Frame& f = site_.f;
    Rng rng(hash_combine(site_.seed, 0xFACADEull + static_cast<std::uint64_t>(facade_counter_++)));
    Eigen::Vector2d pa, pb, pc;
    double za = 0, zb = 0, zc = 0;
    site_.curve.sample(s_center - 0.5 * length_m, &pa, &za);
    site_.curve.sample(s_center + 0.5 * length_m, &pb, &zb);
    site_.curve.sample(s_center, &pc, &zc);
    const Eigen::Vector2d chord = pb - pa;
    if (chord.norm() < 0.3 * length_m) return false;
    const Eigen::Vector2d t = chord.normalized();
    const Eigen::Vector2d n = Eigen::Vector2d(-t.y(), t.x()) * side;  // away from the road
    const double offset = cfg_.street_facade_offset_m + rng.uniform(0.0, cfg_.street_facade_offset_jitter_m);
    const Eigen::Vector2d a = pc - t * 0.5 * length_m + n * offset;
    const Eigen::Vector2d b = pc + t * 0.5 * length_m + n * offset;
    if (site_.path_grid.min_distance_to_segment(a, b, cfg_.street_clearance_m) < cfg_.street_clearance_m)
      return false;
    const Eigen::Vector2d mid = 0.5 * (a + b);
    const Eigen::Vector2d inward = -n;
    if (duplicate(mid, inward, length_m)) return false;
    facade_grid_.add(mid);
    placed_.push_back({a, b, inward});
    const double ground = site_.ground.height(pc, zc - cfg_.street_camera_height_m);
    const double height = rng.uniform(cfg_.street_facade_min_height_m, cfg_.street_facade_max_height_m);
    const double r = rng.uniform();
    const TextureStyle style = r < 0.35  ? TextureStyle::kFacadeWindows
                               : r < 0.6 ? TextureStyle::kFacadeBrick
                               : r < 0.8 ? TextureStyle::kFacadePlaster
                                         : TextureStyle::kFacadeShop;
    const std::uint64_t tex_seed =
        hash_combine(site_.seed, 0xB1D6ull + static_cast<std::uint64_t>(placed_.size()));
    const Eigen::Vector3d origin = f.to_world(a.x(), a.y(), ground - kFacadeBelowGroundM);
    const Eigen::Vector3d du = f.to_world(b.x() - a.x(), b.y() - a.y(), 0.0);
    const int sidx = bld_.add_structure(StructureKind::kFacade, style, tex_seed, length_m, height,
                                        origin + 0.5 * du + f.up * (0.5 * height), true);
    bld_.add_quad(sidx, origin, du, f.up, length_m, height + kFacadeBelowGroundM,
                  cfg_.street_facade_texels_per_m, 0.0,
                  -kFacadeBelowGroundM * cfg_.street_facade_texels_per_m);
    return true;
  }

 private:
  // Whether a facade facing `inward` centred at mid already stands there (a revisit of the place).
  bool duplicate(const Eigen::Vector2d& mid, const Eigen::Vector2d& inward, double length_m) const {
    bool found = false;
    facade_grid_.for_each_within(mid, 2.0 * cfg_.street_facade_length_m, [&](int idx) {
      const PlacedFacade& other = placed_[static_cast<std::size_t>(idx)];
      if (other.normal.dot(inward) < 0.5) return;
      const Eigen::Vector2d ot = (other.b - other.a);
      const double olen = ot.norm();
      const Eigen::Vector2d od = ot / olen;
      const double along = (mid - 0.5 * (other.a + other.b)).dot(od);
      const double lateral = std::abs((mid - other.a).dot(Eigen::Vector2d(-od.y(), od.x())));
      if (lateral < kFacadeDedupLateralM && std::abs(along) < 0.5 * (olen + length_m)) found = true;
    });
    return found;
  }

  Builder& bld_;
  const StreetSite& site_;
  const WorldConfig& cfg_;
  std::vector<PlacedFacade> placed_;
  PointGrid facade_grid_;
  int facade_counter_ = 0;
};

void add_street_facades(Builder& bld, const StreetSite& site) {
  const WorldConfig& cfg = site.cfg;
  FacadePlacer placer(bld, site);
  const double step = cfg.street_facade_length_m + cfg.street_facade_gap_m;
  const double length = cfg.street_facade_length_m;
  for (double s = 0.5 * length; s < site.curve.length(); s += step) {
    for (double side : {1.0, -1.0}) {
      if (!placer.try_place(s, length, side)) {
        placer.try_place(s - 0.25 * step, 0.5 * length - 0.5 * cfg.street_facade_gap_m, side);
        placer.try_place(s + 0.25 * step, 0.5 * length - 0.5 * cfg.street_facade_gap_m, side);
      }
    }
  }
}

void build_street(Builder& bld, const std::vector<Eigen::Vector3d>& path_w) {
  const WorldConfig& cfg = bld.config;
  const PathCurve curve = make_curve(path_w, bld.frame);
  PointGrid path_grid(std::max(1.0, cfg.street_clearance_m));
  for (const Eigen::Vector2d& p : curve.xy) path_grid.add(p);
  StreetGround ground(cfg, curve, path_grid);
  const StreetSite site{cfg, bld.frame, curve, path_grid, ground, static_cast<std::uint64_t>(cfg.seed)};
  add_street_ground(bld, site);
  add_street_markings(bld, site);
  add_street_posts(bld, site);
  add_street_facades(bld, site);
}

// ------------------------------------------------------------------------------------------------- hall

// The hall's box around the path (margins included) and the path's clearance grid.
struct HallSite {
  const WorldConfig& cfg;
  const Frame& f;
  std::uint64_t seed = 0;
  Eigen::Vector2d lo, hi;  // horizontal extent of the room
  double floor_z = 0, ceiling_z = 0, room_h = 0;
  PointGrid path_grid;
};

HallSite make_hall_site(const WorldConfig& cfg, const Frame& f, const std::vector<Eigen::Vector3d>& path_w) {
  HallSite site{cfg, f, static_cast<std::uint64_t>(cfg.seed),          {}, {}, 0,
                0,   0, PointGrid(std::max(0.5, cfg.hall_clearance_m))};
  Eigen::Vector2d lo(std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  double z_lo = std::numeric_limits<double>::infinity(), z_hi = -z_lo;
  for (const Eigen::Vector3d& p : path_w) {
    const Eigen::Vector2d xy(p.dot(f.e1), p.dot(f.e2));
    lo = lo.cwiseMin(xy);
    hi = hi.cwiseMax(xy);
    z_lo = std::min(z_lo, p.dot(f.up));
    z_hi = std::max(z_hi, p.dot(f.up));
    site.path_grid.add(xy);
  }
  lo.array() -= cfg.hall_margin_m;
  hi.array() += cfg.hall_margin_m;
  site.lo = lo;
  site.hi = hi;
  site.floor_z = z_lo - cfg.hall_floor_below_m;
  site.ceiling_z = z_hi + cfg.hall_ceiling_above_m;
  site.room_h = site.ceiling_z - site.floor_z;
  return site;
}

// Walls (four sides split into panels), floor and ceiling (in tiles).
void add_hall_shell(Builder& bld, const HallSite& site) {
  const WorldConfig& cfg = site.cfg;
  const Frame& f = site.f;
  const Eigen::Vector2d &lo = site.lo, &hi = site.hi;
  const double tpm = cfg.hall_texels_per_m;
  const Eigen::Vector2d corners[4] = {{lo.x(), lo.y()}, {hi.x(), lo.y()}, {hi.x(), hi.y()}, {lo.x(), hi.y()}};
  for (int side = 0; side < 4; ++side) {
    const Eigen::Vector2d a = corners[side];
    const Eigen::Vector2d b = corners[(side + 1) % 4];
    const double len = (b - a).norm();
    const int panels = std::max(1, static_cast<int>(std::ceil(len / cfg.hall_wall_panel_m)));
    const double pw = len / panels;
    const Eigen::Vector2d t = (b - a) / len;
    for (int k = 0; k < panels; ++k) {
      const Eigen::Vector2d pa = a + t * (k * pw);
      const Eigen::Vector3d origin = f.to_world(pa.x(), pa.y(), site.floor_z);
      const Eigen::Vector3d du = f.to_world(t.x(), t.y(), 0.0);
      const std::uint64_t s_seed =
          hash_combine(site.seed, 0x3A11ull + static_cast<std::uint64_t>(side * 1000 + k));
      const int s = bld.add_structure(StructureKind::kWall, TextureStyle::kHallWall, s_seed, pw, site.room_h,
                                      origin + du * (0.5 * pw) + f.up * (0.5 * site.room_h), true);
      bld.add_quad(s, origin, du, f.up, pw, site.room_h, tpm, 0.0, 0.0);
    }
  }
  const double tile = 2.0 * cfg.hall_wall_panel_m;
  const int nx = std::max(1, static_cast<int>(std::ceil((hi.x() - lo.x()) / tile)));
  const int ny = std::max(1, static_cast<int>(std::ceil((hi.y() - lo.y()) / tile)));
  const double tx = (hi.x() - lo.x()) / nx, ty = (hi.y() - lo.y()) / ny;
  for (int i = 0; i < nx; ++i) {
    for (int j = 0; j < ny; ++j) {
      const double x0 = lo.x() + i * tx, y0 = lo.y() + j * ty;
      for (int level = 0; level < 2; ++level) {
        const double z = level == 0 ? site.floor_z : site.ceiling_z;
        const Eigen::Vector3d origin = f.to_world(x0, y0, z);
        const std::uint64_t s_seed =
            hash_combine(site.seed, 0xF100ull + static_cast<std::uint64_t>((i * 1000 + j) * 2 + level));
        const TextureStyle style = level == 0 ? TextureStyle::kHallFloor : TextureStyle::kHallCeiling;
        const int s = bld.add_structure(level == 0 ? StructureKind::kFloor : StructureKind::kCeiling, style,
                                        s_seed, tx, ty, origin + f.to_world(0.5 * tx, 0.5 * ty, 0.0), false);
        bld.add_quad(s, origin, f.e1, f.e2, tx, ty, level == 0 ? tpm : 0.5 * tpm, 0.0, 0.0);
      }
    }
  }
}

// Pillars and crates at random places clear of the path and of each other.
void add_hall_props(Builder& bld, const HallSite& site) {
  const WorldConfig& cfg = site.cfg;
  const Frame& f = site.f;
  const Eigen::Vector2d &lo = site.lo, &hi = site.hi;
  const double floor_z = site.floor_z, room_h = site.room_h;
  const double tpm = cfg.hall_texels_per_m;
  Rng rng(hash_combine(site.seed, 0x9111A5ull));
  const auto clear_box = [&](const Eigen::Vector2d& c, double half) {
    return site.path_grid.min_distance_to_segment(c, c, half * 1.5 + cfg.hall_clearance_m) >=
           half * 1.5 + cfg.hall_clearance_m;
  };
  std::vector<std::pair<Eigen::Vector2d, double>> occupied;
  const auto free_of_others = [&](const Eigen::Vector2d& c, double half) {
    for (const auto& [oc, oh] : occupied) {
      if ((oc - c).cwiseAbs().maxCoeff() < half + oh + 0.3) return false;
    }
    return true;
  };
  // A box of size w x w x h standing at (c, base_z): four sides (+ top if requested).
  const auto add_box = [&](int s, const Eigen::Vector2d& c, double w, double h, double base_z, bool top,
                           double texels_per_m) {
    const double half = 0.5 * w;
    const Eigen::Vector2d cs[4] = {{c.x() - half, c.y() - half},
                                   {c.x() + half, c.y() - half},
                                   {c.x() + half, c.y() + half},
                                   {c.x() - half, c.y() + half}};
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d a = cs[k], b = cs[(k + 1) % 4];
      const Eigen::Vector3d du = f.to_world((b - a).x() / w, (b - a).y() / w, 0.0);
      bld.add_quad(s, f.to_world(a.x(), a.y(), base_z), du, f.up, w, h, texels_per_m, k * w * texels_per_m,
                   0.0);
    }
    if (top)
      bld.add_quad(s, f.to_world(cs[0].x(), cs[0].y(), base_z + h), f.e1, f.e2, w, w, texels_per_m, 0.0, 0.0);
  };
  const int attempts = 200;
  int pillars = 0;
  for (int k = 0; k < attempts && pillars < cfg.hall_pillar_count; ++k) {
    const double w = 0.6;
    const Eigen::Vector2d c(rng.uniform(lo.x() + 1.0, hi.x() - 1.0), rng.uniform(lo.y() + 1.0, hi.y() - 1.0));
    if (!clear_box(c, 0.5 * w) || !free_of_others(c, 0.5 * w)) continue;
    occupied.emplace_back(c, 0.5 * w);
    const std::uint64_t s_seed = hash_combine(site.seed, 0x9177ull + static_cast<std::uint64_t>(pillars));
    // Pillar texture wraps around its four faces: width 4 w.
    const int s = bld.add_structure(StructureKind::kPillar, TextureStyle::kPillar, s_seed, 4.0 * w, room_h,
                                    f.to_world(c.x(), c.y(), floor_z + 0.5 * room_h), true);
    add_box(s, c, w, room_h, floor_z, false, tpm);
    ++pillars;
  }
  static constexpr double kCrateSizes[] = {0.8, 1.0, 1.2, 1.5};
  int crates = 0;
  for (int k = 0; k < attempts && crates < cfg.hall_crate_count; ++k) {
    const double w = kCrateSizes[rng.integer(0, 3)];
    const Eigen::Vector2d c(rng.uniform(lo.x() + w, hi.x() - w), rng.uniform(lo.y() + w, hi.y() - w));
    if (!clear_box(c, 0.5 * w) || !free_of_others(c, 0.5 * w)) continue;
    occupied.emplace_back(c, 0.5 * w);
    const bool stacked = rng.chance(0.4);
    const int levels = stacked ? 2 : 1;
    for (int level = 0; level < levels; ++level) {
      const std::uint64_t s_seed =
          hash_combine(site.seed, 0xC7A7Eull + static_cast<std::uint64_t>(crates * 2 + level));
      const double base = floor_z + level * w;
      const int s = bld.add_structure(StructureKind::kCrate, TextureStyle::kCrate, s_seed, 4.0 * w, w,
                                      f.to_world(c.x(), c.y(), base + 0.5 * w), true);
      add_box(s, c, w, w, base, level == levels - 1, tpm);
    }
    ++crates;
  }
}

void build_hall(Builder& bld, const std::vector<Eigen::Vector3d>& path_w) {
  const HallSite site = make_hall_site(bld.config, bld.frame, path_w);
  add_hall_shell(bld, site);
  add_hall_props(bld, site);
}

// --------------------------------------------------------------------------------------------- aliasing

// Structure `idx` takes the texture (seed, style) of structure `src`, and its size: same texture => same
// size, so it adopts the source's height (quads of facades grow or shrink with it).
void alias_structure(Builder& bld, int idx, int src) {
  PendingStructure& s = bld.pending[static_cast<std::size_t>(idx)];
  const PendingStructure& source = bld.pending[static_cast<std::size_t>(src)];
  s.info.aliased_from = src;
  s.info.style = source.info.style;
  s.info.texture_seed = source.info.texture_seed;
  const double dh = source.height_m - s.height_m;
  if (std::abs(dh) > 1e-9) {
    for (int q : s.quads) {
      Quad& quad = bld.world.quads[static_cast<std::size_t>(q)];
      if (std::abs(quad.axis_v_w.dot(bld.frame.up.cast<float>())) > 0.9f)
        quad.height_m += static_cast<float>(dh);
    }
    s.height_m = source.height_m;
  }
}

void apply_aliasing(Builder& bld) {
  const double fraction = bld.config.aliasing_fraction;
  std::vector<int> aliasable;
  for (std::size_t k = 0; k < bld.pending.size(); ++k) {
    if (bld.pending[k].info.aliasable) aliasable.push_back(static_cast<int>(k));
  }
  const int target = static_cast<int>(std::lround(fraction * static_cast<double>(aliasable.size())));
  if (target <= 0) return;
  Rng rng(hash_combine(static_cast<std::uint64_t>(bld.config.seed), 0xA11A5ull));
  std::vector<int> order = aliasable;
  for (std::size_t k = order.size(); k > 1; --k) {
    std::swap(order[k - 1], order[static_cast<std::size_t>(rng.integer(0, static_cast<int>(k) - 1))]);
  }
  std::vector<char> is_alias(bld.pending.size(), 0), is_source(bld.pending.size(), 0);
  int done = 0;
  for (int idx : order) {
    if (done >= target) break;
    if (is_source[static_cast<std::size_t>(idx)]) continue;
    PendingStructure& s = bld.pending[static_cast<std::size_t>(idx)];
    std::vector<std::pair<double, int>> candidates;
    for (int other : aliasable) {
      const PendingStructure& o = bld.pending[static_cast<std::size_t>(other)];
      if (other == idx || is_alias[static_cast<std::size_t>(other)] || o.info.kind != s.info.kind) continue;
      if (std::abs(o.width_m - s.width_m) > 0.01) continue;
      candidates.emplace_back(-(o.center_w - s.center_w).norm(), other);
    }
    if (candidates.empty()) continue;
    std::sort(candidates.begin(), candidates.end());  // farthest first
    const int far_count = std::max(1, static_cast<int>(candidates.size() * kAliasMinDistanceFraction));
    const int src = candidates[static_cast<std::size_t>(rng.integer(0, far_count - 1))].second;
    alias_structure(bld, idx, src);
    is_alias[static_cast<std::size_t>(idx)] = 1;
    is_source[static_cast<std::size_t>(src)] = 1;
    ++done;
  }
  if (done < target) {
    spdlog::warn(
        "world: aliasing_fraction {} asks for {} aliased structures, only {} have a same-size partner",
        fraction, target, done);
  }
}

// The deterministic place copy (WorldConfig alias_copy_*), after the random knob: a target structure that
// the knob already aliased, or used as an alias source, keeps its texture (no chains of aliases).
void apply_alias_copy(Builder& bld) {
  const WorldConfig& cfg = bld.config;
  if (cfg.alias_copy_radius_m <= 0.0) return;
  const auto horizontal = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector2d(p.dot(bld.frame.e1), p.dot(bld.frame.e2));
  };
  const Eigen::Vector2d source_c(cfg.alias_copy_source_x_m, cfg.alias_copy_source_y_m);
  const Eigen::Vector2d target_c(cfg.alias_copy_target_x_m, cfg.alias_copy_target_y_m);
  const Eigen::Rotation2Dd R_target_source(cfg.alias_copy_rotation_deg * std::numbers::pi / 180.0);
  const auto copyable = [](const Structure& info) {
    return info.kind != StructureKind::kGround && info.kind != StructureKind::kMarking;
  };
  std::vector<char> is_source(bld.pending.size(), 0);
  for (const PendingStructure& s : bld.pending) {
    if (s.info.aliased_from >= 0) is_source[static_cast<std::size_t>(s.info.aliased_from)] = 1;
  }
  std::vector<char> in_target(bld.pending.size(), 0);
  for (std::size_t k = 0; k < bld.pending.size(); ++k) {
    in_target[k] = (horizontal(bld.pending[k].center_w) - target_c).norm() <= cfg.alias_copy_radius_m ? 1 : 0;
  }
  int candidates = 0, copied = 0;
  for (std::size_t k = 0; k < bld.pending.size(); ++k) {
    PendingStructure& t = bld.pending[k];
    if (!in_target[k] || !copyable(t.info)) continue;
    ++candidates;
    if (t.info.aliased_from >= 0 || is_source[k]) continue;
    const Eigen::Vector2d expected =
        source_c + R_target_source.inverse() * (horizontal(t.center_w) - target_c);
    int best = -1;
    double best_m = cfg.alias_copy_tolerance_m;
    for (std::size_t o = 0; o < bld.pending.size(); ++o) {
      const PendingStructure& s = bld.pending[o];
      if (in_target[o] || s.info.kind != t.info.kind || std::abs(s.width_m - t.width_m) > 0.01) continue;
      const double d = (horizontal(s.center_w) - expected).norm();
      if (d <= best_m) {
        best_m = d;
        best = static_cast<int>(o);
      }
    }
    spdlog::debug(
        "world: place copy target {} ({}) at ({:.1f}, {:.1f}): source {} at {:.2f} m from the mapped "
        "position",
        k, enum_name(t.info.kind), horizontal(t.center_w).x(), horizontal(t.center_w).y(), best,
        best < 0 ? -1.0 : best_m);
    if (best < 0) continue;
    // Copy from the root of an alias (its seed is the root's anyway) so that no chain forms.
    const int root = bld.pending[static_cast<std::size_t>(best)].info.aliased_from >= 0
                         ? bld.pending[static_cast<std::size_t>(best)].info.aliased_from
                         : best;
    alias_structure(bld, static_cast<int>(k), root);
    t.info.copied = true;
    ++copied;
  }
  spdlog::info(
      "world: place copy ({:.1f}, {:.1f}) -> ({:.1f}, {:.1f}) within {:.1f} m: {} of {} structures copied",
      source_c.x(), source_c.y(), target_c.x(), target_c.y(), cfg.alias_copy_radius_m, copied, candidates);
  if (copied == 0) spdlog::warn("world: the place copy found no structure to copy (check alias_copy_*)");
}

}  // namespace

void WorldConfig::validate() const {
  const auto positive = [](const char* key, double v) {
    if (!(v > 0.0))
      throw ConfigError(std::string("world.") + key + ": must be > 0 (got " + std::to_string(v) + ")");
  };
  const auto non_negative = [](const char* key, double v) {
    if (!(v >= 0.0))
      throw ConfigError(std::string("world.") + key + ": must be >= 0 (got " + std::to_string(v) + ")");
  };
  if (!(aliasing_fraction >= 0.0 && aliasing_fraction <= 0.5)) {
    throw ConfigError("world.aliasing_fraction: must be in [0, 0.5] (got " +
                      std::to_string(aliasing_fraction) + ")");
  }
  non_negative("alias_copy_radius_m", alias_copy_radius_m);
  positive("alias_copy_tolerance_m", alias_copy_tolerance_m);
  for (const double v : {alias_copy_source_x_m, alias_copy_source_y_m, alias_copy_target_x_m,
                         alias_copy_target_y_m, alias_copy_rotation_deg}) {
    if (!std::isfinite(v))
      throw ConfigError("world.alias_copy_*: the place centres and rotation must be finite");
  }
  positive("street_facade_offset_m", street_facade_offset_m);
  non_negative("street_facade_offset_jitter_m", street_facade_offset_jitter_m);
  positive("street_clearance_m", street_clearance_m);
  positive("street_facade_length_m", street_facade_length_m);
  non_negative("street_facade_gap_m", street_facade_gap_m);
  positive("street_facade_min_height_m", street_facade_min_height_m);
  if (street_facade_max_height_m < street_facade_min_height_m) {
    throw ConfigError("world.street_facade_max_height_m: must be >= street_facade_min_height_m");
  }
  non_negative("street_camera_height_m", street_camera_height_m);
  non_negative("street_edge_line_offset_m", street_edge_line_offset_m);
  positive("street_ground_tile_m", street_ground_tile_m);
  positive("street_facade_texels_per_m", street_facade_texels_per_m);
  positive("street_road_texels_per_m", street_road_texels_per_m);
  non_negative("street_pole_spacing_m", street_pole_spacing_m);
  positive("street_pole_height_m", street_pole_height_m);
  positive("street_pole_width_m", street_pole_width_m);
  if (street_pole_spacing_m > 0.0 && street_pole_offset_m < street_clearance_m) {
    throw ConfigError("world.street_pole_offset_m: must be >= street_clearance_m");
  }
  positive("hall_margin_m", hall_margin_m);
  non_negative("hall_floor_below_m", hall_floor_below_m);
  non_negative("hall_ceiling_above_m", hall_ceiling_above_m);
  positive("hall_wall_panel_m", hall_wall_panel_m);
  if (hall_pillar_count < 0) throw ConfigError("world.hall_pillar_count: must be >= 0");
  if (hall_crate_count < 0) throw ConfigError("world.hall_crate_count: must be >= 0");
  non_negative("hall_clearance_m", hall_clearance_m);
  positive("hall_texels_per_m", hall_texels_per_m);
  if (street_clearance_m > street_facade_offset_m) {
    throw ConfigError(
        "world.street_clearance_m: must be <= street_facade_offset_m (facades could never be placed)");
  }
}

int World::aliased_structure_count() const {
  int n = 0;
  for (const Structure& s : structures) n += s.aliased_from >= 0 ? 1 : 0;
  return n;
}

int World::copied_structure_count() const {
  int n = 0;
  for (const Structure& s : structures) n += s.copied ? 1 : 0;
  return n;
}

int World::aliasable_structure_count() const {
  int n = 0;
  for (const Structure& s : structures) n += s.aliasable ? 1 : 0;
  return n;
}

World build_world(const WorldConfig& config, const std::vector<Eigen::Vector3d>& path_w,
                  const Eigen::Vector3d& up_w) {
  config.validate();
  if (path_w.empty()) throw DataError("<path>", "build_world: the trajectory has no positions");
  if (!(up_w.norm() > 1e-9)) throw ConfigError("world.up: the up vector must not be zero");
  for (std::size_t k = 0; k < path_w.size(); ++k) {
    if (!path_w[k].allFinite()) throw DataError("<path>", k + 1, "build_world: position is not finite");
  }
  Builder bld{config, make_frame(up_w), World{}, {}};
  bld.world.config = config;
  bld.world.kind = config.kind;
  bld.world.up_w = up_w.normalized();
  if (bld.world.kind == WorldKind::kStreet) {
    build_street(bld, path_w);
  } else {
    build_hall(bld, path_w);
  }
  apply_aliasing(bld);
  apply_alias_copy(bld);

  // Textures: one per structure with its own seed; aliased ones and shared ground reuse.
  const double tpm_facade = config.street_facade_texels_per_m;
  std::vector<int> texture_of(bld.pending.size(), -1);
  for (std::size_t k = 0; k < bld.pending.size(); ++k) {
    PendingStructure& s = bld.pending[k];
    const bool shared = s.info.kind == StructureKind::kGround || s.info.kind == StructureKind::kMarking;
    if (shared) {
      texture_of[k] = s.info.texture;
      continue;
    }
    if (s.info.aliased_from >= 0) continue;
    double tpm = config.hall_texels_per_m;
    if (s.info.kind == StructureKind::kPole) {
      tpm = 2.0 * tpm_facade;
    } else if (bld.world.kind == WorldKind::kStreet) {
      tpm = tpm_facade;
    } else if (s.info.kind == StructureKind::kCeiling) {
      tpm = 0.5 * config.hall_texels_per_m;
    }
    const int w_px = std::max(2, static_cast<int>(std::ceil(s.width_m * tpm)));
    const int h_px = std::max(2, static_cast<int>(std::ceil(s.height_m * tpm)));
    texture_of[k] = static_cast<int>(bld.world.textures.size());
    bld.world.textures.push_back(
        make_texture(s.info.style, s.info.texture_seed, w_px, h_px, w_px / tpm, h_px / tpm));
  }
  for (std::size_t k = 0; k < bld.pending.size(); ++k) {
    PendingStructure& s = bld.pending[k];
    if (s.info.aliased_from >= 0) texture_of[k] = texture_of[static_cast<std::size_t>(s.info.aliased_from)];
    s.info.texture = texture_of[k];
    bld.world.structures.push_back(s.info);
  }
  for (Quad& q : bld.world.quads) {
    q.texture = q.structure >= 0 ? texture_of[static_cast<std::size_t>(q.structure)] : 0;
  }
  render_detail::build_bvh(bld.world.quads, &bld.world.bvh_nodes, &bld.world.bvh_quad_index);
  std::size_t bytes = 0;
  for (const Texture& t : bld.world.textures) bytes += t.memory_bytes();
  spdlog::info(
      "world: {} ({} quads, {} structures, {} aliased, {} textures, {:.1f} MB of texels, {} BVH nodes)",
      enum_name(config.kind), bld.world.quads.size(), bld.world.structures.size(),
      bld.world.aliased_structure_count(), bld.world.textures.size(), static_cast<double>(bytes) / 1e6,
      bld.world.bvh_nodes.size());
  return std::move(bld.world);
}

void rebuild_acceleration(World* world) {
  render_detail::build_bvh(world->quads, &world->bvh_nodes, &world->bvh_quad_index);
}

int World::intersect(const Eigen::Vector3f& origin_w, const Eigen::Vector3f& dir_w, float t_min, float t_max,
                     float* t_hit, float* u_tx, float* v_tx) const {
  return render_detail::intersect_bvh(*this, origin_w, dir_w, t_min, t_max, t_hit, u_tx, v_tx);
}

}  // namespace loopgate::sim
