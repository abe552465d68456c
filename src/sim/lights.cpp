#include "sim/lights.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "core/error.hpp"
#include "sim/render_random.hpp"

namespace loopgate::sim {
namespace {

using render_detail::hash_combine;
using render_detail::Rng;

constexpr std::uint64_t kLampStream = 0x1A3B5ull;  // seeds of the lamps' spread and outages

double deg(double degrees) {
  return degrees * std::numbers::pi / 180.0;
}

void require(bool ok, const std::string& key, const std::string& what, double value) {
  if (!ok) throw ConfigError("lights." + key + ": must be " + what + " (got " + std::to_string(value) + ")");
}

// A unit vector perpendicular to a (unit).
Eigen::Vector3d any_perpendicular(const Eigen::Vector3d& a) {
  const Eigen::Vector3d helper = std::abs(a.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return (helper - a * a.dot(helper)).normalized();
}

SpotLight make_spot(const Eigen::Vector3d& position_w, const Eigen::Vector3d& axis_w,
                    const Eigen::Vector3d& side_hint_w, double intensity, double half_width_rad,
                    double half_height_rad, double inner_fraction, double range_m) {
  const Eigen::Vector3d axis = axis_w.normalized();
  Eigen::Vector3d side = side_hint_w - axis * axis.dot(side_hint_w);
  side = side.norm() > 1e-9 ? Eigen::Vector3d(side.normalized()) : any_perpendicular(axis);
  SpotLight light;
  light.position_w = position_w.cast<float>();
  light.axis_w = axis.cast<float>();
  light.side_w = side.cast<float>();
  light.across_w = axis.cross(side).cast<float>();
  light.intensity = static_cast<float>(intensity);
  light.tan_half_width = static_cast<float>(std::tan(half_width_rad));
  light.tan_half_height = static_cast<float>(std::tan(half_height_rad));
  light.inner_fraction = static_cast<float>(inner_fraction);
  light.range_m = static_cast<float>(range_m);
  return light;
}

// Round cone with full intensity within inner_deg and none beyond cone_deg.
SpotLight make_lamp(const Eigen::Vector3d& position_w, const Eigen::Vector3d& axis_w,
                    const Eigen::Vector3d& side_hint_w, double intensity, double cone_deg, double inner_deg,
                    double range_m, const LightsConfig& config) {
  SpotLight lamp = make_spot(position_w, axis_w, side_hint_w, intensity, deg(cone_deg), deg(cone_deg),
                             std::tan(deg(inner_deg)) / std::tan(deg(cone_deg)), range_m);
  lamp.head_radius_m = static_cast<float>(config.lamp_head_radius_m);
  lamp.head_radiance = static_cast<float>(config.lamp_head_radiance);
  lamp.glare = static_cast<float>(config.lamp_glare);
  return lamp;
}

void street_lamps(const World& world, const LightsConfig& config, const std::vector<Eigen::Vector3d>& path_w,
                  std::vector<SpotLight>* lamps) {
  const Eigen::Vector3d up = world.up_w.normalized();
  const auto horizontal = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(v - up * up.dot(v)); };
  // The posts' base corners (the origins of their four faces) and heights, in structure order.
  std::vector<Eigen::Vector3d> base_sum(world.structures.size(), Eigen::Vector3d::Zero());
  std::vector<int> faces(world.structures.size(), 0);
  std::vector<double> height(world.structures.size(), 0.0);
  for (const Quad& q : world.quads) {
    if (q.structure < 0) continue;
    const std::size_t s = static_cast<std::size_t>(q.structure);
    if (world.structures[s].kind != StructureKind::kPole) continue;
    base_sum[s] += q.origin_w.cast<double>();
    ++faces[s];
    height[s] = std::max(height[s], static_cast<double>(q.height_m));
  }
  for (std::size_t s = 0; s < world.structures.size(); ++s) {
    if (faces[s] == 0) continue;
    const Eigen::Vector3d top = base_sum[s] / faces[s] + up * height[s];
    // Towards the road: the nearest path point, horizontally.
    double best = std::numeric_limits<double>::infinity();
    Eigen::Vector3d to_road = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& p : path_w) {
      const Eigen::Vector3d h = horizontal(p - top);
      if (h.squaredNorm() < best) {
        best = h.squaredNorm();
        to_road = h;
      }
    }
    to_road = to_road.norm() > 1e-9 ? Eigen::Vector3d(to_road.normalized()) : any_perpendicular(up);
    const double tilt = deg(config.street_lamp_tilt_deg);
    const Eigen::Vector3d position =
        top + up * config.street_lamp_above_post_m + to_road * config.street_lamp_arm_m;
    const Eigen::Vector3d axis = -up * std::cos(tilt) + to_road * std::sin(tilt);
    lamps->push_back(make_lamp(position, axis, up.cross(to_road), config.street_lamp_intensity,
                               config.street_lamp_cone_deg, config.street_lamp_inner_deg,
                               config.street_lamp_range_m, config));
  }
}

void hall_lamps(const World& world, const LightsConfig& config, std::vector<SpotLight>* lamps) {
  const Eigen::Vector3d up = world.up_w.normalized();
  // The ceiling tiles span the room; their edges are the hall's horizontal axes.
  const Quad* first = nullptr;
  for (const Quad& q : world.quads) {
    if (q.structure >= 0 &&
        world.structures[static_cast<std::size_t>(q.structure)].kind == StructureKind::kCeiling) {
      first = &q;
      break;
    }
  }
  if (first == nullptr) return;
  const Eigen::Vector3d e1 = first->axis_u_w.cast<double>();
  const Eigen::Vector3d e2 = first->axis_v_w.cast<double>();
  double lo1 = std::numeric_limits<double>::infinity(), hi1 = -lo1, lo2 = lo1, hi2 = -lo1;
  double ceiling = -std::numeric_limits<double>::infinity();
  for (const Quad& q : world.quads) {
    if (q.structure < 0 ||
        world.structures[static_cast<std::size_t>(q.structure)].kind != StructureKind::kCeiling)
      continue;
    const Eigen::Vector3d o = q.origin_w.cast<double>();
    const Eigen::Vector3d du = q.axis_u_w.cast<double>() * q.width_m;
    const Eigen::Vector3d dv = q.axis_v_w.cast<double>() * q.height_m;
    for (const Eigen::Vector3d& c :
         {o, Eigen::Vector3d(o + du), Eigen::Vector3d(o + dv), Eigen::Vector3d(o + du + dv)}) {
      lo1 = std::min(lo1, c.dot(e1));
      hi1 = std::max(hi1, c.dot(e1));
      lo2 = std::min(lo2, c.dot(e2));
      hi2 = std::max(hi2, c.dot(e2));
    }
    ceiling = std::max(ceiling, o.dot(up));
  }
  const int n1 = std::max(1, static_cast<int>(std::lround((hi1 - lo1) / config.hall_lamp_spacing_m)));
  const int n2 = std::max(1, static_cast<int>(std::lround((hi2 - lo2) / config.hall_lamp_spacing_m)));
  const double z = ceiling - config.hall_lamp_below_ceiling_m;
  for (int i = 0; i < n1; ++i) {
    for (int j = 0; j < n2; ++j) {
      const double a = lo1 + (i + 0.5) * (hi1 - lo1) / n1;
      const double b = lo2 + (j + 0.5) * (hi2 - lo2) / n2;
      lamps->push_back(make_lamp(e1 * a + e2 * b + up * z, -up, e1, config.hall_lamp_intensity,
                                 config.hall_lamp_cone_deg, config.hall_lamp_inner_deg,
                                 config.hall_lamp_range_m, config));
    }
  }
}

}  // namespace

