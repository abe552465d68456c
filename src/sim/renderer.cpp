#include "sim/renderer.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <string>

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
}

cv::Mat Renderer::render(const Eigen::Isometry3d& T_w_c, const Illumination& light,
                         std::uint64_t noise_seed) const {
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
  const std::uint64_t frame_key = render_detail::mix64(noise_seed ^ 0x5EED5EED5EEDull);
  for (int v = 0; v < h; ++v) {
    std::uint8_t* row = image.ptr<std::uint8_t>(v);
    int hint_quad = -1;  // the left neighbour's quad (reset per row)
    for (int u = 0; u < w; ++u) {
      const std::size_t k =
          static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
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
        const float surface = albedo * (ambient + sun_intensity * lambert);
        if (haze_m > 0.0f) {
          const float haze = t / (t + haze_m);
          radiance = surface + (sky - surface) * haze;  // fades into the horizon sky
        } else {
          radiance = surface;
        }
      }
      float linear = exposure * radiance * (1.0f - vignetting * vignette_r2_[k]);
      linear = std::clamp(linear, 0.0f, 1.0f);
      float grey = gamma_lut[static_cast<std::size_t>(linear * lut_scale)];
      if (noise_sigma > 0.0f) {
        const std::uint64_t bits = render_detail::hash_combine(frame_key, k);
        const float s = static_cast<float>(bits & 0xFFFFu) + static_cast<float>((bits >> 16) & 0xFFFFu) +
                        static_cast<float>((bits >> 32) & 0xFFFFu) + static_cast<float>(bits >> 48);
        grey += noise_sigma * kIrwinHallScale * (s * kNoiseUniformScale - 2.0f);
      }
      row[u] = static_cast<std::uint8_t>(std::clamp(grey + 0.5f, 0.0f, 255.0f));
    }
  }
  return image;
}

}  // namespace loopgate::sim
