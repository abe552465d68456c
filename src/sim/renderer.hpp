// Per-pixel ray casting of a World through a CameraModel (distortion included), with illumination.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <span>
#include <vector>

#include "core/camera_model.hpp"
#include "core/types.hpp"
#include "sim/illumination.hpp"
#include "sim/lights.hpp"
#include "sim/world.hpp"

namespace loopgate::sim {

// Rendering knobs (defaults suit both worlds).
struct RendererConfig {
  double near_m = 0.05;            // nothing closer than this is drawn
  double far_m = 3000.0;           // rays end here (sky beyond)
  double haze_distance_m = 500.0;  // distance at which surfaces are half faded into the horizon sky (0 = off)
  double min_incidence_cos = 0.03;  // clamps the texture footprint at grazing angles
  double sky_zenith_gain = 0.35;    // the sky gets brighter by this fraction towards the zenith

  // The keys, in order, for loading, printing and the JSON echo (Self is RendererConfig or const
  // RendererConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("near_m", self.near_m);
    v("far_m", self.far_m);
    v("haze_distance_m", self.haze_distance_m);
    v("min_incidence_cos", self.min_incidence_cos);
    v("sky_zenith_gain", self.sky_zenith_gain);
  }
  void validate() const;  // throws loopgate::ConfigError naming the key
};

// What a render did (for the metadata and the tests).
struct RenderStats {
  double exposure_time = 0.0;    // additive sensor: Illumination::exposure
  double gain = 1.0;             // analogue gain (additive sensor: 1)
  double dn_per_electron = 0.0;  // photon sensor: linear grey levels per electron at that gain (else 0)
  int shading_lights = 0;        // lights that could light something in view
  int visible_lamp_heads = 0;    // lamp heads in view and not hidden
};

class Renderer {
 public:
  // Keeps a reference to world (it must outlive the renderer). Precomputes one camera-frame ray per pixel.
  Renderer(const World& world, const CameraCalibration& camera, const RendererConfig& config = {});

  // 8-bit grey CV_8UC1 of camera.width_px x camera.height_px, seen from camera pose T_w_c, lit by `light`
  // and the spot `lights` (their irradiance on surfaces and their visible heads). With light.photon_sensor
  // the frame is metered and exposed by the sensor's auto-exposure (sim/sensor.hpp). Const and thread-safe;
  // deterministic: same inputs and noise_seed -> same bytes. `stats` (optional) receives what was done.
  cv::Mat render(const Eigen::Isometry3d& T_w_c, const Illumination& light, std::uint64_t noise_seed,
                 std::span<const SpotLight> lights = {}, RenderStats* stats = nullptr) const;

  const CameraModel& camera() const { return camera_; }

 private:
  const World& world_;
  CameraModel camera_;
  RendererConfig config_;
  std::vector<float> ray_c_;          // 3 floats per pixel: unit bearing in the camera frame
  std::vector<float> footprint_rad_;  // angular size of each pixel (radians)
  std::vector<float> vignette_r2_;    // squared normalised distance of each pixel from the image centre
  // Half field of view as tangents (max |x / z|, |y / z| of the rays), for culling lights; 0 = no culling
  // (a ray at or beyond 90 degrees from the optical axis).
  float tan_half_fov_x_ = 0.0f;
  float tan_half_fov_y_ = 0.0f;
};

}  // namespace loopgate::sim
