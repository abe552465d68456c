#include "sim/revisit.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>

namespace loopgate::sim {

namespace {

// Horizontal grid of pose indices, cells of `cell_m`.
class PoseGrid {
 public:
  explicit PoseGrid(double cell_m) : cell_m_(cell_m) {}
  void add(const Eigen::Vector2d& p, int index) { cells_[key(cell(p.x()), cell(p.y()))].push_back(index); }
  // Calls f(index) for the poses of the 3 x 3 cells around p (a superset of those within cell_m).
  template <class F>
  void for_each_near(const Eigen::Vector2d& p, F&& f) const {
    const long long cx = cell(p.x()), cy = cell(p.y());
    for (long long x = cx - 1; x <= cx + 1; ++x) {
      for (long long y = cy - 1; y <= cy + 1; ++y) {
        const auto found = cells_.find(key(x, y));
        if (found == cells_.end()) continue;
        for (const int index : found->second) f(index);
      }
    }
  }

 private:
  long long cell(double v) const { return static_cast<long long>(std::floor(v / cell_m_)); }
  static std::uint64_t key(long long x, long long y) {
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(x)) << 32) |
           static_cast<std::uint64_t>(static_cast<std::uint32_t>(y));
  }
  double cell_m_;
  std::unordered_map<std::uint64_t, std::vector<int>> cells_;
};

double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

}  // namespace

std::vector<bool> find_revisit_poses(const std::vector<StampedPose>& poses,
                                     const ProceduralRouteConfig& config) {
  const std::size_t n = poses.size();
  std::vector<bool> revisit(n, false);
  std::vector<double> travel_m(n, 0.0);
  std::vector<Eigen::Vector2d> xy(n);
  for (std::size_t i = 0; i < n; ++i) {
    xy[i] = poses[i].T_w_b.translation().head<2>();
    if (i > 0) travel_m[i] = travel_m[i - 1] + (xy[i] - xy[i - 1]).norm();
  }
  PoseGrid grid(config.revisit_radius_m);
  const double radius2 = config.revisit_radius_m * config.revisit_radius_m;
  for (std::size_t i = 0; i < n; ++i) {
    bool found = false;
    grid.for_each_near(xy[i], [&](int j) {
      const auto k = static_cast<std::size_t>(j);
      if ((xy[k] - xy[i]).squaredNorm() <= radius2 &&
          travel_m[i] - travel_m[k] >= config.revisit_min_travel_m)
        found = true;
    });
    revisit[i] = found;
    grid.add(xy[i], static_cast<int>(i));
  }
  return revisit;
}

std::vector<double> revisit_offset_weights(const std::vector<StampedPose>& poses,
                                           const std::vector<bool>& revisit, double lane_change_m) {
  const std::size_t n = poses.size();
  std::vector<double> travel_m(n, 0.0);
  for (std::size_t i = 1; i < n; ++i) {
    travel_m[i] =
        travel_m[i - 1] + (poses[i].T_w_b.translation() - poses[i - 1].T_w_b.translation()).head<2>().norm();
  }
  // Path distance to the nearest revisit pose before (forward pass) and after (backward pass).
  constexpr double kFar = std::numeric_limits<double>::infinity();
  std::vector<double> distance_m(n, kFar);
  double last = -kFar;
  for (std::size_t i = 0; i < n; ++i) {
    if (revisit[i]) last = travel_m[i];
    distance_m[i] = travel_m[i] - last;
  }
  last = kFar;
  for (std::size_t k = n; k-- > 0;) {
    if (revisit[k]) last = travel_m[k];
    distance_m[k] = std::min(distance_m[k], last - travel_m[k]);
  }
  std::vector<double> weight(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    weight[i] = lane_change_m > 0.0 ? smoothstep(1.0 - distance_m[i] / lane_change_m)
                                    : (distance_m[i] == 0.0 ? 1.0 : 0.0);
  }
  return weight;
}

std::vector<Eigen::Vector3d> apply_revisit_offset(const ProceduralRouteConfig& config,
                                                  std::vector<StampedPose>& poses) {
  std::vector<Eigen::Vector3d> shift_w(poses.size(), Eigen::Vector3d::Zero());
  if (config.revisit_lateral_offset_m == 0.0) return shift_w;
  const std::vector<double> weight =
      revisit_offset_weights(poses, find_revisit_poses(poses, config), config.revisit_lane_change_m);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    // The body's left (y) axis in the horizontal plane: the route's body is x forward, y left, z up.
    Eigen::Vector3d left = poses[i].T_w_b.linear().col(1);
    left.z() = 0.0;
    left.normalize();
    shift_w[i] = config.revisit_lateral_offset_m * weight[i] * left;
    poses[i].T_w_b.translation() += shift_w[i];
  }
  return shift_w;
}

}  // namespace loopgate::sim
