// Per-frame lighting: exposure/gain, gamma, ambient + directional sun (Lambert), sky brightness,
// vignetting, sensor noise; and a schedule over the sequence so revisits see different light.
#pragma once

#include <Eigen/Core>
#include <span>
#include <string>

#include "core/enum_names.hpp"
#include "sim/sensor.hpp"

namespace loopgate::sim {

// Radiance of a surface = albedo * (ambient + sun_intensity * max(0, n . sun_dir_w) + lights); pixel value =
// 255 * clamp(exposure * radiance * vignette)^(1/gamma) + noise (the additive sensor), or the photon sensor
// of sim/sensor.hpp (auto-exposure, shot + read noise, then gamma). Defaults = a plain day, additive sensor.
struct Illumination {
  double exposure = 0.9;       // gain applied to radiance before gamma
  double gamma = 2.2;          // display gamma (output = linear^(1/gamma))
  double ambient = 0.35;       // ambient irradiance
  double sun_intensity = 0.5;  // directional irradiance
  // Unit direction TOWARDS the sun in the world frame. The default is "up" both for a KITTI-like world
  // (up = -y) and an EuRoC-like world (up = +z).
  Eigen::Vector3d sun_dir_w = Eigen::Vector3d(0.35, -0.65, 0.67).normalized();
  double sky_brightness = 0.9;  // linear radiance of the sky (rays that hit nothing)
  double vignetting = 0.25;     // relative darkening at the image corners (0 = none)
  double noise_sigma = 1.5;     // sensor noise std-dev in grey levels (0..255 scale)
  // The photon sensor (night_model lamps) instead of exposure + additive noise_sigma.
  bool photon_sensor = false;
  SensorConfig sensor;
};

// illumination.kind: the day stays ("constant"), turns to night smoothly ("day-to-night") or at once
// ("jump").
enum class IlluminationKind { kConstant, kDayToNight, kJump };
inline constexpr EnumName<IlluminationKind> kIlluminationKindNames[] = {
    {IlluminationKind::kConstant, "constant"},
    {IlluminationKind::kDayToNight, "day-to-night"},
    {IlluminationKind::kJump, "jump"}};
constexpr std::span<const EnumName<IlluminationKind>> enum_names(IlluminationKind) {
  return kIlluminationKindNames;
}

// illumination.night_model: "ambient_noise" or "lamps" (see IlluminationSchedule::night_model).
enum class NightModel { kAmbientNoise, kLamps };
inline constexpr EnumName<NightModel> kNightModelNames[] = {{NightModel::kAmbientNoise, "ambient_noise"},
                                                            {NightModel::kLamps, "lamps"}};
constexpr std::span<const EnumName<NightModel>> enum_names(NightModel) {
  return kNightModelNames;
}

struct IlluminationSchedule {
  IlluminationKind kind = IlluminationKind::kDayToNight;  // constant | day-to-night | jump
  // What the night is: "ambient_noise" = ambient light only and additive Gaussian noise (night_noise_sigma):
  // the harsh night of the first presets; "lamps" = street / hall lamps and a headlight (section "lights",
  // sim/lights.hpp) seen through the photon sensor with auto-exposure (section "sensor", sim/sensor.hpp);
  // the day_* / night_* end points below still apply except night_ambient and night_sky_brightness (the
  // lights section's), the exposures and the noise sigmas (the sensor's).
  NightModel night_model = NightModel::kAmbientNoise;
  // Day (phase 0) and night (phase 1) end points.
  double day_exposure = 0.9;
  double night_exposure = 1.8;
  double day_ambient = 0.35;
  double night_ambient = 0.05;
  double day_sun_intensity = 0.5;
  double night_sun_intensity = 0.0;
  double day_sky_brightness = 0.9;
  double night_sky_brightness = 0.01;
  double day_vignetting = 0.25;
  double night_vignetting = 0.55;
  double day_noise_sigma = 1.5;
  double night_noise_sigma = 9.0;
  double gamma = 2.2;
  // Sun direction (towards the sun, world frame; normalised on use) at day; it sinks towards the
  // horizontal at dusk.
  double sun_dir_x = 0.35;
  double sun_dir_y = -0.65;
  double sun_dir_z = 0.67;
  // day-to-night: day until transition_start, smooth (smoothstep) change to night at transition_end.
  double transition_start = 0.35;
  double transition_end = 0.75;
  // jump: day before jump_phase, night from jump_phase on.
  double jump_phase = 0.5;

  // The keys, in order, for loading, printing and the JSON echo (Self is IlluminationSchedule or const
  // IlluminationSchedule).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("kind", self.kind);
    v("night_model", self.night_model);
    v("day_exposure", self.day_exposure);
    v("night_exposure", self.night_exposure);
    v("day_ambient", self.day_ambient);
    v("night_ambient", self.night_ambient);
    v("day_sun_intensity", self.day_sun_intensity);
    v("night_sun_intensity", self.night_sun_intensity);
    v("day_sky_brightness", self.day_sky_brightness);
    v("night_sky_brightness", self.night_sky_brightness);
    v("day_vignetting", self.day_vignetting);
    v("night_vignetting", self.night_vignetting);
    v("day_noise_sigma", self.day_noise_sigma);
    v("night_noise_sigma", self.night_noise_sigma);
    v("gamma", self.gamma);
    v("sun_dir_x", self.sun_dir_x);
    v("sun_dir_y", self.sun_dir_y);
    v("sun_dir_z", self.sun_dir_z);
    v("transition_start", self.transition_start);
    v("transition_end", self.transition_end);
    v("jump_phase", self.jump_phase);
  }
  // Throws loopgate::ConfigError naming the key (kind values, ranges, sun direction not zero).
  void validate() const;

  // Lighting at phase in [0, 1] = position in the sequence (frame / (frames - 1)); clamped.
  Illumination at(double phase) const;
  // Night factor in [0, 1] at phase (0 = full day, 1 = full night).
  double night_factor(double phase) const;
};

}  // namespace loopgate::sim