void LightsConfig::validate() const {
  const auto non_negative = [](const char* key, double v) { require(v >= 0.0, key, ">= 0", v); };
  const auto positive = [](const char* key, double v) { require(v > 0.0, key, "> 0", v); };
  const auto cone = [](const char* key, double outer, const char* inner_key, double inner) {
    require(outer > 0.0 && outer < 89.0, key, "in (0, 89) degrees", outer);
    require(inner >= 0.0 && inner < outer, inner_key, "in [0, the outer cone)", inner);
  };
  non_negative("street_lamp_intensity", street_lamp_intensity);
  non_negative("street_lamp_above_post_m", street_lamp_above_post_m);
  non_negative("street_lamp_arm_m", street_lamp_arm_m);
  require(street_lamp_tilt_deg >= 0.0 && street_lamp_tilt_deg < 90.0, "street_lamp_tilt_deg", "in [0, 90)",
          street_lamp_tilt_deg);
  cone("street_lamp_cone_deg", street_lamp_cone_deg, "street_lamp_inner_deg", street_lamp_inner_deg);
  positive("street_lamp_range_m", street_lamp_range_m);
  positive("hall_lamp_spacing_m", hall_lamp_spacing_m);
  non_negative("hall_lamp_below_ceiling_m", hall_lamp_below_ceiling_m);
  non_negative("hall_lamp_intensity", hall_lamp_intensity);
  cone("hall_lamp_cone_deg", hall_lamp_cone_deg, "hall_lamp_inner_deg", hall_lamp_inner_deg);
  positive("hall_lamp_range_m", hall_lamp_range_m);
  require(lamp_intensity_jitter >= 0.0 && lamp_intensity_jitter < 1.0, "lamp_intensity_jitter", "in [0, 1)",
          lamp_intensity_jitter);
  require(lamp_out_fraction >= 0.0 && lamp_out_fraction <= 1.0, "lamp_out_fraction", "in [0, 1]",
          lamp_out_fraction);
  non_negative("lamp_head_radius_m", lamp_head_radius_m);
  non_negative("lamp_head_radiance", lamp_head_radiance);
  non_negative("lamp_glare", lamp_glare);
  require(lamps_on_night_factor >= 0.0 && lamps_on_night_factor <= 1.0, "lamps_on_night_factor", "in [0, 1]",
          lamps_on_night_factor);
  non_negative("headlight_intensity", headlight_intensity);
  require(std::isfinite(headlight_below_camera_m), "headlight_below_camera_m", "finite",
          headlight_below_camera_m);
  require(std::isfinite(headlight_ahead_m), "headlight_ahead_m", "finite", headlight_ahead_m);
  require(headlight_pitch_deg > -45.0 && headlight_pitch_deg < 45.0, "headlight_pitch_deg", "in (-45, 45)",
          headlight_pitch_deg);
  require(headlight_half_width_deg > 0.0 && headlight_half_width_deg < 89.0, "headlight_half_width_deg",
          "in (0, 89)", headlight_half_width_deg);
  require(headlight_half_height_deg > 0.0 && headlight_half_height_deg < 89.0, "headlight_half_height_deg",
          "in (0, 89)", headlight_half_height_deg);
  require(headlight_inner_fraction >= 0.0 && headlight_inner_fraction < 1.0, "headlight_inner_fraction",
          "in [0, 1)", headlight_inner_fraction);
  positive("headlight_range_m", headlight_range_m);
  non_negative("hall_headlight_intensity", hall_headlight_intensity);
  require(hall_headlight_cone_deg > 0.0 && hall_headlight_cone_deg < 89.0, "hall_headlight_cone_deg",
          "in (0, 89)", hall_headlight_cone_deg);
  positive("hall_headlight_range_m", hall_headlight_range_m);
  require(headlight_on_night_factor >= 0.0 && headlight_on_night_factor <= 1.0, "headlight_on_night_factor",
          "in [0, 1]", headlight_on_night_factor);
  non_negative("night_ambient", night_ambient);
  non_negative("night_sky_brightness", night_sky_brightness);
  positive("cull_distance_m", cull_distance_m);
}

