// Light sources of the lamps night model (illumination.night_model = lamps): street lamps on the kerb
// posts, a grid of ceiling lamps in the hall, and a headlight attached to the camera, switched by the
// illumination schedule; and the per-frame lighting (schedule + lights + sensor) the simulator renders with.
// Section "lights".
//
// A light is a spot: irradiance intensity * spot * window * max(0, n . l) / d^2 at a surface point at
// distance d (inverse square), where spot is 1 inside the inner cone and falls smoothly (smoothstep) to 0 at
// the outer cone (elliptical for the headlight: wide and flat), and window = (1 - (d / range_m)^4)^2 ends
// the light's reach smoothly. Lambert term only: no shadows. Intensities are in the units of
// illumination.ambient (irradiance; a surface's radiance is albedo x irradiance): a street lamp of intensity
// 3 at 6.3 m gives 0.076 below it, the day's ambient is 0.35. A lamp's head is visible: a small disc of
// constant radiance with a glare halo around it (lens veiling glare, falling off as 1 / angle^2).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <vector>

#include "sim/illumination.hpp"
#include "sim/sensor.hpp"
#include "sim/world.hpp"

namespace loopgate::sim {

struct LightsConfig {
  // Street: one lamp per kerb post (world.street_pole_spacing_m; none without posts), a lantern this far
  // above the post's top and towards the road, its cone axis tilted from straight down towards the road.
  double street_lamp_intensity = 3.0;
  double street_lamp_above_post_m = 0.3;
  double street_lamp_arm_m = 1.5;
  double street_lamp_tilt_deg = 15.0;
  double street_lamp_cone_deg = 70.0;   // outer half-angle of the cone
  double street_lamp_inner_deg = 45.0;  // full intensity within this half-angle
  double street_lamp_range_m = 40.0;
  // Hall: a grid of ceiling lamps pointing down, about hall_lamp_spacing_m apart, hanging below the ceiling.
  double hall_lamp_spacing_m = 10.0;
  double hall_lamp_below_ceiling_m = 0.6;
  double hall_lamp_intensity = 2.0;
  double hall_lamp_cone_deg = 45.0;
  double hall_lamp_inner_deg = 20.0;
  double hall_lamp_range_m = 25.0;
  // Every lamp: a seeded random intensity spread (+- this fraction), a seeded fraction of lamps out for the
  // night, the visible head (radius, radiance, glare strength), and the night factor (0 day .. 1 night of
  // the illumination schedule) from which the lamps are on.
  double lamp_intensity_jitter = 0.15;
  double lamp_out_fraction = 0.1;
  double lamp_head_radius_m = 0.25;
  double lamp_head_radiance = 20.0;
  double lamp_glare = 0.003;
  double lamps_on_night_factor = 0.5;
  // Headlight (street): a spot on the vehicle, below and ahead of the camera, pointing forward and pitched
  // down, wide and flat (low beam); on from headlight_on_night_factor. Hall: a round spot at the camera
  // (hall_headlight_*, with headlight_inner_fraction and headlight_on_night_factor).
  double headlight_intensity = 100.0;
  double headlight_below_camera_m = 0.9;
  double headlight_ahead_m = 1.0;
  double headlight_pitch_deg = 1.0;  // down
  double headlight_half_width_deg = 25.0;
  double headlight_half_height_deg = 7.0;
  double headlight_inner_fraction = 0.3;  // full intensity within this fraction of the outer ellipse
  double headlight_range_m = 90.0;
  double hall_headlight_intensity = 0.3;
  double hall_headlight_cone_deg = 25.0;
  double hall_headlight_range_m = 20.0;
  double headlight_on_night_factor = 0.3;
  // Night end points of the lamps model, replacing illumination.night_ambient / night_sky_brightness (the
  // ambient-only night had to be bright enough to see anything; under lamps the night is dark between them).
  double night_ambient = 0.001;
  double night_sky_brightness = 0.0015;
  // Lamps farther than this from the camera are not rendered (neither their light nor their head).
  double cull_distance_m = 250.0;

