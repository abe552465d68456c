#include "sim/render_bvh.hpp"

#include <limits>
#include <numeric>

namespace loopgate::sim::render_detail {
namespace {

constexpr int kLeafSize = 2;
constexpr int kMaxLeafSize = 8;
constexpr int kSahBins = 16;
constexpr float kBoxPadM = 1e-3f;

struct QuadBox {
  Eigen::Vector3f lo, hi, centroid;
};

QuadBox box_of(const Quad& q) {
  const Eigen::Vector3f du = q.axis_u_w * q.width_m;
  const Eigen::Vector3f dv = q.axis_v_w * q.height_m;  // (a triangle's box is its parallelogram's)
  QuadBox b;
  b.lo = q.origin_w.cwiseMin(q.origin_w + du).cwiseMin(q.origin_w + dv).cwiseMin(q.origin_w + du + dv);
  b.hi = q.origin_w.cwiseMax(q.origin_w + du).cwiseMax(q.origin_w + dv).cwiseMax(q.origin_w + du + dv);
  b.lo.array() -= kBoxPadM;
  b.hi.array() += kBoxPadM;
  b.centroid = 0.5f * (b.lo + b.hi);
  return b;
}

void build_node(int node, int first, int count, const std::vector<QuadBox>& boxes,
                std::vector<BvhNode>* nodes, std::vector<int>* index) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(1e30f), hi = Eigen::Vector3f::Constant(-1e30f);
  Eigen::Vector3f clo = lo, chi = hi;
  for (int k = first; k < first + count; ++k) {
    const QuadBox& b = boxes[static_cast<std::size_t>((*index)[static_cast<std::size_t>(k)])];
    lo = lo.cwiseMin(b.lo);
    hi = hi.cwiseMax(b.hi);
    clo = clo.cwiseMin(b.centroid);
    chi = chi.cwiseMax(b.centroid);
  }
  BvhNode& n = (*nodes)[static_cast<std::size_t>(node)];
  for (int k = 0; k < 3; ++k) {
    n.min[k] = lo[k];
    n.max[k] = hi[k];
  }
  if (count <= kLeafSize) {
    n.left_or_first = first;
    n.count = count;
    return;
  }
  // Binned surface-area heuristic over the centroid bounds of the three axes.
  const auto area = [](const Eigen::Vector3f& l, const Eigen::Vector3f& h) {
    const Eigen::Vector3f e = (h - l).cwiseMax(0.0f);
    return e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
  };
  float best_cost = std::numeric_limits<float>::infinity();
  int best_axis = -1;
  float best_split = 0.0f;
  for (int axis = 0; axis < 3; ++axis) {
    const float extent = chi[axis] - clo[axis];
    if (!(extent > 0.0f)) continue;
    Eigen::Vector3f bin_lo[kSahBins], bin_hi[kSahBins];
    int bin_count[kSahBins] = {};
    for (int b = 0; b < kSahBins; ++b) {
      bin_lo[b] = Eigen::Vector3f::Constant(1e30f);
      bin_hi[b] = Eigen::Vector3f::Constant(-1e30f);
    }
    const float scale = kSahBins / extent;
    for (int k = first; k < first + count; ++k) {
      const QuadBox& qb = boxes[static_cast<std::size_t>((*index)[static_cast<std::size_t>(k)])];
      const int b = std::min(kSahBins - 1, static_cast<int>((qb.centroid[axis] - clo[axis]) * scale));
      ++bin_count[b];
      bin_lo[b] = bin_lo[b].cwiseMin(qb.lo);
      bin_hi[b] = bin_hi[b].cwiseMax(qb.hi);
    }
    float right_area[kSahBins];
    int right_count[kSahBins];
    Eigen::Vector3f rl = Eigen::Vector3f::Constant(1e30f), rh = Eigen::Vector3f::Constant(-1e30f);
    int rc = 0;
    for (int b = kSahBins - 1; b > 0; --b) {
      rl = rl.cwiseMin(bin_lo[b]);
      rh = rh.cwiseMax(bin_hi[b]);
      rc += bin_count[b];
      right_area[b] = area(rl, rh);
      right_count[b] = rc;
    }
    Eigen::Vector3f ll = Eigen::Vector3f::Constant(1e30f), lh = Eigen::Vector3f::Constant(-1e30f);
    int lc = 0;
    for (int b = 0; b < kSahBins - 1; ++b) {
      ll = ll.cwiseMin(bin_lo[b]);
      lh = lh.cwiseMax(bin_hi[b]);
      lc += bin_count[b];
      if (lc == 0 || right_count[b + 1] == 0) continue;
      const float cost = lc * area(ll, lh) + right_count[b + 1] * right_area[b + 1];
      if (cost < best_cost) {
        best_cost = cost;
        best_axis = axis;
        best_split = clo[axis] + (b + 1) / scale;
      }
    }
  }
  int mid = first;
  if (best_axis >= 0) {
    const auto it = std::partition(index->begin() + first, index->begin() + first + count, [&](int q) {
      return boxes[static_cast<std::size_t>(q)].centroid[best_axis] < best_split;
    });
    mid = static_cast<int>(it - index->begin());
  }
  if (mid == first || mid == first + count) {
    // Degenerate (all centroids equal): split the list in half.
    if (count <= kMaxLeafSize) {
      n.left_or_first = first;
      n.count = count;
      return;
    }
    mid = first + count / 2;
  }
  const int left = static_cast<int>(nodes->size());
  nodes->emplace_back();
  nodes->emplace_back();
  (*nodes)[static_cast<std::size_t>(node)].left_or_first = left;
  (*nodes)[static_cast<std::size_t>(node)].count = 0;
  build_node(left, first, mid - first, boxes, nodes, index);
  build_node(left + 1, mid, first + count - mid, boxes, nodes, index);
}

}  // namespace

void build_bvh(const std::vector<Quad>& quads, std::vector<BvhNode>* nodes, std::vector<int>* quad_index) {
  nodes->clear();
  quad_index->assign(quads.size(), 0);
  std::iota(quad_index->begin(), quad_index->end(), 0);
  if (quads.empty()) return;
  std::vector<QuadBox> boxes;
  boxes.reserve(quads.size());
  for (const Quad& q : quads) boxes.push_back(box_of(q));
  nodes->reserve(2 * quads.size());
  nodes->emplace_back();
  build_node(0, 0, static_cast<int>(quads.size()), boxes, nodes, quad_index);
}

int intersect_bvh(const World& world, const Eigen::Vector3f& origin_w, const Eigen::Vector3f& dir_w,
                  float t_min, float t_max, float* t_hit, float* u_tx, float* v_tx) {
  float a_m = 0, b_m = 0;
  const int qi = closest_hit(world, origin_w, dir_w, t_min, t_max, t_hit, &a_m, &b_m);
  if (qi >= 0) {
    const Quad& q = world.quads[static_cast<std::size_t>(qi)];
    *u_tx = q.u_offset_tx + q.u_sign * a_m * q.texels_per_m;
    *v_tx = q.v_offset_tx + q.v_sign * b_m * q.texels_per_m;
  }
  return qi;
}

}  // namespace loopgate::sim::render_detail