std::size_t Lamps::out_count() const {
  return static_cast<std::size_t>(std::count(working.begin(), working.end(), 0));
}

Lamps make_lamps(const World& world, const LightsConfig& config, const std::vector<Eigen::Vector3d>& path_w,
                 std::uint64_t seed) {
  config.validate();
  Lamps lamps;
  if (world.kind == WorldKind::kStreet) {
    street_lamps(world, config, path_w, &lamps.lights);
  } else {
    hall_lamps(world, config, &lamps.lights);
  }
  lamps.working.assign(lamps.lights.size(), 1);
  for (std::size_t k = 0; k < lamps.lights.size(); ++k) {
    Rng rng(hash_combine(seed ^ kLampStream, k));
    lamps.lights[k].intensity *=
        static_cast<float>(1.0 + config.lamp_intensity_jitter * rng.uniform(-1.0, 1.0));
    lamps.working[k] = rng.chance(config.lamp_out_fraction) ? 0 : 1;
  }
  return lamps;
}

SpotLight make_headlight(WorldKind kind, const LightsConfig& config, const Eigen::Isometry3d& T_w_c) {
  const Eigen::Matrix3d R = T_w_c.linear();
  if (kind == WorldKind::kHall) {
    const double cone = deg(config.hall_headlight_cone_deg);
    return make_spot(T_w_c.translation(), R.col(2), R.col(0), config.hall_headlight_intensity, cone, cone,
                     config.headlight_inner_fraction, config.hall_headlight_range_m);
  }
  // Camera frame: x right, y down, z forward.
  const double pitch = deg(config.headlight_pitch_deg);
  const Eigen::Vector3d position =
      T_w_c * Eigen::Vector3d(0.0, config.headlight_below_camera_m, config.headlight_ahead_m);
  const Eigen::Vector3d axis = R * Eigen::Vector3d(0.0, std::sin(pitch), std::cos(pitch));
  return make_spot(position, axis, R.col(0), config.headlight_intensity, deg(config.headlight_half_width_deg),
                   deg(config.headlight_half_height_deg), config.headlight_inner_fraction,
                   config.headlight_range_m);
}

