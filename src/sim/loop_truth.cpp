// Ground-truth loops of a simulation: which frames revisit which (sim/simulator.hpp find_loop_truth), and
// their CSV file.
#include <cmath>
#include <fstream>
#include <numbers>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "sim/simulator.hpp"

namespace loopgate::sim {
namespace {

// Horizontal component of v (perpendicular to up) or v itself.
Eigen::Vector3d loop_offset(const Eigen::Vector3d& v, const Eigen::Vector3d& up_w, bool horizontal_only) {
  return horizontal_only ? horizontal_part(v, up_w) : v;
}

}  // namespace

std::vector<LoopInterval> find_loop_truth(const std::vector<Eigen::Isometry3d>& T_w_c,
                                          const Eigen::Vector3d& up_w, const LoopTruthSettings& settings) {
  settings.validate();
  const Eigen::Vector3d up = up_w.normalized();
  const double radius2 = settings.radius_m * settings.radius_m;
  const double cos_max = std::cos(settings.max_view_angle_deg * std::numbers::pi / 180.0);
  const bool check_angle = settings.max_view_angle_deg < 180.0;
  const std::size_t gap = static_cast<std::size_t>(settings.min_gap_frames);
  std::vector<Eigen::Vector3d> p(T_w_c.size());
  std::vector<Eigen::Vector3d> axis(T_w_c.size());
  std::vector<double> travel_m(T_w_c.size(), 0.0);  // camera path length from frame 0
  for (std::size_t i = 0; i < T_w_c.size(); ++i) {
    p[i] = loop_offset(T_w_c[i].translation(), up, settings.horizontal_only);
    axis[i] = T_w_c[i].linear().col(2);
    if (i > 0) travel_m[i] = travel_m[i - 1] + (T_w_c[i].translation() - T_w_c[i - 1].translation()).norm();
  }
  std::vector<LoopInterval> out;
  for (std::size_t j = gap; j < T_w_c.size(); ++j) {
    bool open = false;
    LoopInterval current;
    for (std::size_t i = 0; i + gap <= j; ++i) {
      const bool match = (p[i] - p[j]).squaredNorm() <= radius2 &&
                         travel_m[j] - travel_m[i] >= settings.revisit.min_travel_m &&
                         (!check_angle || axis[i].dot(axis[j]) >= cos_max);
      if (match) {
        if (!open) {
          current = LoopInterval{static_cast<std::int64_t>(j), static_cast<std::int64_t>(i),
                                 static_cast<std::int64_t>(i)};
          open = true;
        } else {
          current.last = static_cast<std::int64_t>(i);
        }
      } else if (open) {
        out.push_back(current);
        open = false;
      }
    }
    if (open) out.push_back(current);
  }
  return out;
}

std::vector<LoopInterval> plan_loop_truth(const SimulationPlan& plan, const LoopTruthSettings& settings) {
  std::vector<Eigen::Isometry3d> street_T_w_c;
  street_T_w_c.reserve(plan.frames_used);
  for (std::size_t f = 0; f < plan.frames_used; ++f) street_T_w_c.push_back(plan.street_T_w_c(f));
  return find_loop_truth(street_T_w_c, plan.up_w, settings);
}

void write_loop_truth_pairs(const std::filesystem::path& file, const std::vector<LoopInterval>& loops) {
  std::ofstream out(file, std::ios::binary);
  out << "query,reference\n";
  for (const LoopInterval& loop : loops) {
    for (std::int64_t j = loop.first; j <= loop.last; ++j) out << loop.query << ',' << j << '\n';
  }
  if (!out) throw DataError(file, "cannot write the ground-truth loop pairs");
}

}  // namespace loopgate::sim