  // The keys, in order, for loading, printing and the JSON echo (Self is LightsConfig or const LightsConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("street_lamp_intensity", self.street_lamp_intensity);
    v("street_lamp_above_post_m", self.street_lamp_above_post_m);
    v("street_lamp_arm_m", self.street_lamp_arm_m);
    v("street_lamp_tilt_deg", self.street_lamp_tilt_deg);
    v("street_lamp_cone_deg", self.street_lamp_cone_deg);
    v("street_lamp_inner_deg", self.street_lamp_inner_deg);
    v("street_lamp_range_m", self.street_lamp_range_m);
    v("hall_lamp_spacing_m", self.hall_lamp_spacing_m);
    v("hall_lamp_below_ceiling_m", self.hall_lamp_below_ceiling_m);
    v("hall_lamp_intensity", self.hall_lamp_intensity);
    v("hall_lamp_cone_deg", self.hall_lamp_cone_deg);
    v("hall_lamp_inner_deg", self.hall_lamp_inner_deg);
    v("hall_lamp_range_m", self.hall_lamp_range_m);
    v("lamp_intensity_jitter", self.lamp_intensity_jitter);
    v("lamp_out_fraction", self.lamp_out_fraction);
    v("lamp_head_radius_m", self.lamp_head_radius_m);
    v("lamp_head_radiance", self.lamp_head_radiance);
    v("lamp_glare", self.lamp_glare);
    v("lamps_on_night_factor", self.lamps_on_night_factor);
    v("headlight_intensity", self.headlight_intensity);
    v("headlight_below_camera_m", self.headlight_below_camera_m);
    v("headlight_ahead_m", self.headlight_ahead_m);
    v("headlight_pitch_deg", self.headlight_pitch_deg);
    v("headlight_half_width_deg", self.headlight_half_width_deg);
    v("headlight_half_height_deg", self.headlight_half_height_deg);
    v("headlight_inner_fraction", self.headlight_inner_fraction);
    v("headlight_range_m", self.headlight_range_m);
    v("hall_headlight_intensity", self.hall_headlight_intensity);
    v("hall_headlight_cone_deg", self.hall_headlight_cone_deg);
    v("hall_headlight_range_m", self.hall_headlight_range_m);
    v("headlight_on_night_factor", self.headlight_on_night_factor);
    v("night_ambient", self.night_ambient);
    v("night_sky_brightness", self.night_sky_brightness);
    v("cull_distance_m", self.cull_distance_m);
  }
  void validate() const;  // throws loopgate::ConfigError naming the key
};

// A spot light in the world frame. The cone: a direction l from the light makes tangent-plane coordinates
// (l . side_w, l . across_w) / (l . axis_w); scaled by tan_half_width / tan_half_height they give the radius
// r (1 = the outer edge); the spot factor is 1 for r <= inner_fraction, 0 for r >= 1, smoothstep between.
struct SpotLight {
  Eigen::Vector3f position_w = Eigen::Vector3f::Zero();
  Eigen::Vector3f axis_w = -Eigen::Vector3f::UnitZ();   // unit, the direction the light points
  Eigen::Vector3f side_w = Eigen::Vector3f::UnitX();    // unit, perpendicular to axis_w
  Eigen::Vector3f across_w = Eigen::Vector3f::UnitY();  // unit, axis_w x side_w
  float intensity = 0.0f;  // irradiance at 1 m on the axis, on a surface facing the light
  float tan_half_width = 1.0f;
  float tan_half_height = 1.0f;
  float inner_fraction = 0.5f;
  float range_m = 40.0f;
  float head_radius_m = 0.0f;  // visible head (0: not drawn, e.g. a headlight)
  float head_radiance = 0.0f;
  float glare =
      0.0f;  // halo radiance at angle theta: glare * head_radiance * a^2 / (theta^2 + a^2), a = r / d
};

