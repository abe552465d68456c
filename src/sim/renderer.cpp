#include "sim/renderer.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <string>
#include <utility>

#include "core/error.hpp"
#include "sim/render_bvh.hpp"
#include "sim/render_random.hpp"

namespace loopgate::sim {
namespace {

constexpr float kDistantGroundAlbedo = 0.3f;  // mean albedo of the unmodelled far ground
constexpr float kDistantGroundFade = 8.0f;    // how fast it emerges from the haze below the horizon
constexpr int kGammaLutSize = 16384;          // linear [0, 1] -> display grey level
constexpr float kNoiseUniformScale = 1.0f / 65536.0f;
constexpr float kIrwinHallScale = 1.7320508075688772f;  // sqrt(3): sum of 4 U(0,1) has variance 1/3
constexpr double kMinCullRayZ = 0.1;  // rays closer to 90 degrees off-axis than this turn culling off
constexpr float kGlareFloor = 2e-4f;  // the glare halo of a lamp head is drawn where above this radiance

// Sum of four 16-bit uniforms of `bits` in [0, 1), minus 2: mean 0, variance 1/3, nearly Gaussian.
inline float irwin_hall_centred(std::uint64_t bits) {
  const float s = static_cast<float>(bits & 0xFFFFu) + static_cast<float>((bits >> 16) & 0xFFFFu) +
                  static_cast<float>((bits >> 32) & 0xFFFFu) + static_cast<float>(bits >> 48);
  return s * kNoiseUniformScale - 2.0f;
}

// A visible lamp head in a frame: a disc of angular radius radius_rad around dir_w and its glare halo
// glare_scale / (theta^2 + radius_rad^2), drawn where sin^2(theta) <= sin2_max, dimmed by the haze.
struct LampHead {
  Eigen::Vector3f dir_w = Eigen::Vector3f::UnitZ();
  float radius_rad = 0.0f;
  float radiance = 0.0f;
  float glare_scale = 0.0f;
  float sin2_max = 0.0f;
  float transmission = 1.0f;
};

}  // namespace

void RendererConfig::validate() const {
  if (!(near_m > 0.0)) throw ConfigError("renderer.near_m: must be > 0");
  if (!(far_m > near_m)) throw ConfigError("renderer.far_m: must be > near_m");
  if (!(haze_distance_m >= 0.0)) throw ConfigError("renderer.haze_distance_m: must be >= 0");
  if (!(min_incidence_cos > 0.0 && min_incidence_cos <= 1.0)) {
    throw ConfigError("renderer.min_incidence_cos: must be in (0, 1]");
  }
  if (!(sky_zenith_gain >= 0.0)) throw ConfigError("renderer.sky_zenith_gain: must be >= 0");
}

Renderer::Renderer(const World& world, const CameraCalibration& camera, const RendererConfig& config)
    : world_(world), camera_(camera), config_(config) {
  config_.validate();
  const int w = camera.width_px, h = camera.height_px;
  if (w <= 0 || h <= 0) {
    throw ConfigError("camera.resolution: width and height must be positive (got " + std::to_string(w) +
                      " x " + std::to_string(h) + ")");
  }
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  ray_c_.resize(3 * n);
  footprint_rad_.resize(n);
  vignette_r2_.resize(n);
  std::vector<Eigen::Vector3d> rays(n);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      rays[static_cast<std::size_t>(v) * w + u] = camera_.unproject_ray(Eigen::Vector2d(u, v));
    }
  }
  const double half_w = 0.5 * (w - 1), half_h = 0.5 * (h - 1);
  const double r2_max = half_w * half_w + half_h * half_h;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t k = static_cast<std::size_t>(v) * w + u;
      const Eigen::Vector3d& r = rays[k];
      ray_c_[3 * k + 0] = static_cast<float>(r.x());
      ray_c_[3 * k + 1] = static_cast<float>(r.y());
      ray_c_[3 * k + 2] = static_cast<float>(r.z());
      // Angular pixel size from the neighbours (one-sided at the borders).
      const Eigen::Vector3d& ru = rays[u + 1 < w ? k + 1 : k - (w > 1 ? 1 : 0)];
      const Eigen::Vector3d& rv = rays[v + 1 < h ? k + w : k - (h > 1 ? static_cast<std::size_t>(w) : 0)];
      double foot = std::max((ru - r).norm(), (rv - r).norm());
      if (foot <= 0.0) foot = 1.0 / std::max(camera.fx, camera.fy);
      footprint_rad_[k] = static_cast<float>(foot);
      const double du = u - half_w, dv = v - half_h;
      vignette_r2_[k] = static_cast<float>(r2_max > 0 ? (du * du + dv * dv) / r2_max : 0.0);
    }
  }
  double tan_x = 0.0, tan_y = 0.0;
  bool wide = false;
  for (const Eigen::Vector3d& r : rays) {
    if (!(r.z() > kMinCullRayZ)) {
      wide = true;
      break;
    }
    tan_x = std::max(tan_x, std::abs(r.x()) / r.z());
    tan_y = std::max(tan_y, std::abs(r.y()) / r.z());
  }
  if (!wide) {
    tan_half_fov_x_ = static_cast<float>(tan_x);
    tan_half_fov_y_ = static_cast<float>(tan_y);
  }
}

