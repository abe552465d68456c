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

namespace {

// Display transfer as a lookup table over linear [0, 1]: kGammaLutSize + 1 grey levels.
std::vector<float> make_gamma_lut(double gamma) {
  std::vector<float> gamma_lut(kGammaLutSize + 1);
  const double inv_gamma = 1.0 / gamma;
  for (int k = 0; k <= kGammaLutSize; ++k) {
    gamma_lut[static_cast<std::size_t>(k)] =
        static_cast<float>(255.0 * std::pow(static_cast<double>(k) / kGammaLutSize, inv_gamma));
  }
  return gamma_lut;
}

// The per-pixel constants of the camera a frame is rendered through (owned by the Renderer).
struct PixelRays {
  const float* ray_c = nullptr;          // 3 floats per pixel: unit bearing in the camera frame
  const float* footprint_rad = nullptr;  // angular size of each pixel
  const float* vignette_r2 = nullptr;    // squared normalised distance from the image centre
  float tan_half_fov_x = 0.0f;           // 0 = no culling of lights
  float tan_half_fov_y = 0.0f;
};

// One frame's scene: pose, light, the spot lights that can light something in view and the lamp heads in
// view; radiance(k) is the scene radiance along pixel k's ray.
class FrameScene {
 public:
  FrameScene(const World& world, const RendererConfig& config, const PixelRays& pixels,
             const Eigen::Isometry3d& T_w_c, const Illumination& light, std::span<const SpotLight> lights)
      : world_(world), pixels_(pixels) {
    R_ = T_w_c.linear().cast<float>();
    origin_ = T_w_c.translation().cast<float>();
    up_ = world.up_w.cast<float>();
    const Eigen::Vector3f sun = light.sun_dir_w.cast<float>();
    sun_ = sun.norm() > 0.0f ? Eigen::Vector3f(sun.normalized()) : up_;
    ambient_ = static_cast<float>(light.ambient);
    sun_intensity_ = static_cast<float>(light.sun_intensity);
    sky_ = static_cast<float>(light.sky_brightness);
    zenith_gain_ = static_cast<float>(config.sky_zenith_gain);
    near_m_ = static_cast<float>(config.near_m);
    far_m_ = static_cast<float>(config.far_m);
    haze_m_ = static_cast<float>(config.haze_distance_m);
    min_cos_ = static_cast<float>(config.min_incidence_cos);
    select_lights(lights);
  }

  int shading_lights() const { return static_cast<int>(shading_.size()); }
  int visible_lamp_heads() const { return static_cast<int>(heads_.size()); }

  // Scene radiance along pixel k's ray (hint_quad: the left neighbour's quad, updated).
  float radiance(std::size_t k, int& hint_quad) const {
    const Eigen::Vector3f ray_c(pixels_.ray_c[3 * k], pixels_.ray_c[3 * k + 1], pixels_.ray_c[3 * k + 2]);
    const Eigen::Vector3f d = R_ * ray_c;
    const float elevation = std::clamp(d.dot(up_), 0.0f, 1.0f);
    const float sky_radiance = sky_ * (1.0f + zenith_gain_ * elevation);
    float t = 0, a_m = 0, b_m = 0;
    const int qi = render_detail::closest_hit(world_, origin_, d, near_m_, far_m_, &t, &a_m, &b_m, hint_quad);
    hint_quad = qi;
    float radiance = sky_radiance;
    if (qi < 0 && d.dot(up_) < 0.0f) {
      // Below the horizon beyond the modelled ground: a distant, hazy, sunlit ground.
      radiance =
          sky_ + (kDistantGroundAlbedo * (ambient_ + sun_intensity_ * std::max(0.0f, sun_.dot(up_))) - sky_) *
                     std::min(1.0f, -d.dot(up_) * kDistantGroundFade);
    } else if (qi >= 0) {
      radiance = surface_radiance(world_.quads[static_cast<std::size_t>(qi)], k, d, t, a_m, b_m);
    }
    for (const LampHead& head : heads_) {
      if (d.dot(head.dir_w) <= 0.0f) continue;
      const float sin2 = d.cross(head.dir_w).squaredNorm();
      if (sin2 > head.sin2_max) continue;
      const float cover =
          std::clamp((head.radius_rad - std::sqrt(sin2)) / pixels_.footprint_rad[k] + 0.5f, 0.0f, 1.0f);
      const float a2 = head.radius_rad * head.radius_rad;
      radiance += head.transmission * (head.radiance * cover + head.glare_scale / (sin2 + a2));
    }
    return radiance;
  }

