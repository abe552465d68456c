#pragma once
// The procedural painters behind make_texture (texture.hpp), kept apart from the mip-mapped Texture.
#include <cstdint>
#include <vector>

#include "sim/texture.hpp"

namespace loopgate::sim {

struct PaintedTexture {
  std::vector<std::uint8_t> texels;  // width_px x height_px, row-major, as Texture takes them
  bool wrap = false;                 // the style tiles (road)
};

// Paints `style` at width_px x height_px over width_m x height_m (sizes at least 1 px and 1 mm),
// deterministic in `seed`.
PaintedTexture paint_texture(TextureStyle style, std::uint64_t seed, int width_px, int height_px,
                             double width_m, double height_m);

}  // namespace loopgate::sim
