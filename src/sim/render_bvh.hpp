// Private helper of the world/renderer: BVH over quads (build) and closest-hit traversal (inline, hot path).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "sim/world.hpp"

namespace loopgate::sim::render_detail {

constexpr int kBvhStackSize = 64;
constexpr float kEdgeToleranceM = 1e-3f;  // closes hairline cracks between neighbouring patches

void build_bvh(const std::vector<Quad>& quads, std::vector<BvhNode>* nodes, std::vector<int>* quad_index);

// Ray-quad test; updates *t_best and the local (a, b) in metres on a closer hit.
inline bool hit_quad(const Quad& q, const Eigen::Vector3f& o, const Eigen::Vector3f& d, float t_min,
                     float* t_best, float* a_m, float* b_m) {
  const float denom = q.normal_w.dot(d);
  if (std::abs(denom) < 1e-12f) return false;
  const Eigen::Vector3f rel = q.origin_w - o;
  const float t = q.normal_w.dot(rel) / denom;
  if (!(t > t_min) || !(t < *t_best)) return false;
  const Eigen::Vector3f p = d * t - rel;
  const float a = p.dot(q.dual_u_w);
  if (a < -kEdgeToleranceM || a > q.width_m + kEdgeToleranceM) return false;
  const float b = p.dot(q.dual_v_w);
  if (b < -kEdgeToleranceM || b > q.height_m + kEdgeToleranceM) return false;
  if (q.triangle &&
      a * q.height_m + b * q.width_m > q.width_m * q.height_m + kEdgeToleranceM * (q.width_m + q.height_m)) {
    return false;
  }
  *t_best = t;
  *a_m = a;
  *b_m = b;
  return true;
}

// Closest hit: returns the quad index (or -1), *t_hit and the hit point in quad metres (a, b).
// hint_quad (>= 0): a quad likely to be hit (e.g. the neighbouring pixel's); testing it first bounds the
// traversal. The result is the same closest hit whatever the hint, except between exactly equal distances.
inline int closest_hit(const World& world, const Eigen::Vector3f& o, const Eigen::Vector3f& d, float t_min,
                       float t_max, float* t_hit, float* a_m, float* b_m, int hint_quad = -1) {
  if (world.bvh_nodes.empty()) return -1;
  const float inv[3] = {1.0f / d.x(), 1.0f / d.y(), 1.0f / d.z()};
  const float org[3] = {o.x(), o.y(), o.z()};
  const BvhNode* nodes = world.bvh_nodes.data();
  const int* index = world.bvh_quad_index.data();
  const Quad* quads = world.quads.data();
  int stack[kBvhStackSize];
  int top = 0;
  stack[top++] = 0;
  float best = t_max;
  int best_quad = -1;
  if (hint_quad >= 0 &&
      hit_quad(world.quads[static_cast<std::size_t>(hint_quad)], o, d, t_min, &best, a_m, b_m)) {
    best_quad = hint_quad;
  }
  const auto box_entry = [&](const BvhNode& n) {
    float t0 = t_min, t1 = best;
    for (int k = 0; k < 3; ++k) {
      float near = (n.min[k] - org[k]) * inv[k];
      float far = (n.max[k] - org[k]) * inv[k];
      if (near > far) std::swap(near, far);
      t0 = near > t0 ? near : t0;  // NaN-safe: a NaN never tightens
      t1 = far < t1 ? far : t1;
    }
    return t0 <= t1 ? t0 : -1.0f;
  };
  while (top > 0) {
    const BvhNode& n = nodes[stack[--top]];
    if (n.count > 0) {
      for (int k = 0; k < n.count; ++k) {
        const int qi = index[n.left_or_first + k];
        if (qi != hint_quad && hit_quad(quads[qi], o, d, t_min, &best, a_m, b_m)) best_quad = qi;
      }
      continue;
    }
    const int left = n.left_or_first;
    const float tl = box_entry(nodes[left]);
    const float tr = box_entry(nodes[left + 1]);
    if (tl >= 0.0f && tr >= 0.0f) {
      // Push the farther first so the nearer is visited first.
      if (tl <= tr) {
        stack[top++] = left + 1;
        stack[top++] = left;
      } else {
        stack[top++] = left;
        stack[top++] = left + 1;
      }
    } else if (tl >= 0.0f) {
      stack[top++] = left;
    } else if (tr >= 0.0f) {
      stack[top++] = left + 1;
    }
  }
  *t_hit = best;
  return best_quad;
}

int intersect_bvh(const World& world, const Eigen::Vector3f& origin_w, const Eigen::Vector3f& dir_w,
                  float t_min, float t_max, float* t_hit, float* u_tx, float* v_tx);

}  // namespace loopgate::sim::render_detail