SceneLighting::SceneLighting(const IlluminationSchedule& schedule, const LightsConfig& lights,
                             const SensorConfig& sensor, const World& world,
                             const std::vector<Eigen::Vector3d>& path_w, std::uint64_t seed)
    : schedule_(schedule),
      lamps_schedule_(schedule),
      config_(lights),
      sensor_(sensor),
      kind_(world.kind),
      lamps_model_(schedule.night_model == NightModel::kLamps) {
  schedule_.validate();
  config_.validate();
  sensor_.validate();
  lamps_schedule_.night_ambient = config_.night_ambient;
  lamps_schedule_.night_sky_brightness = config_.night_sky_brightness;
  if (lamps_model_) lamps_ = make_lamps(world, config_, path_w, seed);
}

Illumination SceneLighting::illumination(double phase) const {
  if (!lamps_model_) return schedule_.at(phase);
  Illumination light = lamps_schedule_.at(phase);
  light.photon_sensor = true;
  light.sensor = sensor_;
  return light;
}

bool SceneLighting::lamps_on(double phase) const {
  return lamps_model_ && schedule_.night_factor(phase) >= config_.lamps_on_night_factor;
}

bool SceneLighting::headlight_on(double phase) const {
  return lamps_model_ && schedule_.night_factor(phase) >= config_.headlight_on_night_factor;
}

std::vector<SpotLight> SceneLighting::lights(double phase, const Eigen::Isometry3d& T_w_c) const {
  std::vector<SpotLight> out;
  if (lamps_on(phase)) {
    const Eigen::Vector3f camera = T_w_c.translation().cast<float>();
    const float cull2 = static_cast<float>(config_.cull_distance_m * config_.cull_distance_m);
    for (std::size_t k = 0; k < lamps_.lights.size(); ++k) {
      if (lamps_.working[k] && (lamps_.lights[k].position_w - camera).squaredNorm() <= cull2)
        out.push_back(lamps_.lights[k]);
    }
  }
  if (headlight_on(phase)) {
    const SpotLight headlight = make_headlight(kind_, config_, T_w_c);
    if (headlight.intensity > 0.0f) out.push_back(headlight);
  }
  return out;
}

}  // namespace loopgate::sim
