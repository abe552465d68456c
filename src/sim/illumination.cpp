#include "sim/illumination.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.hpp"

namespace loopgate::sim {
namespace {

constexpr double kLogFloor = 1e-6;  // keeps log-interpolation finite for zero end points

double lerp(double a, double b, double w) {
  return a + (b - a) * w;
}
// Brightness-like quantities fade geometrically (dusk), which also keeps them positive.
double log_lerp(double a, double b, double w) {
  return std::exp(lerp(std::log(std::max(a, kLogFloor)), std::log(std::max(b, kLogFloor)), w));
}

void require(bool ok, const std::string& key, const std::string& what) {
  if (!ok) throw ConfigError("illumination." + key + ": " + what);
}

}  // namespace

void IlluminationSchedule::validate() const {
  require(day_exposure > 0.0, "day_exposure", "must be > 0");
  require(night_exposure > 0.0, "night_exposure", "must be > 0");
  require(day_ambient >= 0.0, "day_ambient", "must be >= 0");
  require(night_ambient >= 0.0, "night_ambient", "must be >= 0");
  require(day_sun_intensity >= 0.0, "day_sun_intensity", "must be >= 0");
  require(night_sun_intensity >= 0.0, "night_sun_intensity", "must be >= 0");
  require(day_sky_brightness >= 0.0, "day_sky_brightness", "must be >= 0");
  require(night_sky_brightness >= 0.0, "night_sky_brightness", "must be >= 0");
  require(day_vignetting >= 0.0 && day_vignetting < 1.0, "day_vignetting", "must be in [0, 1)");
  require(night_vignetting >= 0.0 && night_vignetting < 1.0, "night_vignetting", "must be in [0, 1)");
  require(day_noise_sigma >= 0.0, "day_noise_sigma", "must be >= 0");
  require(night_noise_sigma >= 0.0, "night_noise_sigma", "must be >= 0");
  require(gamma > 0.0, "gamma", "must be > 0");
  require(Eigen::Vector3d(sun_dir_x, sun_dir_y, sun_dir_z).norm() > 1e-9, "sun_dir_x",
          "sun direction (sun_dir_x, sun_dir_y, sun_dir_z) must not be zero");
  require(transition_start >= 0.0 && transition_start <= 1.0, "transition_start", "must be in [0, 1]");
  require(transition_end > transition_start && transition_end <= 1.0, "transition_end",
          "must be in (transition_start, 1]");
  require(jump_phase >= 0.0 && jump_phase <= 1.0, "jump_phase", "must be in [0, 1]");
}

double IlluminationSchedule::night_factor(double phase) const {
  phase = std::clamp(phase, 0.0, 1.0);
  if (kind == IlluminationKind::kConstant) return 0.0;
  if (kind == IlluminationKind::kJump) return phase >= jump_phase ? 1.0 : 0.0;
  if (phase <= transition_start) return 0.0;
  if (phase >= transition_end) return 1.0;
  const double x = (phase - transition_start) / (transition_end - transition_start);
  return x * x * (3.0 - 2.0 * x);
}

Illumination IlluminationSchedule::at(double phase) const {
  const double w = night_factor(phase);
  Illumination light;
  light.exposure = log_lerp(day_exposure, night_exposure, w);
  light.gamma = gamma;
  light.ambient = log_lerp(day_ambient, night_ambient, w);
  light.sun_intensity = lerp(day_sun_intensity, night_sun_intensity, w);
  light.sun_dir_w = Eigen::Vector3d(sun_dir_x, sun_dir_y, sun_dir_z).normalized();
  light.sky_brightness = log_lerp(day_sky_brightness, night_sky_brightness, w);
  light.vignetting = lerp(day_vignetting, night_vignetting, w);
  light.noise_sigma = lerp(day_noise_sigma, night_noise_sigma, w);
  return light;
}

}  // namespace loopgate::sim