cv::Mat Renderer::render(const Eigen::Isometry3d& T_w_c, const Illumination& light, std::uint64_t noise_seed,
                         std::span<const SpotLight> lights, RenderStats* stats) const {
  const CameraCalibration& cal = camera_.calibration();
  const int w = cal.width_px, h = cal.height_px;
  cv::Mat image(h, w, CV_8UC1);

  const Eigen::Matrix3f R = T_w_c.linear().cast<float>();
  const Eigen::Vector3f origin = T_w_c.translation().cast<float>();
  const Eigen::Vector3f up = world_.up_w.cast<float>();
  Eigen::Vector3f sun = light.sun_dir_w.cast<float>();
  sun = sun.norm() > 0.0f ? Eigen::Vector3f(sun.normalized()) : up;
  const float ambient = static_cast<float>(light.ambient);
  const float sun_intensity = static_cast<float>(light.sun_intensity);
  const float sky = static_cast<float>(light.sky_brightness);
  const float zenith_gain = static_cast<float>(config_.sky_zenith_gain);
  const float exposure = static_cast<float>(light.exposure);
  const float vignetting = static_cast<float>(light.vignetting);
  const float noise_sigma = static_cast<float>(light.noise_sigma);
  const float near_m = static_cast<float>(config_.near_m);
  const float far_m = static_cast<float>(config_.far_m);
  const float haze_m = static_cast<float>(config_.haze_distance_m);
  const float min_cos = static_cast<float>(config_.min_incidence_cos);

  // Display transfer as a lookup table over linear [0, 1].
  std::vector<float> gamma_lut(kGammaLutSize + 1);
  const double inv_gamma = 1.0 / light.gamma;
  for (int k = 0; k <= kGammaLutSize; ++k) {
    gamma_lut[static_cast<std::size_t>(k)] =
        static_cast<float>(255.0 * std::pow(static_cast<double>(k) / kGammaLutSize, inv_gamma));
  }
  const float lut_scale = static_cast<float>(kGammaLutSize);

  const World& world = world_;

  // Lights: those whose reach (a sphere of range_m) meets the view, and the lamp heads in view (with their
  // glare halo) and not hidden behind a surface.
  const Eigen::Matrix3f R_c_w = R.transpose();
  const auto sphere_in_view = [&](const Eigen::Vector3f& c, float radius) {
    if (c.z() < -radius) return false;
    if (tan_half_fov_x_ <= 0.0f) return true;
    for (const auto& [coordinate, tangent] :
         {std::pair{c.x(), tan_half_fov_x_}, std::pair{-c.x(), tan_half_fov_x_},
          std::pair{c.y(), tan_half_fov_y_}, std::pair{-c.y(), tan_half_fov_y_}}) {
      if ((coordinate - tangent * c.z()) / std::sqrt(1.0f + tangent * tangent) > radius) return false;
    }
    return true;
  };
  std::vector<SpotLight> shading;
  std::vector<LampHead> heads;
  for (const SpotLight& lamp : lights) {
    const Eigen::Vector3f c = R_c_w * (lamp.position_w - origin);
    if (lamp.intensity > 0.0f && sphere_in_view(c, lamp.range_m)) shading.push_back(lamp);
    if (!(lamp.head_radius_m > 0.0f && lamp.head_radiance > 0.0f)) continue;
    const float distance = c.norm();
    if (!(distance > near_m + lamp.head_radius_m)) continue;
    LampHead head;
    head.radius_rad = lamp.head_radius_m / distance;
    const float a2 = head.radius_rad * head.radius_rad;
    head.glare_scale = lamp.glare * lamp.head_radiance * a2;
    // The halo is drawn where it is above kGlareFloor; the head's edge at least.
    const float halo2 = head.glare_scale / kGlareFloor - a2;
    head.sin2_max = std::max(halo2, 4.0f * a2);
    if (!sphere_in_view(c, distance * std::sqrt(std::min(head.sin2_max, 1.0f)))) continue;
    head.dir_w = (lamp.position_w - origin) / distance;
    float t_hit = 0, a_m = 0, b_m = 0;
    if (render_detail::closest_hit(world, origin, head.dir_w, near_m, distance - lamp.head_radius_m, &t_hit,
                                   &a_m, &b_m) >= 0) {
      continue;  // hidden
    }
    head.transmission = haze_m > 0.0f ? haze_m / (distance + haze_m) : 1.0f;
    head.radiance = lamp.head_radiance;
    heads.push_back(head);
  }

  // Scene radiance along pixel k's ray (hint_quad: the left neighbour's quad, updated).
  const auto shade = [&](std::size_t k, int& hint_quad) {
    const Eigen::Vector3f ray_c(ray_c_[3 * k], ray_c_[3 * k + 1], ray_c_[3 * k + 2]);
    const Eigen::Vector3f d = R * ray_c;
    const float elevation = std::clamp(d.dot(up), 0.0f, 1.0f);
    const float sky_radiance = sky * (1.0f + zenith_gain * elevation);
    float t = 0, a_m = 0, b_m = 0;
    const int qi = render_detail::closest_hit(world, origin, d, near_m, far_m, &t, &a_m, &b_m, hint_quad);
    hint_quad = qi;
    float radiance = sky_radiance;
    if (qi < 0 && d.dot(up) < 0.0f) {
      // Below the horizon beyond the modelled ground: a distant, hazy, sunlit ground.
      radiance =
          sky + (kDistantGroundAlbedo * (ambient + sun_intensity * std::max(0.0f, sun.dot(up))) - sky) *
                    std::min(1.0f, -d.dot(up) * kDistantGroundFade);
    } else if (qi >= 0) {
      const Quad& q = world.quads[static_cast<std::size_t>(qi)];
      const float cos_inc = q.normal_w.dot(d);
      const float facing = cos_inc < 0.0f ? 1.0f : -1.0f;  // normal turned towards the camera
      const float lambert = std::max(0.0f, facing * q.normal_w.dot(sun));
      const float abs_cos = std::max(std::abs(cos_inc), min_cos);
      const float footprint_tx = t * footprint_rad_[k] * q.texels_per_m / std::sqrt(abs_cos);
      const Texture& tex = world.textures[static_cast<std::size_t>(q.texture)];
      const float albedo = tex.sample(q.u_offset_tx + q.u_sign * a_m * q.texels_per_m,
                                      q.v_offset_tx + q.v_sign * b_m * q.texels_per_m, footprint_tx);
      float irradiance = ambient + sun_intensity * lambert;
      if (!shading.empty()) {
        const Eigen::Vector3f p = origin + t * d;
        const Eigen::Vector3f n = facing * q.normal_w;
        for (const SpotLight& lamp : shading) irradiance += spot_irradiance(lamp, p, n);
      }
      const float surface = albedo * irradiance;
      if (haze_m > 0.0f) {
        const float haze = t / (t + haze_m);
        radiance = surface + (sky - surface) * haze;  // fades into the horizon sky
      } else {
        radiance = surface;
      }
    }
    for (const LampHead& head : heads) {
      if (d.dot(head.dir_w) <= 0.0f) continue;
      const float sin2 = d.cross(head.dir_w).squaredNorm();
      if (sin2 > head.sin2_max) continue;
      const float cover =
          std::clamp((head.radius_rad - std::sqrt(sin2)) / footprint_rad_[k] + 0.5f, 0.0f, 1.0f);
      const float a2 = head.radius_rad * head.radius_rad;
      radiance += head.transmission * (head.radiance * cover + head.glare_scale / (sin2 + a2));
    }
    return radiance;
  };

  if (stats != nullptr) {
    *stats = RenderStats{};
    stats->shading_lights = static_cast<int>(shading.size());
    stats->visible_lamp_heads = static_cast<int>(heads.size());
  }
  if (light.photon_sensor) {
    // Radiance at the sensor (vignetting is the lens'), metered on a sparse grid, exposed, then shot + read
    // noise in linear grey levels, clipping, gamma and quantisation.
    std::vector<float> signal(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    for (int v = 0; v < h; ++v) {
      int hint_quad = -1;
      for (int u = 0; u < w; ++u) {
        const std::size_t k =
            static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
        signal[k] = shade(k, hint_quad) * (1.0f - vignetting * vignette_r2_[k]);
      }
    }
    const int stride = light.sensor.ae_metering_stride_px;
    std::vector<float> samples;
    samples.reserve(signal.size() / static_cast<std::size_t>(stride * stride) + 1);
    for (int v = stride / 2; v < h; v += stride) {
      for (int u = stride / 2; u < w; u += stride) {
        samples.push_back(
            signal[static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u)]);
      }
    }
    const SensorExposure ae = auto_exposure(samples, light.sensor, light.gamma);
    const float scale_dn = static_cast<float>(255.0 * ae.scale());
    const float dn_per_e = static_cast<float>(ae.dn_per_electron(light.sensor));
    const float read_dn = dn_per_e * static_cast<float>(light.sensor.read_noise_e);
    const float read_dn2 = read_dn * read_dn;
    const std::uint64_t photon_key = render_detail::mix64(noise_seed ^ 0xF070F070F070ull);
    for (int v = 0; v < h; ++v) {
      std::uint8_t* row = image.ptr<std::uint8_t>(v);
      for (int u = 0; u < w; ++u) {
        const std::size_t k =
            static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
        const float signal_dn = scale_dn * signal[k];
        const float sigma_dn = std::sqrt(dn_per_e * std::max(0.0f, signal_dn) + read_dn2);
        const float noisy_dn = signal_dn + sigma_dn * kIrwinHallScale *
                                               irwin_hall_centred(render_detail::hash_combine(photon_key, k));
        const float linear = std::clamp(noisy_dn * (1.0f / 255.0f), 0.0f, 1.0f);
        const float grey = gamma_lut[static_cast<std::size_t>(linear * lut_scale)];
        row[u] = static_cast<std::uint8_t>(std::clamp(grey + 0.5f, 0.0f, 255.0f));
      }
    }
    if (stats != nullptr) {
      stats->exposure_time = ae.exposure_time;
      stats->gain = ae.gain;
      stats->dn_per_electron = ae.dn_per_electron(light.sensor);
    }
    return image;
  }

  if (stats != nullptr) stats->exposure_time = light.exposure;
  const std::uint64_t frame_key = render_detail::mix64(noise_seed ^ 0x5EED5EED5EEDull);
  for (int v = 0; v < h; ++v) {
    std::uint8_t* row = image.ptr<std::uint8_t>(v);
    int hint_quad = -1;  // the left neighbour's quad (reset per row)
    for (int u = 0; u < w; ++u) {
      const std::size_t k =
          static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
      const float radiance = shade(k, hint_quad);
      float linear = exposure * radiance * (1.0f - vignetting * vignette_r2_[k]);
      linear = std::clamp(linear, 0.0f, 1.0f);
      float grey = gamma_lut[static_cast<std::size_t>(linear * lut_scale)];
      if (noise_sigma > 0.0f) {
        grey += noise_sigma * kIrwinHallScale * irwin_hall_centred(render_detail::hash_combine(frame_key, k));
      }
      row[u] = static_cast<std::uint8_t>(std::clamp(grey + 0.5f, 0.0f, 255.0f));
    }
  }
  return image;
}

}  // namespace loopgate::sim
