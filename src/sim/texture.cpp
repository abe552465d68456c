#include "sim/texture.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "sim/texture_painters.hpp"

namespace loopgate::sim {
namespace {

// Cheap, deterministic log2 for mip selection: exponent plus a linear mantissa.
float fast_log2(float x) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &x, sizeof(bits));
  const float exponent = static_cast<float>(static_cast<int>((bits >> 23) & 0xFFu) - 127);
  bits = (bits & 0x007FFFFFu) | 0x3F800000u;
  float mantissa = 0.0f;
  std::memcpy(&mantissa, &bits, sizeof(mantissa));
  return exponent + (mantissa - 1.0f);
}

}  // namespace

const char* to_string(TextureStyle style) {
  switch (style) {
    case TextureStyle::kFacadeWindows: return "facade-windows";
    case TextureStyle::kFacadeBrick: return "facade-brick";
    case TextureStyle::kFacadePlaster: return "facade-plaster";
    case TextureStyle::kFacadeShop: return "facade-shop";
    case TextureStyle::kRoad: return "road";
    case TextureStyle::kHallWall: return "hall-wall";
    case TextureStyle::kHallFloor: return "hall-floor";
    case TextureStyle::kHallCeiling: return "hall-ceiling";
    case TextureStyle::kPillar: return "pillar";
    case TextureStyle::kCrate: return "crate";
    case TextureStyle::kMarking: return "marking";
  }
  return "unknown";
}

Texture::Texture(int width_px, int height_px, const std::vector<std::uint8_t>& texels_0, bool wrap)
    : wrap_(wrap) {
  Level level0;
  level0.width_px = std::max(1, width_px);
  level0.height_px = std::max(1, height_px);
  level0.texels = texels_0;
  level0.texels.resize(static_cast<std::size_t>(level0.width_px) * static_cast<std::size_t>(level0.height_px),
                       128);
  levels_.push_back(std::move(level0));
  while (levels_.back().width_px > 1 || levels_.back().height_px > 1) {
    const Level& prev = levels_.back();
    Level next;
    next.width_px = std::max(1, (prev.width_px + 1) / 2);
    next.height_px = std::max(1, (prev.height_px + 1) / 2);
    next.texels.resize(static_cast<std::size_t>(next.width_px) * static_cast<std::size_t>(next.height_px));
    for (int j = 0; j < next.height_px; ++j) {
      const int j0 = std::min(2 * j, prev.height_px - 1), j1 = std::min(2 * j + 1, prev.height_px - 1);
      for (int i = 0; i < next.width_px; ++i) {
        const int i0 = std::min(2 * i, prev.width_px - 1), i1 = std::min(2 * i + 1, prev.width_px - 1);
        const auto px = [&](int ii, int jj) {
          return static_cast<unsigned>(prev.texels[static_cast<std::size_t>(jj) * prev.width_px + ii]);
        };
        next.texels[static_cast<std::size_t>(j) * next.width_px + i] =
            static_cast<std::uint8_t>((px(i0, j0) + px(i1, j0) + px(i0, j1) + px(i1, j1) + 2u) / 4u);
      }
    }
    levels_.push_back(std::move(next));
  }
}

std::uint8_t Texture::texel(int u, int v) const {
  const Level& l = levels_.at(0);
  return l.texels.at(static_cast<std::size_t>(v) * l.width_px + u);
}

std::size_t Texture::memory_bytes() const {
  std::size_t bytes = 0;
  for (const Level& l : levels_) bytes += l.texels.size();
  return bytes;
}

float Texture::sample_level(int level, float u_tx, float v_tx) const {
  const Level& l = levels_[static_cast<std::size_t>(level)];
  const float scale = 1.0f / static_cast<float>(1 << level);
  const float x = u_tx * scale - 0.5f;
  const float y = v_tx * scale - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float tx = x - fx, ty = y - fy;
  int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  int x1 = x0 + 1, y1 = y0 + 1;
  const int w = l.width_px, h = l.height_px;
  if (wrap_) {
    x0 %= w;
    if (x0 < 0) x0 += w;
    y0 %= h;
    if (y0 < 0) y0 += h;
    x1 = x0 + 1 == w ? 0 : x0 + 1;
    y1 = y0 + 1 == h ? 0 : y0 + 1;
  } else {
    x0 = std::clamp(x0, 0, w - 1);
    x1 = std::clamp(x1, 0, w - 1);
    y0 = std::clamp(y0, 0, h - 1);
    y1 = std::clamp(y1, 0, h - 1);
  }
  const std::uint8_t* row0 = l.texels.data() + static_cast<std::size_t>(y0) * w;
  const std::uint8_t* row1 = l.texels.data() + static_cast<std::size_t>(y1) * w;
  const float a = row0[x0], b = row0[x1], c = row1[x0], d = row1[x1];
  const float top = a + (b - a) * tx;
  const float bottom = c + (d - c) * tx;
  return (top + (bottom - top) * ty) * (1.0f / 255.0f);
}

float Texture::sample(float u_tx, float v_tx, float footprint_tx) const {
  const int max_level = static_cast<int>(levels_.size()) - 1;
  const float lod = footprint_tx > 1.0f ? fast_log2(footprint_tx) : 0.0f;
  int l0 = static_cast<int>(lod);
  if (l0 >= max_level) return sample_level(max_level, u_tx, v_tx);
  const float frac = lod - static_cast<float>(l0);
  const float s0 = sample_level(l0, u_tx, v_tx);
  if (frac < 1.0f / 64.0f) return s0;
  const float s1 = sample_level(l0 + 1, u_tx, v_tx);
  return s0 + (s1 - s0) * frac;
}

Texture make_texture(TextureStyle style, std::uint64_t seed, int width_px, int height_px, double width_m,
                     double height_m) {
  width_px = std::max(1, width_px);
  height_px = std::max(1, height_px);
  PaintedTexture painted = paint_texture(style, seed, width_px, height_px, width_m, height_m);
  return Texture(width_px, height_px, painted.texels, painted.wrap);
}

}  // namespace loopgate::sim