 private:
  // Radiance of quad q hit at distance t along ray d of pixel k, at (a_m, b_m) on the quad, hazed.
  float surface_radiance(const Quad& q, std::size_t k, const Eigen::Vector3f& d, float t, float a_m,
                         float b_m) const {
    const float cos_inc = q.normal_w.dot(d);
    const float facing = cos_inc < 0.0f ? 1.0f : -1.0f;  // normal turned towards the camera
    const float lambert = std::max(0.0f, facing * q.normal_w.dot(sun_));
    const float abs_cos = std::max(std::abs(cos_inc), min_cos_);
    const float footprint_tx = t * pixels_.footprint_rad[k] * q.texels_per_m / std::sqrt(abs_cos);
    const Texture& tex = world_.textures[static_cast<std::size_t>(q.texture)];
    const float albedo = tex.sample(q.u_offset_tx + q.u_sign * a_m * q.texels_per_m,
                                    q.v_offset_tx + q.v_sign * b_m * q.texels_per_m, footprint_tx);
    float irradiance = ambient_ + sun_intensity_ * lambert;
    if (!shading_.empty()) {
      const Eigen::Vector3f p = origin_ + t * d;
      const Eigen::Vector3f n = facing * q.normal_w;
      for (const SpotLight& lamp : shading_) irradiance += spot_irradiance(lamp, p, n);
    }
    const float surface = albedo * irradiance;
    if (haze_m_ > 0.0f) {
      const float haze = t / (t + haze_m_);
      return surface + (sky_ - surface) * haze;  // fades into the horizon sky
    }
    return surface;
  }

  // Whether a sphere of `radius` around c (camera frame) meets the view.
  bool sphere_in_view(const Eigen::Vector3f& c, float radius) const {
    if (c.z() < -radius) return false;
    if (pixels_.tan_half_fov_x <= 0.0f) return true;
    for (const auto& [coordinate, tangent] :
         {std::pair{c.x(), pixels_.tan_half_fov_x}, std::pair{-c.x(), pixels_.tan_half_fov_x},
          std::pair{c.y(), pixels_.tan_half_fov_y}, std::pair{-c.y(), pixels_.tan_half_fov_y}}) {
      if ((coordinate - tangent * c.z()) / std::sqrt(1.0f + tangent * tangent) > radius) return false;
    }
    return true;
  }

  // Lights: those whose reach (a sphere of range_m) meets the view, and the lamp heads in view (with their
  // glare halo) and not hidden behind a surface.
  void select_lights(std::span<const SpotLight> lights) {
    const Eigen::Matrix3f R_c_w = R_.transpose();
    for (const SpotLight& lamp : lights) {
      const Eigen::Vector3f c = R_c_w * (lamp.position_w - origin_);
      if (lamp.intensity > 0.0f && sphere_in_view(c, lamp.range_m)) shading_.push_back(lamp);
      if (!(lamp.head_radius_m > 0.0f && lamp.head_radiance > 0.0f)) continue;
      const float distance = c.norm();
      if (!(distance > near_m_ + lamp.head_radius_m)) continue;
      LampHead head;
      head.radius_rad = lamp.head_radius_m / distance;
      const float a2 = head.radius_rad * head.radius_rad;
      head.glare_scale = lamp.glare * lamp.head_radiance * a2;
      // The halo is drawn where it is above kGlareFloor; the head's edge at least.
      const float halo2 = head.glare_scale / kGlareFloor - a2;
      head.sin2_max = std::max(halo2, 4.0f * a2);
      if (!sphere_in_view(c, distance * std::sqrt(std::min(head.sin2_max, 1.0f)))) continue;
      head.dir_w = (lamp.position_w - origin_) / distance;
      float t_hit = 0, a_m = 0, b_m = 0;
      if (render_detail::closest_hit(world_, origin_, head.dir_w, near_m_, distance - lamp.head_radius_m,
                                     &t_hit, &a_m, &b_m) >= 0) {
        continue;  // hidden
      }
      head.transmission = haze_m_ > 0.0f ? haze_m_ / (distance + haze_m_) : 1.0f;
      head.radiance = lamp.head_radiance;
      heads_.push_back(head);
    }
  }

