// The painters of the simulator's procedural textures (facades, road, hall surfaces, crates): each draws one
// style onto a canvas addressed in metres, deterministically from its seed.
#include "sim/texture_painters.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "sim/render_random.hpp"
#include "sim/texture_canvas.hpp"

namespace loopgate::sim {
namespace {

using render_detail::hash_combine;
using render_detail::mix64;
using render_detail::Rng;
using render_detail::unit_from_bits;
using texture_detail::Canvas;

// A window with frame, pane, optional mullions / shutters / curtain.
void draw_window(Canvas& c, Rng& rng, double x0, double y0, double x1, double y1, double wall_value) {
  const double frame_m = rng.uniform(0.06, 0.12);
  const double frame_value = std::clamp(wall_value + (rng.chance(0.5) ? 0.3 : -0.3), 0.05, 0.95);
  const double pane_value = rng.uniform(0.06, 0.3);
  // Recess shadow, frame, pane.
  c.rect(x0 - 0.05, y0 - 0.08, x1 + 0.05, y1 + 0.05, wall_value * 0.7);
  c.rect(x0, y0, x1, y1, frame_value);
  c.rect(x0 + frame_m, y0 + frame_m, x1 - frame_m, y1 - frame_m, pane_value);
  // Sky reflection: a lighter diagonal-ish band.
  if (rng.chance(0.6)) {
    const double band = rng.uniform(0.2, 0.6);
    c.rect(x0 + frame_m, y0 + (y1 - y0) * band, x1 - frame_m, y1 - frame_m,
           pane_value + rng.uniform(0.1, 0.3), 0.6);
  }
  const double r = rng.uniform();
  if (r < 0.15) {  // shutters: horizontal slats
    const double slat = 0.1;
    for (double y = y0 + frame_m; y + slat * 0.5 < y1 - frame_m; y += slat) {
      c.rect(x0 + frame_m, y, x1 - frame_m, y + slat * 0.55, frame_value * 0.9);
    }
  } else if (r < 0.35) {  // curtain on one side
    const double cw = (x1 - x0) * rng.uniform(0.25, 0.5);
    const bool left = rng.chance(0.5);
    c.rect(left ? x0 + frame_m : x1 - frame_m - cw, y0 + frame_m, left ? x0 + frame_m + cw : x1 - frame_m,
           y1 - frame_m, rng.uniform(0.55, 0.9));
  }
  if (rng.chance(0.7)) {  // mullions
    const double xm = 0.5 * (x0 + x1);
    c.rect(xm - frame_m * 0.4, y0, xm + frame_m * 0.4, y1, frame_value);
    if (rng.chance(0.5)) {
      const double ym = y0 + (y1 - y0) * rng.uniform(0.55, 0.7);
      c.rect(x0, ym - frame_m * 0.4, x1, ym + frame_m * 0.4, frame_value);
    }
  }
  // Sill.
  c.rect(x0 - 0.1, y0 - 0.1, x1 + 0.1, y0, std::clamp(wall_value + 0.2, 0.0, 1.0));
}

void draw_sign(Canvas& c, Rng& rng, double x0, double y0, double x1, double y1) {
  const bool dark = rng.chance(0.5);
  const double bg = dark ? rng.uniform(0.05, 0.25) : rng.uniform(0.75, 0.95);
  const double fg = dark ? rng.uniform(0.75, 0.95) : rng.uniform(0.05, 0.25);
  c.rect(x0, y0, x1, y1, bg);
  c.frame(x0, y0, x1, y1, 0.05, fg);
  const double margin = (y1 - y0) * 0.2;
  c.lettering(rng, x0 + margin, y0 + margin, x1 - margin, y1 - margin, fg);
}

void draw_door(Canvas& c, Rng& rng, double x0, double x1, double height_m, double wall_value) {
  const double door_value = rng.uniform(0.1, 0.7);
  c.rect(x0 - 0.12, 0.0, x1 + 0.12, height_m + 0.12, std::clamp(wall_value - 0.25, 0.0, 1.0));
  c.rect(x0, 0.0, x1, height_m, door_value);
  const double inset = 0.12;
  const int panels = rng.integer(1, 3);
  const double ph = (height_m - inset * (panels + 1)) / panels;
  for (int p = 0; p < panels; ++p) {
    const double y = inset + p * (ph + inset);
    c.frame(x0 + inset, y, x1 - inset, y + ph, 0.04, door_value * 0.6);
  }
  c.disc(x1 - 0.15, height_m * 0.48, 0.04, 0.9);
}

// Common wall base: tone, low-frequency stains, fine grain.
void wall_base(Canvas& c, Rng& rng, std::uint64_t seed, double value) {
  c.fill(value);
  c.noise(seed ^ 0x11, 0.08, 3.0);
  c.noise(seed ^ 0x22, 0.05, 0.7);
  c.noise(seed ^ 0x33, 0.03, 0.15);
  // Darker weathering near the ground.
  c.noise(seed ^ 0x44, 0.06, 1.2, 0.0, 0.0, c.width_m(), 1.2);
  (void)rng;
}

void facade_windows(Canvas& c, Rng& rng, std::uint64_t seed, bool shop) {
  const double wall = rng.uniform(0.4, 0.85);
  wall_base(c, rng, seed, wall);
  const double floor_h = rng.uniform(2.8, 3.6);
  const double spacing = rng.uniform(1.7, 3.2);
  const double win_w = spacing * rng.uniform(0.4, 0.7);
  const double win_h = floor_h * rng.uniform(0.4, 0.6);
  const double ground_floor_h = shop ? rng.uniform(3.6, 4.4) : floor_h + 0.8;
  const int columns = std::max(1, static_cast<int>((c.width_m() - 0.6) / spacing));
  const double x_start = 0.5 * (c.width_m() - columns * spacing);
  const double top = c.height_m() - 0.8;
  // Floor bands.
  const bool bands = rng.chance(0.6);
  for (double y = ground_floor_h; y + floor_h <= top + 0.01; y += floor_h) {
    if (bands) c.rect(0.0, y - 0.12, c.width_m(), y + 0.06, std::clamp(wall + 0.15, 0.0, 1.0));
    for (int k = 0; k < columns; ++k) {
      const double xc = x_start + (k + 0.5) * spacing;
      const double y0 = y + floor_h * 0.3;
      draw_window(c, rng, xc - 0.5 * win_w, y0, xc + 0.5 * win_w, y0 + win_h, wall);
    }
  }
  // Cornice at the top.
  c.rect(0.0, c.height_m() - 0.5, c.width_m(), c.height_m(), std::clamp(wall - 0.3, 0.0, 1.0));
  c.rect(0.0, c.height_m() - 0.65, c.width_m(), c.height_m() - 0.5, std::clamp(wall + 0.1, 0.0, 1.0));
  // Ground floor.
  if (shop) {
    const double band_y0 = ground_floor_h - 0.9;
    double x = 0.3;
    while (x < c.width_m() - 1.5) {
      const double w = std::min(rng.uniform(1.6, 3.5), c.width_m() - 0.3 - x);
      if (w < 1.0) break;
      if (rng.chance(0.25)) {
        draw_door(c, rng, x + 0.1, x + std::min(w, 1.2) - 0.1, 2.2, wall);
      } else {
        c.rect(x, 0.4, x + w, band_y0 - 0.15, 0.1);
        c.rect(x + 0.08, 0.48, x + w - 0.08, band_y0 - 0.23, rng.uniform(0.1, 0.35));
        // Display items.
        for (int k = 0; k < 3; ++k) {
          const double ix = x + rng.uniform(0.2, w - 0.5);
          c.rect(ix, 0.5, ix + rng.uniform(0.15, 0.35), 0.5 + rng.uniform(0.3, 1.2), rng.uniform(0.3, 0.9));
        }
      }
      x += w + 0.25;
    }
    draw_sign(c, rng, 0.2, band_y0, c.width_m() - 0.2, ground_floor_h - 0.1);
  } else {
    double x = rng.uniform(0.5, 2.0);
    while (x < c.width_m() - 1.5) {
      if (rng.chance(0.35)) {
        draw_door(c, rng, x, x + rng.uniform(0.9, 1.4), rng.uniform(2.1, 2.5), wall);
        x += 2.0;
      } else {
        const double w = rng.uniform(0.8, 1.4);
        draw_window(c, rng, x, 1.0, x + w, 1.0 + rng.uniform(1.0, 1.6), wall);
        x += w + rng.uniform(0.8, 1.8);
      }
    }
    if (rng.chance(0.6)) {
      const double sx = rng.uniform(0.5, std::max(0.6, c.width_m() - 3.5));
      draw_sign(c, rng, sx, ground_floor_h - 1.0, sx + rng.uniform(1.5, 3.0), ground_floor_h - 0.4);
    }
  }
  c.grain(seed ^ 0x55, 0.02);
}

void facade_brick(Canvas& c, Rng& rng, std::uint64_t seed) {
  const double brick = rng.uniform(0.3, 0.65);
  const double mortar = std::clamp(brick + rng.uniform(0.15, 0.3), 0.0, 1.0);
  c.fill(mortar);
  const double course = rng.uniform(0.14, 0.2);
  const double brick_len = course * rng.uniform(2.0, 2.6);
  const double joint = 0.025;
  int row = 0;
  for (double y = 0.0; y < c.height_m(); y += course, ++row) {
    const double shift = (row % 2) ? 0.5 * brick_len : 0.0;
    int col = 0;
    for (double x = -shift; x < c.width_m(); x += brick_len, ++col) {
      const double v =
          brick +
          0.12 *
              (2.0 * unit_from_bits(hash_combine(seed, static_cast<std::uint64_t>(row) * 7919u + col)) - 1.0);
      c.rect(x + joint, y + joint, x + brick_len - joint, y + course - joint, v);
    }
  }
  c.noise(seed ^ 0x66, 0.07, 2.5);
  c.noise(seed ^ 0x77, 0.03, 0.4);
  const double floor_h = rng.uniform(3.0, 3.8);
  const double spacing = rng.uniform(2.6, 4.2);
  const int columns = std::max(1, static_cast<int>((c.width_m() - 1.0) / spacing));
  const double x_start = 0.5 * (c.width_m() - columns * spacing);
  const double win_w = rng.uniform(0.9, 1.4);
  const double win_h = rng.uniform(1.3, 1.9);
  for (double y = floor_h; y + floor_h <= c.height_m() - 0.3; y += floor_h) {
    for (int k = 0; k < columns; ++k) {
      if (rng.chance(0.1)) continue;
      const double xc = x_start + (k + 0.5) * spacing;
      // Lintel.
      c.rect(xc - 0.5 * win_w - 0.15, y + 0.9 + win_h, xc + 0.5 * win_w + 0.15, y + 1.1 + win_h,
             std::clamp(brick + 0.3, 0.0, 1.0));
      draw_window(c, rng, xc - 0.5 * win_w, y + 0.9, xc + 0.5 * win_w, y + 0.9 + win_h, brick);
    }
  }
  // Ground floor: doors, a window, a sign, a drainpipe.
  const double dx = rng.uniform(0.5, std::max(0.6, c.width_m() - 2.0));
  draw_door(c, rng, dx, dx + 1.1, 2.3, brick);
  if (rng.chance(0.7)) {
    const double sx = rng.uniform(0.3, std::max(0.4, c.width_m() - 2.5));
    draw_sign(c, rng, sx, 2.6, sx + rng.uniform(1.2, 2.4), 3.1);
  }
  const double px = rng.uniform(0.1, c.width_m() - 0.2);
  c.rect(px, 0.0, px + 0.1, c.height_m() - 0.3, rng.uniform(0.1, 0.4));
  for (double y = 1.0; y < c.height_m(); y += 2.0) c.rect(px - 0.03, y, px + 0.13, y + 0.06, 0.2);
  c.grain(seed ^ 0x88, 0.025);
}

void facade_plaster(Canvas& c, Rng& rng, std::uint64_t seed) {
  const double wall = rng.uniform(0.5, 0.9);
  wall_base(c, rng, seed, wall);
  c.noise(seed ^ 0x99, 0.1, 5.0);
  // Plinth.
  c.rect(0.0, 0.0, c.width_m(), rng.uniform(0.5, 1.0), std::clamp(wall - 0.3, 0.0, 1.0));
  // Irregular windows.
  const double floor_h = rng.uniform(2.7, 3.4);
  for (double y = floor_h; y + floor_h <= c.height_m() - 0.4; y += floor_h) {
    double x = rng.uniform(0.4, 1.5);
    while (x < c.width_m() - 1.2) {
      const double w = rng.uniform(0.6, 1.5);
      draw_window(c, rng, x, y + 0.8, x + w, y + 0.8 + rng.uniform(1.0, 1.6), wall);
      x += w + rng.uniform(0.9, 2.6);
    }
  }
  // Posters and graffiti on the ground floor.
  double x = rng.uniform(0.2, 1.0);
  while (x < c.width_m() - 1.0) {
    const double r = rng.uniform();
    if (r < 0.3) {
      const double w = rng.uniform(0.5, 1.0);
      const double h = w * rng.uniform(1.2, 1.5);
      const double y0 = rng.uniform(0.8, 1.3);
      c.rect(x, y0, x + w, y0 + h, rng.uniform(0.7, 0.95));
      c.rect(x + 0.05, y0 + h * 0.45, x + w - 0.05, y0 + h - 0.05, rng.uniform(0.1, 0.5));
      c.lettering(rng, x + 0.06, y0 + 0.08, x + w - 0.06, y0 + 0.08 + h * 0.12, 0.1);
      c.lettering(rng, x + 0.06, y0 + 0.1 + h * 0.18, x + w - 0.06, y0 + 0.1 + h * 0.26, 0.15);
      x += w + rng.uniform(0.3, 1.2);
    } else if (r < 0.55) {
      draw_door(c, rng, x, x + rng.uniform(0.9, 1.3), rng.uniform(2.1, 2.4), wall);
      x += rng.uniform(2.0, 3.0);
    } else if (r < 0.75) {
      const double v = rng.uniform(0.05, 0.4);
      for (int k = 0; k < 6; ++k) {
        c.disc(x + rng.uniform(0.0, 1.2), rng.uniform(0.6, 1.8), rng.uniform(0.08, 0.25), v);
      }
      x += 1.6;
    } else {
      draw_sign(c, rng, x, 2.3, x + rng.uniform(1.0, 2.0), 2.75);
      x += 2.5;
    }
  }
  c.grain(seed ^ 0xAA, 0.02);
}

void road(Canvas& c, Rng& rng, std::uint64_t seed) {
  c.set_wrap(true);
  c.fill(0.33);  // same base tone for every variant: no visible seams between ground tiles
  c.noise(seed ^ 0x1, 0.06, 4.0);
  c.noise(seed ^ 0x2, 0.05, 1.0);
  c.noise(seed ^ 0x3, 0.04, 0.25);
  c.noise(seed ^ 0x4, 0.03, 0.06);
  // Patches.
  const int patches = static_cast<int>(c.width_m() * c.height_m() / 40.0) + 2;
  for (int k = 0; k < patches; ++k) {
    const double x = rng.uniform(0.0, c.width_m() - 2.0), y = rng.uniform(0.0, c.height_m() - 2.0);
    const double w = rng.uniform(0.5, 2.0), h = rng.uniform(0.4, 1.8);
    c.rect(x, y, x + w, y + h, rng.uniform(0.15, 0.5), 0.8);
  }
  // Cracks: short random walks of dark squares.
  const int cracks = patches * 2;
  for (int k = 0; k < cracks; ++k) {
    double x = rng.uniform(0.5, c.width_m() - 0.5), y = rng.uniform(0.5, c.height_m() - 0.5);
    double heading = rng.uniform(0.0, 6.283185307179586);
    const int steps = rng.integer(10, 40);
    for (int s = 0; s < steps; ++s) {
      c.rect(x, y, x + 0.03, y + 0.03, 0.08, 0.8);
      heading += rng.uniform(-0.5, 0.5);
      x = std::clamp(x + 0.03 * std::cos(heading), 0.0, c.width_m() - 0.05);
      y = std::clamp(y + 0.03 * std::sin(heading), 0.0, c.height_m() - 0.05);
    }
  }
  // Manhole covers and drains.
  for (int k = 0; k < std::max(1, patches / 3); ++k) {
    const double x = rng.uniform(1.0, c.width_m() - 1.0), y = rng.uniform(1.0, c.height_m() - 1.0);
    c.disc(x, y, 0.35, 0.2);
    c.disc(x, y, 0.3, 0.45);
    for (int g = -2; g <= 2; ++g) c.rect(x - 0.25, y + g * 0.1 - 0.02, x + 0.25, y + g * 0.1 + 0.02, 0.25);
  }
  c.grain(seed ^ 0x5, 0.04);
}

void marking(Canvas& c, Rng& rng, std::uint64_t seed) {
  c.fill(rng.uniform(0.82, 0.92));
  c.noise(seed ^ 0x1, 0.08, 0.3);
  c.grain(seed ^ 0x2, 0.03);
}

void hall_wall(Canvas& c, Rng& rng, std::uint64_t seed) {
  const double wall = rng.uniform(0.45, 0.8);
  wall_base(c, rng, seed, wall);
  // Corrugated vertical panels.
  const double panel = rng.uniform(0.6, 1.2);
  for (double x = 0.0; x < c.width_m(); x += panel) {
    c.rect(x, 0.0, x + 0.03, c.height_m(), std::clamp(wall - 0.2, 0.0, 1.0));
    c.rect(x + 0.03, 0.0, x + 0.06, c.height_m(), std::clamp(wall + 0.1, 0.0, 1.0));
  }
  // Hazard stripes at the bottom.
  const double stripe_h = rng.uniform(0.3, 0.6);
  for (double x = -1.0; x < c.width_m(); x += 0.4) {
    for (double y = 0.0; y < stripe_h; y += 0.05) c.rect(x + y, y, x + y + 0.2, y + 0.05, 0.1);
  }
  c.rect(0.0, stripe_h, c.width_m(), stripe_h + 0.05, 0.85);
  // Pipes.
  const int pipes = rng.integer(1, 3);
  for (int p = 0; p < pipes; ++p) {
    const double y = rng.uniform(1.5, c.height_m() - 0.5);
    const double r = rng.uniform(0.05, 0.15);
    c.rect(0.0, y - r, c.width_m(), y + r, 0.3);
    c.rect(0.0, y, c.width_m(), y + r * 0.6, 0.6);
    for (double x = rng.uniform(0.0, 1.0); x < c.width_m(); x += rng.uniform(1.0, 2.5)) {
      c.rect(x, y - r - 0.04, x + 0.06, y + r + 0.04, 0.15);
    }
  }
  // Posters, vents, signs, boxes.
  const int items = std::max(2, static_cast<int>(c.width_m() * 1.2));
  for (int k = 0; k < items; ++k) {
    const double x = rng.uniform(0.0, std::max(0.1, c.width_m() - 1.0));
    const double y = rng.uniform(0.8, std::max(0.9, c.height_m() - 1.5));
    const double r = rng.uniform();
    if (r < 0.3) {
      const double w = rng.uniform(0.4, 0.9);
      c.rect(x, y, x + w, y + w * 1.3, rng.uniform(0.75, 0.95));
      c.lettering(rng, x + 0.05, y + w * 1.0, x + w - 0.05, y + w * 1.2, 0.1);
      c.rect(x + 0.05, y + 0.05, x + w - 0.05, y + w * 0.9, rng.uniform(0.1, 0.6));
    } else if (r < 0.5) {
      const double w = rng.uniform(0.4, 0.8);
      c.rect(x, y, x + w, y + w, 0.25);
      for (double yy = y + 0.05; yy < y + w - 0.05; yy += 0.08)
        c.rect(x + 0.05, yy, x + w - 0.05, yy + 0.04, 0.05);
    } else if (r < 0.75) {
      draw_sign(c, rng, x, y, x + rng.uniform(0.6, 1.4), y + rng.uniform(0.25, 0.45));
    } else {
      const double w = rng.uniform(0.2, 0.5);
      c.rect(x, y, x + w, y + w * 1.4, rng.uniform(0.05, 0.95));
      c.frame(x, y, x + w, y + w * 1.4, 0.03, 0.1);
      c.disc(x + w * 0.5, y + w * 0.7, w * 0.2, rng.uniform(0.0, 1.0));
    }
  }
  c.grain(seed ^ 0xBB, 0.02);
}

void hall_floor(Canvas& c, Rng& rng, std::uint64_t seed) {
  c.fill(rng.uniform(0.4, 0.6));
  c.noise(seed ^ 0x1, 0.08, 2.0);
  c.noise(seed ^ 0x2, 0.05, 0.4);
  c.noise(seed ^ 0x3, 0.03, 0.08);
  const double tile = rng.uniform(0.8, 1.5);
  for (double x = 0.0; x < c.width_m(); x += tile) c.rect(x, 0.0, x + 0.02, c.height_m(), 0.25);
  for (double y = 0.0; y < c.height_m(); y += tile) c.rect(0.0, y, c.width_m(), y + 0.02, 0.25);
  // Painted lines and arrows.
  const double line_y = rng.uniform(0.5, c.height_m() - 0.5);
  c.rect(0.0, line_y, c.width_m(), line_y + 0.1, 0.85);
  for (int k = 0; k < 3; ++k) {
    const double x = rng.uniform(0.3, std::max(0.4, c.width_m() - 1.0));
    const double y = rng.uniform(0.3, std::max(0.4, c.height_m() - 1.0));
    c.rect(x, y, x + 0.5, y + 0.15, 0.85);
    c.rect(x + 0.4, y - 0.1, x + 0.5, y + 0.25, 0.85);
  }
  for (int k = 0; k < 8; ++k) {
    c.disc(rng.uniform(0.0, c.width_m()), rng.uniform(0.0, c.height_m()), rng.uniform(0.1, 0.5),
           rng.uniform(0.15, 0.35));
  }
  c.grain(seed ^ 0x4, 0.03);
}

void hall_ceiling(Canvas& c, Rng& rng, std::uint64_t seed) {
  c.fill(rng.uniform(0.35, 0.55));
  c.noise(seed ^ 0x1, 0.06, 1.5);
  const double beam = rng.uniform(1.5, 2.5);
  for (double x = 0.0; x < c.width_m(); x += beam) c.rect(x, 0.0, x + 0.25, c.height_m(), 0.15);
  for (double y = 0.5; y < c.height_m(); y += rng.uniform(2.0, 3.5)) {
    const double x = rng.uniform(0.3, std::max(0.4, c.width_m() - 1.5));
    c.rect(x, y, x + 1.2, y + 0.3, 0.95);
    c.frame(x, y, x + 1.2, y + 0.3, 0.04, 0.2);
  }
  c.grain(seed ^ 0x2, 0.02);
}

void pillar(Canvas& c, Rng& rng, std::uint64_t seed) {
  const double base = rng.uniform(0.4, 0.85);
  c.fill(base);
  c.noise(seed ^ 0x1, 0.06, 0.8);
  c.noise(seed ^ 0x2, 0.03, 0.1);
  for (double y = 0.0; y < 1.2; y += 0.3) c.rect(0.0, y, c.width_m(), y + 0.15, 0.1);
  const double label_y = rng.uniform(1.6, 2.4);
  c.rect(0.05, label_y, c.width_m() - 0.05, label_y + 0.35, 0.9);
  c.lettering(rng, 0.1, label_y + 0.07, c.width_m() - 0.1, label_y + 0.28, 0.1);
  for (double y = 3.0; y < c.height_m(); y += rng.uniform(1.5, 3.0)) {
    c.rect(0.0, y, c.width_m(), y + 0.08, std::clamp(base - 0.3, 0.0, 1.0));
    c.disc(0.1, y + 0.2, 0.03, 0.2);
    c.disc(c.width_m() - 0.1, y + 0.2, 0.03, 0.2);
  }
  c.grain(seed ^ 0x3, 0.02);
}

void crate(Canvas& c, Rng& rng, std::uint64_t seed) {
  const double wood = rng.uniform(0.35, 0.75);
  c.fill(wood);
  const double slat = rng.uniform(0.12, 0.2);
  int row = 0;
  for (double y = 0.0; y < c.height_m(); y += slat, ++row) {
    const double v =
        wood + 0.1 * (2.0 * unit_from_bits(hash_combine(seed, static_cast<std::uint64_t>(row))) - 1.0);
    c.rect(0.0, y + 0.01, c.width_m(), y + slat - 0.01, v);
  }
  c.noise(seed ^ 0x1, 0.05, 0.05);
  const double edge = 0.08;
  c.frame(0.0, 0.0, c.width_m(), c.height_m(), edge, std::clamp(wood - 0.2, 0.0, 1.0));
  // Diagonal brace from small squares.
  for (double t = 0.0; t < 1.0; t += 0.01) {
    const double x = edge + t * (c.width_m() - 2 * edge), y = edge + t * (c.height_m() - 2 * edge);
    c.rect(x - 0.04, y - 0.04, x + 0.04, y + 0.04, std::clamp(wood - 0.15, 0.0, 1.0));
  }
  const double w = c.width_m() * 0.5;
  const double y = c.height_m() * rng.uniform(0.55, 0.75);
  c.lettering(rng, c.width_m() * 0.25, y, c.width_m() * 0.25 + w, y + std::min(0.18, c.height_m() * 0.15),
              0.08);
  c.grain(seed ^ 0x2, 0.03);
}

}  // namespace

PaintedTexture paint_texture(TextureStyle style, std::uint64_t seed, int width_px, int height_px,
                             double width_m, double height_m) {
  Canvas canvas(width_px, height_px, std::max(width_m, 1e-3), std::max(height_m, 1e-3));
  Rng rng(hash_combine(seed, static_cast<std::uint64_t>(style) + 1u));
  const std::uint64_t noise_seed = mix64(seed ^ 0xC0FFEEull);
  bool wrap = false;
  switch (style) {
    case TextureStyle::kFacadeWindows: facade_windows(canvas, rng, noise_seed, false); break;
    case TextureStyle::kFacadeShop: facade_windows(canvas, rng, noise_seed, true); break;
    case TextureStyle::kFacadeBrick: facade_brick(canvas, rng, noise_seed); break;
    case TextureStyle::kFacadePlaster: facade_plaster(canvas, rng, noise_seed); break;
    case TextureStyle::kRoad:
      road(canvas, rng, noise_seed);
      wrap = true;
      break;
    case TextureStyle::kMarking: marking(canvas, rng, noise_seed); break;
    case TextureStyle::kHallWall: hall_wall(canvas, rng, noise_seed); break;
    case TextureStyle::kHallFloor: hall_floor(canvas, rng, noise_seed); break;
    case TextureStyle::kHallCeiling: hall_ceiling(canvas, rng, noise_seed); break;
    case TextureStyle::kPillar: pillar(canvas, rng, noise_seed); break;
    case TextureStyle::kCrate: crate(canvas, rng, noise_seed); break;
  }
  return {canvas.to_bytes(), wrap};
}

}  // namespace loopgate::sim