// Irradiance the light gives a surface point p_w of unit normal n_w (the side the light must be on).
// Cheapest rejections first (range, behind the light, outside the cone, facing away); one square root and
// one division on the lit path.
inline float spot_irradiance(const SpotLight& light, const Eigen::Vector3f& p_w, const Eigen::Vector3f& n_w) {
  const Eigen::Vector3f to_light = light.position_w - p_w;
  const float d2 = to_light.squaredNorm();
  const float range2 = light.range_m * light.range_m;
  if (!(d2 < range2) || d2 < 1e-8f) return 0.0f;
  const float along = -to_light.dot(light.axis_w);
  if (along <= 0.0f) return 0.0f;
  // Tangent-plane coordinates times `along`, scaled to the outer edge: inside the cone when r^2 < 1.
  const float x = to_light.dot(light.side_w) / light.tan_half_width;
  const float y = to_light.dot(light.across_w) / light.tan_half_height;
  const float along2 = along * along;
  const float r2_along2 = x * x + y * y;
  if (r2_along2 >= along2) return 0.0f;
  const float n_dot = n_w.dot(to_light);
  if (n_dot <= 0.0f) return 0.0f;
  float spot = 1.0f;
  const float inner2 = light.inner_fraction * light.inner_fraction;
  if (r2_along2 > inner2 * along2) {
    const float s = (1.0f - std::sqrt(r2_along2 / along2)) / (1.0f - light.inner_fraction);
    spot = s * s * (3.0f - 2.0f * s);
  }
  const float q = d2 / range2;
  const float window = (1.0f - q * q) * (1.0f - q * q);
  return light.intensity * spot * window * n_dot / (d2 * std::sqrt(d2));
}

// The lamps of a world (street: on the "pole" structures, road side from the nearest path point; hall:
// the grid under the "ceiling" structures), with their seeded intensity spread, in a fixed order.
// `working[i]` is false for the lamps out for the night (seeded, lamp_out_fraction).
struct Lamps {
  std::vector<SpotLight> lights;
  std::vector<char> working;
  std::size_t out_count() const;
};
Lamps make_lamps(const World& world, const LightsConfig& config, const std::vector<Eigen::Vector3d>& path_w,
                 std::uint64_t seed);

// The headlight for camera pose T_w_c (street: the vehicle's low beam; hall: a round spot at the camera).
SpotLight make_headlight(WorldKind kind, const LightsConfig& config, const Eigen::Isometry3d& T_w_c);

// Per-frame lighting of a simulation: the schedule's illumination and, under night_model lamps, the lamps'
// night end points, the sensor model, and the lights on at the frame.
class SceneLighting {
 public:
  // Keeps copies of the configurations; makes the lamps from world and path_w (lamps model only).
  SceneLighting(const IlluminationSchedule& schedule, const LightsConfig& lights, const SensorConfig& sensor,
                const World& world, const std::vector<Eigen::Vector3d>& path_w, std::uint64_t seed);

  bool lamps_model() const { return lamps_model_; }
  // The light at phase in [0, 1]: the schedule's (night_model ambient_noise), or with the lamps model's
  // night_ambient / night_sky_brightness and the photon sensor (night_model lamps).
  Illumination illumination(double phase) const;
  // The lights that shine at `phase` seen from T_w_c: the working lamps within cull_distance_m when the
  // lamps are on, and the headlight when it is on. Empty under night_model ambient_noise.
  std::vector<SpotLight> lights(double phase, const Eigen::Isometry3d& T_w_c) const;
  bool lamps_on(double phase) const;
  bool headlight_on(double phase) const;
  const Lamps& lamps() const { return lamps_; }

 private:
  IlluminationSchedule schedule_;
  IlluminationSchedule lamps_schedule_;  // schedule_ with the lamps model's night end points
  LightsConfig config_;
  SensorConfig sensor_;
  WorldKind kind_;
  bool lamps_model_ = false;
  Lamps lamps_;
};

}  // namespace loopgate::sim