  const World& world_;
  PixelRays pixels_;
  Eigen::Matrix3f R_;
  Eigen::Vector3f origin_, up_, sun_;
  float ambient_ = 0, sun_intensity_ = 0, sky_ = 0, zenith_gain_ = 0;
  float near_m_ = 0, far_m_ = 0, haze_m_ = 0, min_cos_ = 0;
  std::vector<SpotLight> shading_;
  std::vector<LampHead> heads_;
};

std::size_t pixel_index(int u, int v, int w) {
  return static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
}

// The photon sensor: radiance at the sensor (vignetting is the lens'), metered on a sparse grid, exposed,
// then shot + read noise in linear grey levels, clipping, gamma and quantisation.
void expose_photon_sensor(const FrameScene& scene, const PixelRays& pixels, const Illumination& light,
                          std::uint64_t noise_seed, cv::Mat& image, RenderStats* stats) {
  const int w = image.cols, h = image.rows;
  const float vignetting = static_cast<float>(light.vignetting);
  const std::vector<float> gamma_lut = make_gamma_lut(light.gamma);
  const float lut_scale = static_cast<float>(kGammaLutSize);
  std::vector<float> signal(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  for (int v = 0; v < h; ++v) {
    int hint_quad = -1;
    for (int u = 0; u < w; ++u) {
      const std::size_t k = pixel_index(u, v, w);
      signal[k] = scene.radiance(k, hint_quad) * (1.0f - vignetting * pixels.vignette_r2[k]);
    }
  }
  const int stride = light.sensor.ae_metering_stride_px;
  std::vector<float> samples;
  samples.reserve(signal.size() / static_cast<std::size_t>(stride * stride) + 1);
  for (int v = stride / 2; v < h; v += stride) {
    for (int u = stride / 2; u < w; u += stride) samples.push_back(signal[pixel_index(u, v, w)]);
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
      const std::size_t k = pixel_index(u, v, w);
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
}

// The additive sensor: fixed exposure, vignetting, clipping, gamma, then additive grey-level noise.
void expose_additive_sensor(const FrameScene& scene, const PixelRays& pixels, const Illumination& light,
                            std::uint64_t noise_seed, cv::Mat& image, RenderStats* stats) {
  const int w = image.cols, h = image.rows;
  const float exposure = static_cast<float>(light.exposure);
  const float vignetting = static_cast<float>(light.vignetting);
  const float noise_sigma = static_cast<float>(light.noise_sigma);
  const std::vector<float> gamma_lut = make_gamma_lut(light.gamma);
  const float lut_scale = static_cast<float>(kGammaLutSize);
  if (stats != nullptr) stats->exposure_time = light.exposure;
  const std::uint64_t frame_key = render_detail::mix64(noise_seed ^ 0x5EED5EED5EEDull);
  for (int v = 0; v < h; ++v) {
    std::uint8_t* row = image.ptr<std::uint8_t>(v);
    int hint_quad = -1;  // the left neighbour's quad (reset per row)
    for (int u = 0; u < w; ++u) {
      const std::size_t k = pixel_index(u, v, w);
      const float radiance = scene.radiance(k, hint_quad);
      float linear = exposure * radiance * (1.0f - vignetting * pixels.vignette_r2[k]);
      linear = std::clamp(linear, 0.0f, 1.0f);
      float grey = gamma_lut[static_cast<std::size_t>(linear * lut_scale)];
      if (noise_sigma > 0.0f) {
        grey += noise_sigma * kIrwinHallScale * irwin_hall_centred(render_detail::hash_combine(frame_key, k));
      }
      row[u] = static_cast<std::uint8_t>(std::clamp(grey + 0.5f, 0.0f, 255.0f));
    }
  }
}

}  // namespace

cv::Mat Renderer::render(const Eigen::Isometry3d& T_w_c, const Illumination& light, std::uint64_t noise_seed,
                         std::span<const SpotLight> lights, RenderStats* stats) const {
  const CameraCalibration& cal = camera_.calibration();
  cv::Mat image(cal.height_px, cal.width_px, CV_8UC1);
  const PixelRays pixels{ray_c_.data(), footprint_rad_.data(), vignette_r2_.data(), tan_half_fov_x_,
                         tan_half_fov_y_};
  const FrameScene scene(world_, config_, pixels, T_w_c, light, lights);
  if (stats != nullptr) {
    *stats = RenderStats{};
    stats->shading_lights = scene.shading_lights();
    stats->visible_lamp_heads = scene.visible_lamp_heads();
  }
  if (light.photon_sensor) {
    expose_photon_sensor(scene, pixels, light, noise_seed, image, stats);
  } else {
    expose_additive_sensor(scene, pixels, light, noise_seed, image, stats);
  }
  return image;
}

}  // namespace loopgate::sim
