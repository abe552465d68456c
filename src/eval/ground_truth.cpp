#include "eval/ground_truth.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "core/error.hpp"
#include "core/geometry.hpp"

namespace loopgate {

namespace {

struct CellKey {
  std::int64_t x, y, z;
  bool operator==(const CellKey&) const = default;
};
struct CellHash {
  std::size_t operator()(const CellKey& k) const {
    std::size_t h = std::hash<std::int64_t>{}(k.x);
    h = h * 1000003u ^ std::hash<std::int64_t>{}(k.y);
    return h * 1000003u ^ std::hash<std::int64_t>{}(k.z);
  }
};

CellKey cell_of(const Eigen::Vector3d& p, double cell_m) {
  return {static_cast<std::int64_t>(std::floor(p.x() / cell_m)),
          static_cast<std::int64_t>(std::floor(p.y() / cell_m)),
          static_cast<std::int64_t>(std::floor(p.z() / cell_m))};
}

}  // namespace

void GroundTruthConfig::validate() const {
  if (!(radius_m > 0.0)) throw ConfigError("ground_truth.radius_m: must be > 0");
  if (gap_frames < 1) throw ConfigError("ground_truth.gap_frames: must be >= 1");
  if (!std::isfinite(accept_radius_m)) throw ConfigError("ground_truth.accept_radius_m: must be finite");
  revisit.validate("ground_truth.min_travel_m");
}

LoopGroundTruth LoopGroundTruth::from_positions(const std::vector<Eigen::Vector3d>& p_w,
                                                const GroundTruthConfig& config) {
  config.validate();
  LoopGroundTruth gt;
  const std::size_t n = p_w.size();
  gt.references_.resize(n);
  gt.positions_.reserve(n);
  for (const auto& p : p_w) gt.positions_.push_back(project_to_plane(p, config.plane));
  gt.accept_radius_m_ = config.effective_accept_radius_m();
  gt.min_travel_m_ = config.revisit.min_travel_m;
  gt.travel_m_.assign(n, 0.0);
  const Eigen::Vector3d* last = nullptr;
  double travel_m = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    if (p_w[i].allFinite()) {
      if (last) travel_m += (p_w[i] - *last).norm();
      last = &p_w[i];
    }
    gt.travel_m_[i] = travel_m;
  }
  const double r = config.radius_m;
  const double r2 = r * r;
  const auto gap = static_cast<std::size_t>(config.gap_frames);
  // Insert frames into the grid as they become eligible (j <= i - gap), then query the 27 cells.
  std::unordered_map<CellKey, std::vector<std::size_t>, CellHash> grid;
  for (std::size_t i = 0; i < n; ++i) {
    if (i >= gap && gt.positions_[i - gap].allFinite()) {
      const std::size_t j = i - gap;
      grid[cell_of(gt.positions_[j], r)].push_back(j);
    }
    if (!gt.positions_[i].allFinite()) continue;
    const CellKey c = cell_of(gt.positions_[i], r);
    auto& refs = gt.references_[i];
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        for (std::int64_t dz = -1; dz <= 1; ++dz) {
          const auto it = grid.find({c.x + dx, c.y + dy, c.z + dz});
          if (it == grid.end()) continue;
          for (const std::size_t j : it->second) {
            if ((gt.positions_[j] - gt.positions_[i]).squaredNorm() <= r2 &&
                gt.travel_m_[i] - gt.travel_m_[j] >= config.revisit.min_travel_m)
              refs.push_back(j);
          }
        }
    std::sort(refs.begin(), refs.end());
  }
  return gt;
}

LoopGroundTruth LoopGroundTruth::from_pairs(
    std::size_t frame_count, const std::vector<std::pair<std::size_t, std::size_t>>& query_reference) {
  LoopGroundTruth gt;
  gt.references_.resize(frame_count);
  for (const auto& [q, r] : query_reference) {
    if (q >= frame_count || r >= frame_count) {
      throw std::out_of_range("LoopGroundTruth: pair (" + std::to_string(q) + ", " + std::to_string(r) +
                              ") outside " + std::to_string(frame_count) + " frames");
    }
    gt.references_[q].push_back(r);
  }
  for (auto& refs : gt.references_) {
    std::sort(refs.begin(), refs.end());
    refs.erase(std::unique(refs.begin(), refs.end()), refs.end());
  }
  return gt;
}

std::size_t LoopGroundTruth::positive_count() const {
  return static_cast<std::size_t>(
      std::count_if(references_.begin(), references_.end(), [](const auto& refs) { return !refs.empty(); }));
}

bool LoopGroundTruth::is_true_match(std::size_t query, std::size_t reference) const {
  if (query >= references_.size() || reference >= references_.size()) return false;
  if (!positions_.empty()) return within_accept_radius(query, reference) && !without_travel(query, reference);
  const auto& refs = references_[query];
  return std::binary_search(refs.begin(), refs.end(), reference);
}

bool LoopGroundTruth::is_same_place_without_travel(std::size_t query, std::size_t reference) const {
  if (positions_.empty() || query >= positions_.size() || reference >= positions_.size()) return false;
  return within_accept_radius(query, reference) && without_travel(query, reference);
}

bool LoopGroundTruth::within_accept_radius(std::size_t query, std::size_t reference) const {
  const double d = (positions_[query] - positions_[reference]).norm();
  return std::isfinite(d) && d <= accept_radius_m_;
}

bool LoopGroundTruth::without_travel(std::size_t query, std::size_t reference) const {
  return std::abs(travel_m_[query] - travel_m_[reference]) < min_travel_m_;
}

std::vector<std::pair<std::size_t, std::size_t>> LoopGroundTruth::pairs() const {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  for (std::size_t q = 0; q < references_.size(); ++q)
    for (const std::size_t r : references_[q]) out.emplace_back(q, r);
  return out;
}

}  // namespace loopgate
