// Procedural, seed-deterministic textures with a mip pyramid and trilinear filtering.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace loopgate::sim {

// What a texture depicts. Facade styles carry windows, brick courses, plaster, signs, etc.
enum class TextureStyle {
  kFacadeWindows,  // grid of windows with frames, sills and varied panes
  kFacadeBrick,    // brick courses with a few windows and a sign
  kFacadePlaster,  // plaster with stains, doors, posters and signs
  kFacadeShop,     // shop front: large windows, sign band, lettering blocks
  kRoad,           // asphalt with lane markings (u along the road, v across)
  kHallWall,       // industrial wall: panels, pipes, posters, vents
  kHallFloor,      // concrete floor with tiles, markings and stains
  kHallCeiling,    // ceiling beams and lamps
  kPillar,         // painted pillar with stripes and labels
  kCrate,          // wooden / metal crate with slats and stencils
  kMarking,        // worn white road paint
};
const char* to_string(TextureStyle style);

// 8-bit grey texture (albedo in [0, 1] stored as 0..255) with a full mip pyramid (box filter).
class Texture {
 public:
  Texture() = default;
  // texels_0: width_px * height_px values in row-major order (row = v). wrap: tile (repeat) instead
  // of clamping at the borders.
  Texture(int width_px, int height_px, const std::vector<std::uint8_t>& texels_0, bool wrap);

  int width_px() const { return levels_.empty() ? 0 : levels_[0].width_px; }
  int height_px() const { return levels_.empty() ? 0 : levels_[0].height_px; }
  int level_count() const { return static_cast<int>(levels_.size()); }
  bool wrap() const { return wrap_; }

  // Albedo in [0, 1] at level-0 texel coordinates (u_tx, v_tx) (texel centres at +0.5), filtered
  // trilinearly for a pixel footprint of footprint_tx level-0 texels.
  float sample(float u_tx, float v_tx, float footprint_tx) const;
  // Bilinear sample of one mip level (coordinates in level-0 texels).
  float sample_level(int level, float u_tx, float v_tx) const;
  // Raw level-0 texel (for tests).
  std::uint8_t texel(int u, int v) const;

  std::size_t memory_bytes() const;

 private:
  struct Level {
    int width_px = 0;
    int height_px = 0;
    std::vector<std::uint8_t> texels;
  };
  std::vector<Level> levels_;
  bool wrap_ = false;
};

// Builds a texture of the given style, deterministically from the seed. width_m / height_m: the
// physical size the texture covers (layouts such as window grids are laid out in metres).
Texture make_texture(TextureStyle style, std::uint64_t seed, int width_px, int height_px, double width_m,
                     double height_m);

}  // namespace loopgate::sim
